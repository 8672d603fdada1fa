"""Campaign files (TOML): the unit under test, the plan, what varies, and pass/fail limits.

docs/campaigns.md describes every key. Errors name the file and the key (pydantic), a TOML
syntax error the file, line and column. Results of a campaign: per-run metrics beside the
model's prediction, lost motion against position (mean, spread, and the runout signature: a
once-per-revolution sine fitted over the input angle) and pass/fail with the cause.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from analysis.loop import PROFILES
from rig.core.errors import RigError
from rig.core.json_files import read_json_file
from rig.core.ranges import (
    INPUT_SPEED_RPM,
    LIMIT_ARCMIN,
    LIMIT_ARCSEC,
    LIMIT_STIFFNESS_NM_PER_ARCMIN,
    TORQUE_LIMIT_NM,
)
from rig.core.toml_files import describe_validation_error, read_toml
from rig.plans import (
    TE_KIND,
    CampaignAxes,
    Direction,
    LoopParams,
    Plan,
    TEParams,
    campaign_plan,
    check_plan_size,
    te_campaign_plan,
    unit_ratio,
)
from rig.results.outcome import campaign_outcome, run_outcome
from rig.runformat.meta_check import unit_problems

PROFILE_NAMES = tuple(PROFILES)
"""The lost-motion definitions a campaign may name (analysis/loop/__init__.py PROFILES)."""


class CampaignError(RigError):
    """A campaign file is malformed: names the file and the key (or line:column)."""


class Limits(BaseModel):
    """Pass/fail limits; None = not checked. Lost motion and backlash in arcmin (at most),
    stiffness in N*m/arcmin (at least); a transmission error run's peak-to-peak TE in arcsec
    and its two-direction hysteresis in arcmin (at most)."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)

    lost_motion_arcmin_max: LIMIT_ARCMIN.after(Field(gt=0)) | None = None
    backlash_arcmin_max: LIMIT_ARCMIN.after(Field(gt=0)) | None = None
    stiffness_Nm_per_arcmin_min: LIMIT_STIFFNESS_NM_PER_ARCMIN.after(Field(gt=0)) | None = None
    te_pp_max_arcsec: LIMIT_ARCSEC.after(Field(gt=0)) | None = None
    te_hysteresis_max_arcmin: LIMIT_ARCMIN.after(Field(gt=0)) | None = None

    def check(self, run: dict[str, Any]) -> list[str]:
        """The causes of failure of one run's metrics (empty: passed; a metric the run's
        design cannot measure is not applicable, not a cause: rig/results/outcome.py)."""
        return run_outcome(run, self.model_dump())[1]

    def outcome(self, run: dict[str, Any]) -> str:
        """"ok", "not_ok" or "incomplete" (rig/results/outcome.py)."""
        return run_outcome(run, self.model_dump())[0]


class UnitSection(BaseModel):
    """The unit under test: ``file`` (a run.json ``unit`` JSON, relative to the campaign
    file) and/or the unit keys inline (they override the file's); ``serial`` names it."""

    model_config = ConfigDict(extra="allow")

    file: str | None = None
    serial: str | None = None


class SimulationSection(BaseModel):
    """Used only with ``--simulated``: the plant's tables beyond the unit (``effects``,
    ``noise``, ``housing``, ``rig``; docs/plant.md) and its noise ``seed``."""

    model_config = ConfigDict(extra="forbid", strict=True)

    seed: int | None = None
    plant: dict[str, Any] = Field(default_factory=dict)


