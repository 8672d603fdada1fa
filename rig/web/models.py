"""Request and response models of the control page's API (pydantic; units in the names).

Requests are validated here with bounds that keep every value finite and every plan small
enough to preview: a bad value is a 422 naming the field, never a 500. The plan and campaign
settings map one to one onto :class:`rig.plans.LoopParams`, :class:`rig.plans.CampaignAxes`
and :class:`rig.plans.campaign_file.Limits`.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, Union

from pydantic import (
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    field_validator,
    model_validator,
)

from rig.core import ids
from rig.core.ranges import (
    DWELL_S,
    INPUT_SPEED_RPM,
    LIMIT_ARCMIN,
    LIMIT_ARCSEC,
    LIMIT_STIFFNESS_NM_PER_ARCMIN,
    POSITION_DEG,
    RATE_NM_PER_S,
    RATED_TORQUE_NM,
    SAMPLE_S,
    SETTLE_HOLD_S,
    SETTLE_RATE_ARCMIN_PER_S,
    SETTLE_TIMEOUT_S,
    TEMPERATURE_SETPOINT_C,
    TORQUE_LIMIT_NM,
    TWIST_STEP_ARCMIN,
    ZERO_BAND_NM,
)
from rig.plans import TE_KIND, CampaignAxes, LoopParams, TEParams, check_plan_size, unit_ratio
from rig.plans.campaign_file import Limits

ID_PATTERN = rf"^{ids.ID_PATTERN.pattern}$"
"""Run and campaign ids in URLs: the one rule of :mod:`rig.core.ids`."""
NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._-]{0,79}$"
"""A plan longer than this is refused (its preview alone would take seconds)."""

_strict = ConfigDict(extra="forbid", strict=True)


Positive_mm = Annotated[float, Field(ge=0, le=100_000, allow_inf_nan=False)]
Angle_deg = POSITION_DEG.type
Percent = Annotated[float, Field(gt=0, le=100, allow_inf_nan=False)]
Celsius = TEMPERATURE_SETPOINT_C.type


def _length(min_value: float, max_value: float, **kw: Any) -> Any:
    return Field(ge=min_value, le=max_value, allow_inf_nan=False, **kw)


class _UnitBase(BaseModel):
    """What every unit kind's model shares: strict fields and the run.json mapping."""

    model_config = _strict

    def mapping(self) -> dict[str, Any]:
        """The run.json ``unit`` object (unknown fields left out)."""
        return self.model_dump(exclude_none=True)


class _InternalPairBase(_UnitBase):
    """An internal gear pair's tooth counts (seed 000's ring and pinion, seed 002's gear 2 and
    gear 1): the internal gear has more teeth."""

    serial: str | None = Field(None, pattern=NAME_PATTERN, description="Serial number.")
    z_internal: int = Field(ge=3, le=2000, description="Teeth of the internal gear.")
    z_external: int = Field(ge=3, le=2000, description="Teeth of the external gear.")
    module_mm: float = _length(0.01, 100.0)

    @model_validator(mode="after")
    def _consistent(self) -> _InternalPairBase:
        if self.z_internal <= self.z_external:
            raise ValueError(f"z_internal ({self.z_internal}) must exceed z_external "
                             f"({self.z_external})")
        return self


class UnitData(_InternalPairBase):
    """The unit under test: the seed 000 fields of run.json ``unit`` (mm, deg).

    Optional fields left out are unknown to the model (not zero); run-format.md says how the
    reference nominal model uses each one.
    """

    kind: Literal["internal_involute"] = "internal_involute"
    pressure_angle_deg: float | None = Field(None, gt=0, lt=45, allow_inf_nan=False)
    addendum_coeff: float | None = _length(0.0, 2.0, default=None)
    clearance_coeff: float | None = _length(0.0, 1.0, default=None)
    face_width_mm: float | None = Field(None, gt=0, le=10_000, allow_inf_nan=False)
    center_distance_mm: float | None = _length(0.0, 10_000.0, default=None)
    pin_diameter_mm: float | None = Field(None, gt=0, le=1000, allow_inf_nan=False)
    m_value_internal_mm: list[Positive_mm] | None = Field(None, min_length=1, max_length=64)
    m_value_external_mm: list[Positive_mm] | None = Field(None, min_length=1, max_length=64)
    runout_internal_mm: float | None = _length(0.0, 10.0, default=None)
    runout_external_mm: float | None = _length(0.0, 10.0, default=None)
    bearing_clearance_mm: list[Positive_mm] | None = Field(None, min_length=1, max_length=8)


