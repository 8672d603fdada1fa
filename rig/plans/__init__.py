"""Measurement plans: plain generators of steps (``rig/plans/steps.py``).

The hysteresis run follows the GB/T 35089 / GB/T 40731 definition as the rig runs it: the unit
is preloaded to -T (with ``pre_cycles`` full cycles -T -> +T -> -T first), the run starts at
-T and the torque goes -T -> 0 -> +T -> 0 -> -T (``cycles`` times), T = amplitude % of the
rated torque. Three loading modes:

- ``equal_torque``: ``steps_per_quarter`` equal torque steps per quarter cycle, each ramped
  at ``rate_Nm_per_s``, then settled (twist rate below ``settle_rate_arcmin_per_s``), held
  for ``dwell_s`` and sampled;
- ``equal_position``: equal twist steps of ``twist_step_arcmin`` (the torque is raised at
  ``rate_Nm_per_s`` until the output has moved that much), each settled and dwelt;
- ``constant_rate``: the torque is ramped continuously at ``rate_Nm_per_s``.

The torque zero is read before and after each loop. A campaign plan repeats the run over
temperatures (outer), positions (the input motor locks the eccentric shaft at each angle),
amplitudes and repeats (inner). Every run's ``test`` object records the loading parameters
(mode, rate, dwell, settle threshold, steps, pre-cycles): results depend on them.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from rig.core.ranges import (
    DWELL_S,
    INPUT_SPEED_RPM,
    POSITION_DEG,
    RATE_NM_PER_S,
    RATED_TORQUE_NM,
    SAMPLE_S,
    SETTLE_HOLD_S,
    SETTLE_RATE_ARCMIN_PER_S,
    SETTLE_TIMEOUT_S,
    TEMPERATURE_SETPOINT_C,
    TEMPERATURE_TIMEOUT_S,
    TEMPERATURE_TOLERANCE_C,
    TWIST_STEP_ARCMIN,
    WINDOW_S,
    ZERO_BAND_NM,
)
from rig.plans.steps import (
    BeginRun,
    Checkpoint,
    Dwell,
    EndRun,
    LockInput,
    Ramp,
    ReadTorqueZero,
    Sample,
    SetAmbient,
    Settle,
    Step,
    StepTwist,
    TurnInput,
    WaitTemperature,
    describe,
)

PLAN_VERSION = "1"
LoadingMode = Literal["equal_torque", "equal_position", "constant_rate"]


MAX_PLAN_STEPS = 200_000
"""The largest plan the rig accepts (about 2 days of stepped loading): a bigger one is a typo
(10,000 positions, 1,000 repeats x 100 cycles) and is refused before anything moves."""

_STRICT = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)
"""Campaign files and the page's API: a boolean is not a number, NaN and inf are no value."""


def plan_size(loop: Any, n_runs: int) -> int:
    """An upper bound of the steps of ``n_runs`` runs of ``loop`` (a :class:`LoopParams` or
    the page's plan settings: a few steps per level and quarter)."""
    per_quarter = 4 * (loop.steps_per_quarter + 2 * len(loop.extra_levels_pct)) + 5
    return n_runs * (loop.cycles * 4 * per_quarter + 2 * loop.pre_cycles + 12)


def check_plan_size(loop: Any, n_runs: int) -> None:
    """ValueError naming the size when the plan exceeds :data:`MAX_PLAN_STEPS`."""
    size = plan_size(loop, n_runs)
    if size > MAX_PLAN_STEPS:
        raise ValueError(f"the plan would have about {size} steps (at most "
                         f"{MAX_PLAN_STEPS}): fewer positions, repeats, cycles or steps")


ExtraLevel = Annotated[float, Field(gt=0, lt=100)]