class TESection(BaseModel):
    """The transmission error test of a campaign (``test = "transmission_error"``): input
    speed (rpm), brake torque (fraction of ``plan.rated_torque_Nm``), output revolutions per
    direction, the directions, and the signed ratio (default: the unit's)."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)

    input_speed_rpm: INPUT_SPEED_RPM.type = 120.0
    brake_torque_fraction: float = Field(0.2, gt=0, le=1)
    output_revolutions: float = Field(1.0, ge=1, le=100)
    directions: list[Direction] = Field(default_factory=lambda: ["forward", "reverse"],
                                        min_length=1, max_length=2)
    ratio: float | None = None


class CampaignFile(BaseModel):
    """A whole campaign file (validated). ``unit`` is the resolved unit mapping."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
    description: str = ""
    operator: str | None = None
    calibration_override: str | None = Field(None, min_length=1, max_length=500)
    """Why the campaign may run with a sensor calibration past due (recorded in each run)."""
    profile: Literal[PROFILE_NAMES] = "nabtesco"  # type: ignore[valid-type]
    torque_limit_Nm: TORQUE_LIMIT_NM.type | None = Field(None, allow_inf_nan=False, strict=True)
    unit: UnitSection
    test: Literal["lost_motion", "transmission_error"] = "lost_motion"
    """Which test the campaign's runs are: the hysteresis loop (``plan``) or the
    transmission error (``te``, with ``plan.rated_torque_Nm``)."""
    te: TESection = Field(default_factory=TESection)
    plan: LoopParams
    axes: CampaignAxes = Field(default_factory=CampaignAxes)
    limits: Limits = Field(default_factory=Limits)
    simulation: SimulationSection = Field(default_factory=SimulationSection)
    confirm_long: bool = Field(False, strict=True)
    """The campaign may take longer than :data:`rig.core.ranges.PLAN_CONFIRM_S` (8 h)."""
    source: str = "<memory>"

    @model_validator(mode="after")
    def _small_enough(self) -> CampaignFile:
        a = self.axes
        if self.test == TE_KIND:
            if list(a.positions_deg) != [0.0] or list(a.amplitudes_pct) != [100.0]:
                raise ValueError("axes.positions_deg / axes.amplitudes_pct: a "
                                 "transmission_error campaign turns the input under the "
                                 "brake torque; positions and amplitudes do not apply")
            return self
        check_plan_size(self.plan, len(a.positions_deg) * len(a.amplitudes_pct)
                        * max(1, len(a.temperatures_C)) * a.repeats)
        return self

    def unit_data(self) -> dict[str, Any]:
        """The run.json ``unit`` mapping: the file's keys, then the inline ones."""
        data: dict[str, Any] = {}
        if self.unit.file is not None:
            path = Path(self.unit.file)
            if not path.is_absolute() and self.source != "<memory>":
                path = Path(self.source).parent / path
            try:
                data = read_json_file(path, CampaignError, "unit file")
            except CampaignError as exc:
                text = str(exc)
                raise CampaignError(f"{self.source}: unit.file: {text}"
                                    if text.startswith("cannot read")
                                    else f"{text} (named by {self.source}: unit.file)") from None
            if not isinstance(data, dict):
                raise CampaignError(f"{path}: a unit must be a JSON object (unit.file)")
        inline = {k: v for k, v in (self.unit.model_extra or {}).items()}
        data.update(inline)
        if self.unit.serial is not None:
            data["serial"] = self.unit.serial
        data.setdefault("serial", self.name)
        problems = unit_problems(data)
        if problems:
            raise CampaignError(f"{self.source}: {problems[0]}")
        return data

    def te_params(self) -> TEParams:
        """The transmission error parameters (CampaignError without a ratio)."""
        te = self.te
        ratio = te.ratio if te.ratio is not None else unit_ratio(self.unit_data())
        if ratio is None:
            raise CampaignError(f"{self.source}: key te.ratio: missing (the unit does not give "
                                "the reduction ratio)")
        try:
            return TEParams(rated_torque_Nm=self.plan.rated_torque_Nm, ratio=ratio,
                            input_speed_rpm=te.input_speed_rpm,
                            brake_torque_fraction=te.brake_torque_fraction,
                            output_revolutions=te.output_revolutions,
                            directions=list(te.directions))
        except ValidationError as exc:
            raise CampaignError(describe_validation_error(exc, self.source)) from exc

    def build_plan(self) -> Plan:
        if self.test == TE_KIND:
            return te_campaign_plan(self.te_params(), self.axes)
        return campaign_plan(self.plan, self.axes)