class CycloidUnitData(_InternalPairBase):
    """A compound cycloid unit (``kind`` "cycloid", seed 002; mm, N*m): gear 2
    (``z_internal``, eq. 1's profile with r0 = m z2, e1 = m h1, e2 = f1 e1 of eq. 15) fixed,
    gear 1 (``z_external``) on the crank is the output. The keys of
    :mod:`analysis.models.cycloid_nominal` (optional ones left out are assumed, and said so)
    and the inspected tolerances the diagnosis and the plant read (docs/unit-kinds.md)."""

    kind: Literal["cycloid"]
    height_coeff: float = Field(gt=0, le=1, allow_inf_nan=False, description="h1 of eq. 15.")
    shape_coeff: float = _length(0.0, 1.0, description="f1 of eq. 15.")
    eccentricity_mm: float | None = Field(None, gt=0, le=1000, allow_inf_nan=False)
    shift_modification_mm: float | None = _length(-1.0, 1.0, default=None)
    rotation_modification_mm: float | None = _length(-1.0, 1.0, default=None)
    face_width_mm: float | None = Field(None, gt=0, le=10_000, allow_inf_nan=False)
    reference_torque_Nm: float | None = Field(None, gt=0, le=100_000, allow_inf_nan=False)
    runout_internal_mm: float | None = _length(0.0, 10.0, default=None)
    runout_external_mm: float | None = _length(0.0, 10.0, default=None)
    pitch_deviation_mm: float | None = _length(0.0, 10.0, default=None)
    bearing_clearance_mm: list[Positive_mm] | None = Field(None, min_length=1, max_length=8)


class BeveloidUnitData(_UnitBase):
    """A parallel-axis helical beveloid unit (``kind`` "beveloid", seed 001; mm, deg): the
    pinion (``z_pinion``) is the input, the gear (``z_gear``) the output. The keys of
    :mod:`analysis.models.beveloid_nominal` with the ranges of seed 001's gear
    (:class:`analysis.models.seed001_surfaces.BeveloidGear`)."""

    kind: Literal["beveloid"]
    serial: str | None = Field(None, pattern=NAME_PATTERN, description="Serial number.")
    z_pinion: int = Field(ge=5, le=2000, description="Teeth of the pinion (the input).")
    z_gear: int = Field(ge=5, le=2000, description="Teeth of the gear (the output).")
    module_mm: float = _length(0.01, 100.0, description="Normal module.")
    pressure_angle_deg: float = _length(5.0, 35.0, description="Normal pressure angle.")
    helix_angle_deg: float = Field(gt=-45, lt=45, allow_inf_nan=False,
                                   description="Pinion's helix angle, + right hand.")
    cone_angle_deg: float = Field(gt=-30, lt=30, allow_inf_nan=False,
                                  description="Pinion's cone angle.")
    face_width_mm: float = Field(gt=0, le=10_000, allow_inf_nan=False)
    addendum_coeff: float | None = _length(0.0, 1.5, default=None)
    center_distance_mm: float | None = Field(None, gt=0, le=10_000, allow_inf_nan=False)
    axial_shift_mm: float | None = _length(-100.0, 100.0, default=None)
    runout_internal_mm: float | None = _length(0.0, 10.0, default=None)
    runout_external_mm: float | None = _length(0.0, 10.0, default=None)
    runout_pinion_mm: float | None = _length(0.0, 10.0, default=None)
    runout_gear_mm: float | None = _length(0.0, 10.0, default=None)
    bearing_clearance_mm: list[Positive_mm] | None = Field(None, min_length=1, max_length=8)