class LoopParams(BaseModel):
    """Parameters of one hysteresis run (units in the names; pct of the rated torque)."""

    model_config = _STRICT

    rated_torque_Nm: RATED_TORQUE_NM.type
    amplitude_pct: float = Field(100.0, gt=0, le=100)
    mode: LoadingMode = "equal_torque"
    cycles: int = Field(1, ge=1, le=100)
    pre_cycles: int = Field(1, ge=0, le=100)
    rate_Nm_per_s: RATE_NM_PER_S.type = 20.0
    steps_per_quarter: int = Field(10, ge=1, le=1000)
    twist_step_arcmin: TWIST_STEP_ARCMIN.type = 0.5
    dwell_s: DWELL_S.type = 0.1
    settle_rate_arcmin_per_s: SETTLE_RATE_ARCMIN_PER_S.type = 2.0
    settle_hold_s: SETTLE_HOLD_S.type = 0.1
    settle_timeout_s: SETTLE_TIMEOUT_S.type = 3.0
    sample_s: SAMPLE_S.type = 0.05
    extra_levels_pct: list[ExtraLevel] = Field(default_factory=list, max_length=20)
    zero_band_Nm: ZERO_BAND_NM.type = 0.0
    zero_rate_Nm_per_s: RATE_NM_PER_S.type | None = None
    zero_window_s: WINDOW_S.type = 0.2

    @property
    def amplitude_Nm(self) -> float:
        """T, the loop's torque amplitude (N*m)."""
        return self.rated_torque_Nm * self.amplitude_pct / 100.0

    def test_meta(self) -> dict[str, Any]:
        """The run.json ``test`` keys these parameters give (the loading is recorded)."""
        return {
            "rated_torque_Nm": self.rated_torque_Nm,
            "amplitude_pct": self.amplitude_pct,
            "amplitude_Nm": self.amplitude_Nm,
            "cycles": self.cycles,
            "start_flank": -1,
            "loading": {
                "mode": self.mode,
                "rate_Nm_per_s": self.rate_Nm_per_s,
                "dwell_s": self.dwell_s,
                "steps_per_quarter": self.steps_per_quarter,
                "twist_step_arcmin": self.twist_step_arcmin,
                "settle_rate_arcmin_per_s": self.settle_rate_arcmin_per_s,
                "settle_hold_s": self.settle_hold_s,
                "pre_cycles": self.pre_cycles,
                "extra_levels_pct": list(self.extra_levels_pct),
                "zero_band_Nm": self.zero_band_Nm,
                "zero_rate_Nm_per_s": self.zero_rate_Nm_per_s,
                "sequence": "-T -> 0 -> +T -> 0 -> -T (GB/T)",
            },
        }


class CampaignAxes(BaseModel):
    """What a campaign varies: input angles (deg), amplitudes (% of rated), housing
    temperatures (deg C; empty: no climate control) and repeats."""

    model_config = _STRICT

    positions_deg: list[POSITION_DEG.type] = Field(default_factory=lambda: [0.0], min_length=1,
                                       max_length=10_000)
    amplitudes_pct: list[float] = Field(default_factory=lambda: [100.0], min_length=1,
                                        max_length=100)
    temperatures_C: list[TEMPERATURE_SETPOINT_C.type] = Field(default_factory=list,
                                                            max_length=100)
    repeats: int = Field(1, ge=1, le=1000)
    temperature_tolerance_C: TEMPERATURE_TOLERANCE_C.type = 0.5
    temperature_timeout_s: TEMPERATURE_TIMEOUT_S.type = 3600.0

    @model_validator(mode="after")
    def _amplitudes_in_range(self) -> CampaignAxes:
        bad = [a for a in self.amplitudes_pct if not 0 < a <= 100]
        if bad:
            raise ValueError(f"amplitudes_pct must be in (0, 100], got {bad}")
        return self


@dataclass(frozen=True)
class Plan:
    """A named, versioned plan: ``steps()`` yields a fresh generator of steps each call."""

    name: str
    params: dict[str, Any]
    build: Callable[[], Iterator[Step]]
    version: str = PLAN_VERSION
    notes: list[str] = field(default_factory=list)

    def steps(self) -> Iterator[Step]:
        return self.build()

    def listing(self) -> list[str]:
        """One line per step, numbered (the plan as a list)."""
        return [f"{i:4d}  {describe(s)}" for i, s in enumerate(self.steps(), start=1)]

    def meta(self) -> dict[str, Any]:
        """The run.json ``plan`` object."""
        return {"name": self.name, "version": self.version, "params": self.params}


# --------------------------------------------------------------------------- building blocks


def _levels(start: float, end: float, n: int) -> list[float]:
    """``n`` equal steps from ``start`` (excluded) to ``end`` (included)."""
    return [start + (end - start) * k / n for k in range(1, n + 1)]


def _quarter_levels(p: LoopParams, start: float, end: float) -> list[float]:
    """The equal torque steps of a quarter plus the extra levels (+-``extra_levels_pct`` of
    the rated torque, e.g. the lost-motion torque) that lie inside it, in path order."""
    levels = set(_levels(start, end, p.steps_per_quarter))
    lo, hi = min(start, end), max(start, end)
    for pct in p.extra_levels_pct:
        for value in (p.rated_torque_Nm * pct / 100.0, -p.rated_torque_Nm * pct / 100.0):
            if lo < value < hi:
                levels.add(value)
    return sorted(levels, key=lambda v: abs(v - start))