def campaign_from_mapping(data: dict[str, Any], source: str = "<memory>") -> CampaignFile:
    """Validate a parsed TOML mapping; errors name ``source`` and the key."""
    try:
        camp = CampaignFile.model_validate({**data, "source": source})
    except ValidationError as exc:
        raise CampaignError(describe_validation_error(exc, source)) from exc
    camp.unit_data()  # a unit file that cannot be read is an error now, not mid-campaign
    if camp.test == TE_KIND:
        camp.te_params()  # and a missing ratio
    return camp


def load_campaign(path: str | Path) -> CampaignFile:
    """Read and validate a campaign TOML (CampaignError naming file and key/line:column)."""
    data = read_toml(path, CampaignError, "campaign")
    return campaign_from_mapping(data, str(Path(path)))


# --------------------------------------------------------------------------- results


def runout_signature(angles_deg: list[float], values: list[float]) -> dict[str, Any] | None:
    """Least-squares fit ``v(theta) = mean + amplitude cos(theta - phase)`` over the input
    angle theta (deg): the once-per-revolution signature of runout (seed 000 eq. 4: the ring
    gear's eccentricity turns with the eccentric shaft). Needs 3 distinct angles (mod 360);
    returns None otherwise. ``residual_rms`` is in the values' unit."""
    theta = np.radians(np.asarray(angles_deg, dtype=float))
    v = np.asarray(values, dtype=float)
    keep = np.isfinite(v)
    theta, v = theta[keep], v[keep]
    if len(np.unique(np.round(np.degrees(theta) % 360.0, 6))) < 3:
        return None
    design = np.column_stack([np.ones_like(theta), np.cos(theta), np.sin(theta)])
    coef, *_ = np.linalg.lstsq(design, v, rcond=None)
    resid = v - design @ coef
    amplitude = float(math.hypot(coef[1], coef[2]))
    return {
        "mean": float(coef[0]),
        "amplitude": amplitude,
        "phase_deg": float(math.degrees(math.atan2(coef[2], coef[1])) % 360.0),
        "peak_to_peak": 2.0 * amplitude,
        "residual_rms": float(np.sqrt(np.mean(resid**2))),
        "n_positions": int(v.size),
    }


def batch_band(
    unit: dict[str, Any], rated_torque_Nm: float, pct: float, *, samples: int = 5000
) -> dict[str, Any] | None:
    """Where this design's production batch lies: the Monte Carlo lost motion over seed 000
    Table 1's tolerances (:mod:`analysis.models.seed000_batch`), worst eccentric-shaft
    position, as the central 95 % band (arcmin). None for a unit the batch model cannot use
    (another kind, or design data missing), with no error: the measurement stands alone."""
    from analysis.errors import AnalysisError
    from analysis.models.seed000_batch import lost_motion_batch
    from analysis.models.seed000_unit import InternalPairUnit

    kind = unit.get("kind", "internal_involute")
    if kind in ("cycloid", "beveloid"):
        return _kind_batch_band(unit, kind, rated_torque_Nm, pct, samples)
    if kind != "internal_involute":
        return None
    try:
        parsed, _ = InternalPairUnit.from_mapping(unit)
        batch = lost_motion_batch(parsed, samples=samples, seed=0,
                                  rated_torque_Nm=rated_torque_Nm, lost_motion_pct=pct)
    except AnalysisError:
        return None
    low, high = batch.band_arcmin(0.95)
    worst = batch.to_dict()["worst_position_arcmin"]
    return {"band_95_arcmin": [low, high], "median_arcmin": worst["median"],
            "samples": samples, "kind": "internal_involute",
            "what": "seed 000 Table 1 tolerances, worst position "
            "(seed 003's Monte Carlo method); `rig batch` for the whole distribution"}