PLANETARY_RATIO = 320.0
"""Seed 003's paper train (stages 8 * 8 * 5): the one planetary unit the plant and the TE model
know (simulators/plant/planetary.py refuses another ratio)."""
PLANETARY_STAGES = 3


class PlanetaryUnitData(_UnitBase):
    """A planetary unit (``kind`` "planetary", seed 003's 3-stage paper train; mm, um, N*m):
    stage I sun in, stage III carrier out, rings fixed. The keys of the plant's ``[unit]``
    (docs/plant.md, simulators/plant/planetary.py): the ratio (320, the only train), the face
    width of every gear, the planets per stage and each stage's circumferential backlash. The
    unit's errors as made are the plant's ``[planetary]`` table, not unit data."""

    kind: Literal["planetary"]
    serial: str | None = Field(None, pattern=NAME_PATTERN, description="Serial number.")
    design: str | None = Field(None, pattern=NAME_PATTERN, description="The train's design.")
    ratio: float = Field(PLANETARY_RATIO, allow_inf_nan=False,
                         description="Signed reduction ratio (the output turns with the input).")
    face_width_mm: float = Field(gt=0, le=10_000, allow_inf_nan=False)
    planets: int | None = Field(None, ge=1, le=12, description="Planets per stage (blank: 3).")
    backlash_um: list[Annotated[float, Field(ge=0, le=1000, allow_inf_nan=False)]] = Field(
        min_length=PLANETARY_STAGES, max_length=PLANETARY_STAGES,
        description="Circumferential backlash of each stage's meshes (stages I, II, III).")
    reference_torque_Nm: float | None = Field(None, gt=0, le=100_000, allow_inf_nan=False)

    @field_validator("ratio")
    @classmethod
    def _paper_train(cls, value: float) -> float:
        if value != PLANETARY_RATIO:
            raise ValueError(f"the seed 003 paper train's ratio is {PLANETARY_RATIO:g} "
                             f"(got {value:g})")
        return value


UNIT_MODELS: dict[str, type[BaseModel]] = {
    "internal_involute": UnitData, "cycloid": CycloidUnitData, "beveloid": BeveloidUnitData,
    "planetary": PlanetaryUnitData}
"""The page's unit of each kind: those :mod:`analysis.models.by_kind` has a nominal loop model
for, and seed 003's planetary train (a transmission error model only)."""
UNIT_KIND_MESSAGE = ("unit kind must be one of " + ", ".join(UNIT_MODELS)
                     + " (absent: internal_involute)")


def _unit_kind(value: Any) -> str | None:
    kind = value.get("kind", "internal_involute") if isinstance(value, dict) else getattr(
        value, "kind", None)
    return kind if isinstance(kind, str) and kind in UNIT_MODELS else None


AnyUnit = Annotated[
    Union[  # noqa: UP007 (the tagged members of a discriminated union)
        Annotated[UnitData, Tag("internal_involute")],
        Annotated[CycloidUnitData, Tag("cycloid")],
        Annotated[BeveloidUnitData, Tag("beveloid")],
        Annotated[PlanetaryUnitData, Tag("planetary")],
    ],
    Discriminator(_unit_kind, custom_error_type="unit_kind",
                  custom_error_message=UNIT_KIND_MESSAGE),
]
"""A unit of any kind, chosen by its ``kind`` (absent: ``internal_involute``). A field error's
``loc`` holds the kind after ``unit`` (pydantic's tag); the page's API drops it
(:func:`plain_unit_loc`), so a wrong field is named as for a seed 000 unit."""


def plain_unit_loc(loc: tuple[Any, ...] | list[Any]) -> tuple[Any, ...]:
    """``loc`` of a validation error without the unit kind's tag (``body.unit.cycloid.x`` ->
    ``body.unit.x``)."""
    out = list(loc)
    for i in range(len(out) - 1):
        if out[i] == "unit" and out[i + 1] in UNIT_MODELS:
            del out[i + 1]
            break
    return tuple(out)