def ramp_segments(p: LoopParams, start: float, end: float) -> Iterator[Ramp]:
    """Ramps from ``start`` to ``end`` N*m: at ``rate_Nm_per_s``, but at ``zero_rate_Nm_per_s``
    inside the band |T| < ``zero_band_Nm``, where the output crosses the free play (a slow
    crossing keeps the flank impact and the drag torque small)."""
    z, slow = p.zero_band_Nm, p.zero_rate_Nm_per_s
    if z <= 0 or slow is None or start == end:
        yield Ramp(end, p.rate_Nm_per_s)
        return
    sign = 1.0 if end > start else -1.0
    edges = sorted({e for e in (-z, z) if (e - start) * sign > 0 and (end - e) * sign > 0},
                   key=lambda e: e * sign)
    here = start
    for point in [*edges, end]:
        mid = 0.5 * (here + point)
        yield Ramp(point, slow if abs(mid) < z else p.rate_Nm_per_s)
        here = point


def _quarter(p: LoopParams, start: float, end: float) -> Iterator[Step]:
    """One quarter cycle from ``start`` to ``end`` N*m in the plan's loading mode."""
    if p.mode == "constant_rate":
        yield from ramp_segments(p, start, end)
        # hold at the quarter's end (the peaks and zero): the drive lags a ramp by its time
        # constant, and the loop analysis needs the torque to reach +-T
        yield Settle(p.settle_rate_arcmin_per_s, p.settle_hold_s, 0.0, p.settle_timeout_s)
    elif p.mode == "equal_torque":
        here = start
        for level in _quarter_levels(p, start, end):
            yield from ramp_segments(p, here, level)
            here = level
            yield Settle(p.settle_rate_arcmin_per_s, p.settle_hold_s, 0.0, p.settle_timeout_s)
            if p.dwell_s > 0:
                yield Dwell(p.dwell_s)
            if p.sample_s > 0:
                yield Sample(p.sample_s)
    else:
        settle = Settle(p.settle_rate_arcmin_per_s, p.settle_hold_s, 0.0, p.settle_timeout_s)
        yield StepTwist(p.twist_step_arcmin, end, p.rate_Nm_per_s, settle, p.dwell_s,
                        p.sample_s, p.steps_per_quarter,
                        zero_band_Nm=p.zero_band_Nm if p.zero_rate_Nm_per_s else 0.0,
                        zero_rate_Nm_per_s=p.zero_rate_Nm_per_s)
    yield Checkpoint(f"{start:+g} -> {end:+g} N*m")


def hysteresis_loop(p: LoopParams) -> Iterator[Step]:
    """The loop itself, from -T: -T -> 0 -> +T -> 0 -> -T, ``cycles`` times (GB/T order)."""
    t = p.amplitude_Nm
    for _ in range(p.cycles):
        for start, end in ((-t, 0.0), (0.0, t), (t, 0.0), (0.0, -t)):
            yield from _quarter(p, start, end)


def preload(p: LoopParams) -> Iterator[Step]:
    """From rest to -T, with ``pre_cycles`` full cycles -T -> +T -> -T (not recorded; at the
    full rate, no slow zero crossing)."""
    t = p.amplitude_Nm
    yield Ramp(-t, p.rate_Nm_per_s)
    for _ in range(p.pre_cycles):
        yield Ramp(t, p.rate_Nm_per_s)
        yield Ramp(-t, p.rate_Nm_per_s)
    yield Settle(p.settle_rate_arcmin_per_s, p.settle_hold_s, 0.0, p.settle_timeout_s)
    yield Checkpoint("preloaded to -T")


def hysteresis_run(p: LoopParams, label: str, test: dict[str, Any] | None = None,
                   *, label_from_input: bool = False) -> Iterator[Step]:
    """One recorded run: torque zero, preload, the loop, back to zero and torque zero."""
    yield ReadTorqueZero("before", p.zero_window_s, p.rate_Nm_per_s)
    yield from preload(p)
    yield BeginRun(label, {**p.test_meta(), **(test or {})}, label_from_input=label_from_input)
    yield from hysteresis_loop(p)
    yield ReadTorqueZero("after", p.zero_window_s, p.rate_Nm_per_s)
    yield EndRun()
    yield Checkpoint(f"run {label} done")


def run_label(position_deg: float, amplitude_pct: float, repeat: int,
              temperature_C: float | None = None) -> str:
    """``[T25C-]pos090-a100-r0``: a readable, folder-safe run label."""
    pos = f"pos{_num(position_deg, 3)}"
    temp = "" if temperature_C is None else f"T{_num(temperature_C, 0)}C-"
    return f"{temp}{pos}-a{_num(amplitude_pct, 0)}-r{repeat}"