def _kind_batch_band(unit: dict[str, Any], kind: str, rated_torque_Nm: float, pct: float,
                     samples: int) -> dict[str, Any] | None:
    """The batch band of a cycloid (seed 002's modification budget,
    :mod:`analysis.models.cycloid_batch`) or beveloid unit (seed 001's installation error
    budget, :mod:`analysis.models.beveloid_batch`), with the compensation advice; None when
    the unit's data cannot give one."""
    from analysis.errors import AnalysisError

    if kind == "cycloid":
        from analysis.models.cycloid_batch import cycloid_advice as advise
        from analysis.models.cycloid_batch import cycloid_batch as draw

        what = ("seed 002's modification budget (Table 2, JB/T 10419 grade 5: runouts, "
                "pitch deviations, eccentricity, crank bearings, grinding), worst crank "
                "position (seed 003's Monte Carlo method)")
    else:
        from analysis.models.beveloid_batch import beveloid_advice as advise
        from analysis.models.beveloid_batch import beveloid_batch as draw

        what = ("seed 001's installation error budget (eq. 8: center distance, lateral "
                "offset, axial position; runouts, bearings), worst position (seed 003's "
                "Monte Carlo method)")
    try:
        batch = draw(unit, rated_torque_Nm=rated_torque_Nm, lost_motion_pct=pct,
                     samples=samples)
        advice = advise(unit, rated_torque_Nm=rated_torque_Nm, lost_motion_pct=pct,
                        samples=samples)
    except (AnalysisError, KeyError, TypeError, ValueError):
        return None
    low, high = batch.band_arcmin(0.95)
    out = {"band_95_arcmin": [low, high],
           "median_arcmin": float(np.median(batch.worst_arcmin)),
           "samples": samples, "kind": kind, "what": what,
           "binding_fraction": batch.interference_fraction, "advice": advice}
    position = batch.position_band_arcmin(0.95)
    if position is not None:
        out["position_band_95_arcmin"] = list(position)
        out["nominal_relation"] = (
            "the band is each unit's worst crank position, where runouts, crank-bearing "
            "clearances and the thinnest tooth pair only add, so a perfect unit (the nominal "
            "model, mean over the mesh phases) lies below it by their size; at one random "
            f"position the batch spans {position[0]:.3f} .. {position[1]:.3f} arcmin")
    return out


def summarise(runs: list[dict[str, Any]], limits: Limits) -> dict[str, Any]:
    """Campaign results from the per-run dicts (``RunOutcome.to_dict()``): lost motion
    {mean, min, max, std} (arcmin) over completed runs, by position, its runout signature,
    the model's prediction, and pass/fail with every cause."""
    done = [r for r in runs if r.get("status") == "completed"]
    lm = [r["lost_motion_arcmin"] for r in done if r.get("lost_motion_arcmin") is not None]
    stats: dict[str, Any] = {"mean": None, "min": None, "max": None, "std": None, "n": len(lm)}
    if lm:
        stats.update(mean=float(np.mean(lm)), min=float(np.min(lm)), max=float(np.max(lm)),
                     std=float(np.std(lm, ddof=1)) if len(lm) > 1 else 0.0)
    by_position: dict[str, list[float]] = {}
    for r in done:
        if r.get("lost_motion_arcmin") is not None and r.get("input_angle_deg") is not None:
            by_position.setdefault(f"{r['input_angle_deg']:g}", []).append(
                r["lost_motion_arcmin"])
    angles = [float(k) for k in by_position]
    means = [float(np.mean(v)) for v in by_position.values()]
    model = next((r.get("model") for r in done if r.get("model")), None)
    causes = [c for r in runs for c in limits.check(r)]
    for r in runs:
        r["outcome"], r["limits"] = limits.outcome(r), limits.model_dump()
    if not runs:
        causes.append("no run was measured")
    return {
        "lost_motion_arcmin": stats,
        "lost_motion_by_position": [
            {"input_angle_deg": a, "lost_motion_arcmin": m, "n": len(by_position[f"{a:g}"])}
            for a, m in sorted(zip(angles, means, strict=True))
        ],
        "runout_signature": runout_signature(angles, means),
        "model": model,
        "limits": limits.model_dump(),
        "passed": not causes,
        "outcome": campaign_outcome([r["outcome"] for r in runs], "completed"),
        "failures": causes,
        "n_runs": len(runs),
        "n_completed": len(done),
    }