class PlanSettings(BaseModel):
    """One hysteresis run's loading (rig/plans/__init__.py, :class:`rig.plans.LoopParams`): N*m, %,
    s, arcmin. The defaults are the GB/T loop of examples/campaigns/seed000-pair1.toml:
    4 equal torque steps per quarter, settled points at +-3 % of rated too, the free play
    crossed slowly (|T| < 0.3 N*m at 0.3 N*m/s)."""

    model_config = _strict

    rated_torque_Nm: RATED_TORQUE_NM.type
    amplitude_pct: float = Field(100.0, gt=0, le=100, allow_inf_nan=False)
    mode: Literal["equal_torque", "equal_position", "constant_rate"] = "equal_torque"
    cycles: int = Field(1, ge=1, le=20)
    pre_cycles: int = Field(1, ge=0, le=10)
    rate_Nm_per_s: RATE_NM_PER_S.type = 25.0
    steps_per_quarter: int = Field(4, ge=1, le=200)
    twist_step_arcmin: TWIST_STEP_ARCMIN.type = 0.5
    dwell_s: DWELL_S.type = 0.05
    settle_rate_arcmin_per_s: SETTLE_RATE_ARCMIN_PER_S.type = 2.0
    settle_hold_s: SETTLE_HOLD_S.type = 0.1
    settle_timeout_s: SETTLE_TIMEOUT_S.type = 2.0
    sample_s: SAMPLE_S.type = 0.05
    extra_levels_pct: list[Annotated[float, Field(gt=0, lt=100, allow_inf_nan=False)]] = Field(
        default_factory=lambda: [3.0], max_length=10)
    zero_band_Nm: ZERO_BAND_NM.type = 0.3
    zero_rate_Nm_per_s: RATE_NM_PER_S.type | None = 0.3

    def loop_params(self) -> LoopParams:
        return LoopParams(**self.model_dump())


class LimitSettings(BaseModel):
    """Pass/fail limits (:class:`rig.plans.campaign_file.Limits`): arcmin at most, N*m/arcmin at
    least;
    None: not checked."""

    model_config = _strict

    lost_motion_arcmin_max: LIMIT_ARCMIN.type | None = None
    backlash_arcmin_max: LIMIT_ARCMIN.type | None = None
    stiffness_Nm_per_arcmin_min: LIMIT_STIFFNESS_NM_PER_ARCMIN.type | None = None
    te_pp_max_arcsec: LIMIT_ARCSEC.type | None = None
    te_hysteresis_max_arcmin: LIMIT_ARCMIN.type | None = None

    def limits(self) -> Limits:
        return Limits(**self.model_dump())


class AxesSettings(BaseModel):
    """What a campaign varies (:class:`rig.plans.CampaignAxes`): input angles (deg),
    amplitudes (% of rated), housing temperatures (deg C; empty: none) and repeats."""

    model_config = _strict

    positions_deg: list[Angle_deg] = Field(default_factory=lambda: [0.0], min_length=1,
                                           max_length=360)
    amplitudes_pct: list[Percent] = Field(default_factory=lambda: [100.0], min_length=1,
                                          max_length=20)
    temperatures_C: list[Celsius] = Field(default_factory=list, max_length=20)
    repeats: int = Field(1, ge=1, le=50)

    def axes(self) -> CampaignAxes:
        return CampaignAxes(**self.model_dump())


class TESettings(BaseModel):
    """The transmission error test (:class:`rig.plans.TEParams`): input speed (rpm), brake
    torque (fraction of the plan's rated torque), output revolutions per direction, the
    signed ratio (None: the unit's)."""

    model_config = _strict

    input_speed_rpm: INPUT_SPEED_RPM.type = 120.0
    brake_torque_fraction: float = Field(0.2, gt=0, le=1, allow_inf_nan=False)
    output_revolutions: float = Field(1.0, ge=1, le=100, allow_inf_nan=False)
    ratio: float | None = Field(None, ge=-10_000, le=10_000, allow_inf_nan=False)