def _num(value: float, width: int) -> str:
    """A number for a folder name: 90 -> '090' (width 3), 2.5 -> '2p5', -10 -> 'm10'."""
    sign = "m" if value < 0 else ""
    value = abs(value)
    text = f"{int(value):0{width}d}" if value == int(value) else f"{value:g}".replace(".", "p")
    return sign + text


def campaign_steps(loop: LoopParams, axes: CampaignAxes) -> Iterator[Step]:
    """Temperatures (outer) x positions x amplitudes x repeats (inner) of hysteresis runs."""
    temps: list[float | None] = list(axes.temperatures_C) or [None]
    for temp in temps:
        if temp is not None:
            yield SetAmbient(temp)
            yield WaitTemperature(temp, axes.temperature_tolerance_C, axes.temperature_timeout_s)
        for pos in axes.positions_deg:
            yield LockInput(pos)
            for amp in axes.amplitudes_pct:
                p = loop.model_copy(update={"amplitude_pct": amp})
                for k in range(axes.repeats):
                    test: dict[str, Any] = {"input_angle_deg": pos, "repeat": k}
                    if temp is not None:
                        test["temperature_setpoint_C"] = temp
                    yield from hysteresis_run(p, run_label(pos, amp, k, temp), test)


def hysteresis_plan(loop: LoopParams, position_deg: float | None = None) -> Plan:
    """A single hysteresis run (``rig measure``), optionally at a locked input angle."""

    def build() -> Iterator[Step]:
        test: dict[str, Any] = {}
        if position_deg is not None:
            yield LockInput(position_deg)
            test["input_angle_deg"] = position_deg
        label = run_label(position_deg or 0.0, loop.amplitude_pct, 0)
        yield from hysteresis_run(loop, label, test, label_from_input=position_deg is None)

    params = {"loop": loop.model_dump(), "position_deg": position_deg}
    return Plan("hysteresis", params, build)


def campaign_plan(loop: LoopParams, axes: CampaignAxes) -> Plan:
    """Multi-position / multi-amplitude / multi-temperature / repeated hysteresis runs."""
    params = {"loop": loop.model_dump(), "axes": axes.model_dump()}
    return Plan("hysteresis-campaign", params, lambda: campaign_steps(loop, axes))


# --------------------------------------------------------------------------- transmission error

TE_KIND = "transmission_error"
Direction = Literal["forward", "reverse"]


class TEParams(BaseModel):
    """Parameters of one transmission error run (docs/run-format.md, "A transmission error
    run"): the input turns at ``input_speed_rpm`` through ``output_revolutions`` output
    revolutions in each of ``directions`` under a brake torque of ``brake_torque_fraction``
    of the rated torque; ``ratio`` is the signed reduction ratio (``-8`` for the seed 000
    45/40 pair). Times in s, angles in deg."""

    model_config = _STRICT

    rated_torque_Nm: RATED_TORQUE_NM.type
    ratio: float
    input_speed_rpm: INPUT_SPEED_RPM.type = 120.0
    brake_torque_fraction: float = Field(0.2, gt=0, le=1)
    output_revolutions: float = Field(1.0, ge=1, le=100)
    directions: list[Direction] = Field(default_factory=lambda: ["forward", "reverse"],
                                        min_length=1, max_length=2)
    lead_in_output_deg: float = Field(10.0, ge=0, le=360)
    brake_rate_Nm_per_s: RATE_NM_PER_S.type = 20.0
    stall_s: float = Field(0.5, gt=0)
    overspeed_factor: float = Field(1.5, gt=1)
    jump_tolerance_deg: float = Field(0.1, gt=0)
    zero_window_s: WINDOW_S.type = 0.2
    coupling_index_deg: float | None = Field(None, ge=0, lt=360)
    """Where the coupling between the output and its encoder is indexed (deg, as the operator
    set it; None: not stated): ``rig te-calibrate`` needs its two runs 180 deg apart."""

    @field_validator("ratio")
    @classmethod
    def _ratio(cls, value: float) -> float:
        if not (abs(value) >= 1.0 and abs(value) <= 10_000):
            raise ValueError(f"the ratio must be a reduction ratio with 1 <= |ratio| <= 10000 "
                             f"(signed: negative when the output turns against the input), "
                             f"got {value!r}")
        return value

    @field_validator("directions")
    @classmethod
    def _distinct(cls, value: list[str]) -> list[str]:
        if len(set(value)) != len(value):
            raise ValueError(f"each direction once, got {value}")
        return value

    @property
    def brake_torque_Nm(self) -> float:
        """The brake torque's magnitude (N*m)."""
        return self.rated_torque_Nm * self.brake_torque_fraction

    def test_meta(self) -> dict[str, Any]:
        """The run.json ``test`` keys of docs/run-format.md for a transmission error run."""
        return {
            "kind": TE_KIND,
            "ratio": self.ratio,
            "input_speed_rpm": self.input_speed_rpm,
            "brake_torque_Nm": self.brake_torque_Nm,
            "brake_torque_fraction": self.brake_torque_fraction,
            "directions": list(self.directions),
            "output_revolutions": self.output_revolutions,
            "rated_torque_Nm": self.rated_torque_Nm,
            "lead_in_output_deg": self.lead_in_output_deg,
        } | ({} if self.coupling_index_deg is None
             else {"coupling_index_deg": self.coupling_index_deg})

    def turn(self, direction: str) -> TurnInput:
        """The :class:`TurnInput` step of one direction."""
        return TurnInput(self.input_speed_rpm, 1 if direction == "forward" else -1,
                         self.brake_torque_Nm, self.ratio, self.output_revolutions,
                         self.lead_in_output_deg, self.brake_rate_Nm_per_s, self.stall_s,
                         overspeed_factor=self.overspeed_factor,
                         jump_tolerance_deg=self.jump_tolerance_deg)