class RunRequest(BaseModel):
    """Set up a single run (``kind`` "run") or a campaign (``kind`` "campaign": runs over
    ``axes``). ``position_deg`` (run only) locks the input there first (needs an input
    motor); ``torque_limit_Nm`` may only lower the rig's limit."""

    model_config = _strict

    kind: Literal["run", "campaign"] = "run"
    test: Literal["lost_motion", "transmission_error"] = "lost_motion"
    """The test: the hysteresis loop (``plan``) or the transmission error (``te``)."""
    te: TESettings = Field(default_factory=TESettings)
    name: str = Field("web", pattern=NAME_PATTERN, description="Campaign name (campaigns).")
    operator: str | None = Field(None, min_length=1, max_length=80)
    calibration_override: str | None = Field(None, min_length=1, max_length=500)
    """Why the measurement may run with a sensor calibration past due (recorded in run.json);
    refused (409) without it while one is expired."""
    unit: AnyUnit
    plan: PlanSettings
    position_deg: POSITION_DEG.type | None = None
    axes: AxesSettings = Field(default_factory=AxesSettings)
    limits: LimitSettings = Field(default_factory=LimitSettings)
    torque_limit_Nm: TORQUE_LIMIT_NM.type | None = None
    profile: Literal["nabtesco", "harmonic-drive", "gbt", "spinea"] = "nabtesco"
    confirm_long: bool = False
    """The plan may take longer than 8 h (at most 30 days: :mod:`rig.core.ranges`); without
    it the preview does not fit and the start is refused (409)."""

    def te_params(self) -> TEParams:
        """The transmission error run's parameters (ValueError without a ratio)."""
        ratio = self.te.ratio if self.te.ratio is not None else unit_ratio(self.unit.mapping())
        if ratio is None:
            raise ValueError("te.ratio: the unit does not give the reduction ratio; enter it")
        return TEParams(rated_torque_Nm=self.plan.rated_torque_Nm, ratio=ratio,
                        input_speed_rpm=self.te.input_speed_rpm,
                        brake_torque_fraction=self.te.brake_torque_fraction,
                        output_revolutions=self.te.output_revolutions)

    @model_validator(mode="after")
    def _small_enough(self) -> RunRequest:
        a = self.axes
        if self.test == TE_KIND:
            self.te_params()
            return self
        n_runs = 1 if self.kind == "run" else (
            len(a.positions_deg) * len(a.amplitudes_pct) * max(1, len(a.temperatures_C))
            * a.repeats)
        check_plan_size(self.plan, n_runs)
        return self


class PlanPreview(BaseModel):
    """The plan before it runs: its steps (the first ``len(steps)`` of ``n_steps``), the
    expected duration (s), the number of runs, and whether it fits the rig."""

    name: str
    n_steps: int
    n_runs: int
    estimated_s: float
    dwell_s: float
    steps: list[str]
    truncated: bool
    torque_limit_Nm: float | None
    amplitude_Nm: float
    fits: bool
    problems: list[str]
    assumptions: list[str]
    model: dict[str, Any] | None
    batch: dict[str, Any] | None = None
    """Where a production batch of this design lies (95 % band, from the unit kind's
    tolerances: seed 000 Table 1, seed 002's modification budget, seed 001's installation
    error budget)."""
    diagnosis_design: dict[str, Any] | None = None
    """A loop campaign: the candidate effects the gap diagnosis can test on its runs
    (``testable``) and the others with why not (``untestable``: effect -> reason); None for a
    single run or a TE campaign (rig/plans/diagnosability.py)."""


class Message(BaseModel):
    """A short answer: ``ok`` and what was done."""

    ok: bool
    message: str


class InputLockAnswer(Message):
    """The answer to an input lock: at once, whatever the move's length. ``moving`` True
    (HTTP 202): the motor is turning to ``target_deg`` (deg); its progress comes on the live
    stream (``input_lock`` events) and in ``/api/status`` (``input_lock.moving``), and the lock
    is confirmed when it ends. False: done (locked, or confirmed by the operator)."""

    moving: bool = False
    target_deg: float | None = None


class TareResult(BaseModel):
    """The torque transducer's stored tare offset (N*m) after taring."""

    ok: bool
    offset_Nm: float
    message: str


class InputLockRequest(BaseModel):
    """Confirm the input lock. With an input motor, ``angle_deg`` (deg) locks it there first;
    without one the operator confirms the input is locked by hand."""

    model_config = _strict

    angle_deg: POSITION_DEG.type | None = None
    confirm: bool = True


class Device(BaseModel):
    """One device: connected, healthy, heartbeat age (s), a readable detail."""

    name: str
    connected: bool
    ok: bool
    heartbeat_age_s: float | None = None
    detail: str = ""


class LiveValues(BaseModel):
    """Latest values: output twist (arcmin), torque (N*m), housing temperature (deg C),
    torque setpoint (N*m), drive enabled; None when unknown."""

    twist_arcmin: float | None = None
    """Output twist counted from the output angle at the confirmed input lock (zero torque)."""
    output_angle_deg: float | None = None
    """The output encoder's angle as it reads (deg)."""
    torque_Nm: float | None = None
    crosscheck_torque_Nm: float | None = None
    temperature_C: float | None = None
    setpoint_Nm: float | None = None
    drive_enabled: bool | None = None
    input_angle_deg: float | None = None


class Progress(BaseModel):
    """Step ``step`` of ``n_steps``; times in s."""

    step: int
    n_steps: int
    elapsed_s: float
    remaining_s: float
    description: str
    run_label: str | None
    run_id: str | None


class FaultOut(BaseModel):
    """A fault in plain words (title, what to do) with the engine's message (detail)."""

    title: str
    action: str
    detail: str


class InputLockMove(BaseModel):
    """The input motor turning to the lock angle: target and angle now (deg)."""

    target_deg: float
    angle_deg: float | None = None


class InputLock(BaseModel):
    """Whether the operator confirmed the input lock (a run may start only then)."""

    confirmed: bool
    angle_deg: float | None
    by_motor: bool
    moving: InputLockMove | None = None
    """The motor turning to the lock angle now (None: not moving)."""
    failed: str | None = None
    """Why the last lock move failed (None: it did not, or a later one succeeded)."""


class LatchedFault(BaseModel):
    """A latched fault: the device (or "E-stop") and what it says."""

    device: str
    detail: str


class ResetFaultsRequest(BaseModel):
    """Who acknowledges the faults (kept in the store's audit trail)."""

    model_config = _strict

    operator: str | None = Field(None, min_length=1, max_length=80)


class ResetFaultsResult(BaseModel):
    """What the reset did: ``ok`` when no fault is left; cleared and remaining faults."""

    ok: bool
    message: str
    cleared: list[LatchedFault]
    still: list[LatchedFault]


class Status(BaseModel):
    """Everything the page shows about the rig now."""

    state: Literal["no_rig", "idle", "starting", "running", "paused", "stopping",
                   "completed", "aborted", "fault"]
    """"fault": idle with a latched fault (a device, or an E-stop): Reset faults first."""
    operator: bool
    faults: list[LatchedFault] = Field(default_factory=list)
    rig: str | None
    rig_id: str | None = None
    """The rig's name (``[rig] rig_id`` of its configuration)."""
    calibration: list[dict[str, Any]] = Field(default_factory=list)
    """The sensors' calibrations (rig configuration ``[calibration]``), each with ``expired``
    and ``days_left``."""
    simulated: bool
    torque_limit_Nm: float | None
    devices: list[Device]
    live: LiveValues
    safe: bool | None
    progress: Progress | None
    fault: FaultOut | None
    input_lock: InputLock
    current: dict[str, Any] | None
    last_result: dict[str, Any] | None
    message: str


class RunSummary(BaseModel):
    """One run of the store's index (docs/store.md)."""

    run_id: str
    campaign_id: str | None
    status: str
    reason: str | None
    unit_serial: str | None
    operator: str | None
    rig_id: str | None
    plan_name: str | None
    plan_version: str | None
    started_at: str
    finished_at: str | None
    n_samples: int | None
    calibration_warnings: list[str]
    metrics: dict[str, Any] | None
    outcome: str | None = None
    """The run's verdict: "ok", "not_ok", "incomplete", "no_limits" (rig/results/outcome.py; None
    while running or when none is recorded)."""
    verdict: str | None = None
    """The displayed word of ``outcome``: OK, NOT OK, INCOMPLETE, NO LIMITS."""
    label: str | None = None
    """The plan's name of the run (``pos090-a100-r0``), as the live panel calls it too."""