def unit_ratio(unit: dict[str, Any]) -> float | None:
    """The signed reduction ratio of docs/run-format.md from a run.json ``unit``: for an
    internal involute pair whose output is the external gear, ``-z_external / (z_internal -
    z_external)`` (-8 for 45/40); ``unit.ratio`` when given; else None."""
    given = unit.get("ratio")
    if isinstance(given, int | float) and not isinstance(given, bool) and given:
        return float(given)
    z1, z2 = unit.get("z_internal"), unit.get("z_external")
    if (unit.get("kind", "internal_involute") == "internal_involute"
            and isinstance(z1, int) and isinstance(z2, int) and z1 > z2 > 0):
        return -z2 / (z1 - z2)
    return None


def te_label(p: TEParams, repeat: int = 0, temperature_C: float | None = None) -> str:
    """``[T25C-]te-s120-b20-r0``: speed (rpm), brake (% of rated), repeat."""
    temp = "" if temperature_C is None else f"T{_num(temperature_C, 0)}C-"
    return (f"{temp}te-s{_num(p.input_speed_rpm, 0)}-b{_num(100 * p.brake_torque_fraction, 0)}"
            f"-r{repeat}")


def te_run(p: TEParams, label: str, test: dict[str, Any] | None = None) -> Iterator[Step]:
    """One recorded transmission error run: torque zero, then each direction turned under
    the brake torque, the torque zero after, end."""
    yield ReadTorqueZero("before", p.zero_window_s, p.brake_rate_Nm_per_s)
    yield BeginRun(label, {**p.test_meta(), **(test or {})})
    for direction in p.directions:
        yield p.turn(direction)
        yield Checkpoint(f"{direction} done")
    yield ReadTorqueZero("after", p.zero_window_s, p.brake_rate_Nm_per_s)
    yield EndRun()
    yield Checkpoint(f"run {label} done")


def te_plan(p: TEParams, repeats: int = 1) -> Plan:
    """Transmission error runs (``rig measure --test transmission-error``)."""

    def build() -> Iterator[Step]:
        for k in range(repeats):
            yield from te_run(p, te_label(p, k), {"repeat": k})

    return Plan(TE_KIND, {"te": p.model_dump(), "repeats": repeats}, build)


def te_campaign_plan(p: TEParams, axes: CampaignAxes) -> Plan:
    """A campaign of transmission error runs: temperatures (outer) x repeats."""

    def build() -> Iterator[Step]:
        temps: list[float | None] = list(axes.temperatures_C) or [None]
        for temp in temps:
            if temp is not None:
                yield SetAmbient(temp)
                yield WaitTemperature(temp, axes.temperature_tolerance_C,
                                      axes.temperature_timeout_s)
            for k in range(axes.repeats):
                test: dict[str, Any] = {"repeat": k}
                if temp is not None:
                    test["temperature_setpoint_C"] = temp
                yield from te_run(p, te_label(p, k, temp), test)

    return Plan(f"{TE_KIND}-campaign", {"te": p.model_dump(), "axes": axes.model_dump()},
                build)