class RunDetail(BaseModel):
    """A run's run.json (``meta``), its index row and its columns."""

    summary: RunSummary
    meta: dict[str, Any]
    columns: list[str]


class LoopData(BaseModel):
    """A stored run's loop for drawing: torque (N*m) and twist (arcmin, centred on the loop),
    the model loop on the same torque (or None), the ±p % band half-width (N*m) and the
    metrics (``rig analyse --json`` keys; empty with ``analysis_error`` when not analysable).
    """

    run_id: str
    n_samples: int
    torque_Nm: list[float | None]
    twist_arcmin: list[float | None]
    model_twist_arcmin: list[float | None] | None
    band_Nm: float | None
    metrics: dict[str, Any]
    analysis_error: str | None
    outcome: str | None = None
    """The run's verdict against its ``limits``: "ok", "not_ok", "incomplete", "no_limits"
    (rig/results/outcome.py; None while running)."""
    verdict: str | None = None
    """The displayed word of ``outcome``: OK, NOT OK, INCOMPLETE, NO LIMITS."""
    limits: dict[str, Any] | None = None
    status: str | None = None


class TEData(BaseModel):
    """A stored transmission error run for drawing, as the page draws it live: the raw TE
    (arcsec, docs/run-format.md, before each direction's mean) against the output angle (deg)
    and the direction (+1 forward, -1 reverse) of each row of the turns, decimated; and the
    run's recorded ``result`` (``te_pp_arcsec`` ...), verdict and limits."""

    run_id: str
    n_samples: int
    output_deg: list[float | None]
    te_arcsec: list[float | None]
    direction: list[float | None]
    result: dict[str, Any]
    outcome: str | None = None
    verdict: str | None = None
    limits: dict[str, Any] | None = None
    status: str | None = None


class CampaignSummary(BaseModel):
    """One campaign of the store: status, its meta and results summary."""

    campaign_id: str
    name: str
    status: str
    started_at: str
    finished_at: str | None
    meta: dict[str, Any]
    summary: dict[str, Any] | None
    outcome: str | None = None
    """The campaign's verdict (rig/results/outcome.py codes, as for a run)."""
    verdict: str | None = None
    """The displayed word of ``outcome``: OK, NOT OK, INCOMPLETE, NO LIMITS."""
    no_diagnosis: str | None = None
    """Why the campaign has no diagnosis report, in one sentence ("no diagnosis: the
    campaign was aborted in its first run (E-STOP ...)"); None when it has one or can have
    one (made when first asked for)."""
    runs: list[RunSummary]


class UnitExample(BaseModel):
    """An example unit shipped with the package (rig/examples/units)."""

    name: str
    unit: dict[str, Any]


class ErrorBody(BaseModel):
    """An error: ``detail`` says what was wrong and what to do."""

    detail: str


class OutcomeWord(BaseModel):
    """How the page shows one outcome code (rig/results/outcome.py)."""

    word: str
    """OK, NOT OK, INCOMPLETE or NO LIMITS."""
    meaning: str
    """What it means, in a few words."""


class CampaignFileName(BaseModel):
    """An example campaign of the rig (``examples/campaigns``), by name."""

    name: str
    description: str


class CampaignUpload(BaseModel):
    """A campaign file the operator chose: its name (shown in messages, never a path) and
    its TOML text (at most 1 MB)."""

    model_config = _strict

    file_name: str = Field("uploaded file", max_length=255)
    text: str = Field(max_length=1024 * 1024)


class CampaignSetup(BaseModel):
    """A campaign file as the page's set-up: ``request`` is a :class:`RunRequest` body (its
    ``unit`` None when the file gives no complete unit); ``notes`` say what the page does not
    take over from the file."""

    source: str
    name: str
    description: str
    request: dict[str, Any]
    notes: list[str]
