"""Analyse stored runs: loop metrics beside the reference nominal model's prediction.

This is the application service behind ``rig analyse`` (and, later, the sequencer and the page):
it reads what the run says about itself (rated torque, encoder resolution, unit data) and calls
the pure numerics of :mod:`analysis.loop` and :mod:`analysis.models.nominal`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from analysis.errors import AnalysisError
from analysis.loop import PROFILES, LoopResult, analyse_loop, twist_arcmin
from analysis.models.by_kind import LoopModel
from analysis.models.by_kind import nominal_model_for_unit as model_by_kind
from rig.core.errors import RigError
from rig.core.ranges import ANGLE_READING_DEG, RATED_TORQUE_NM, TORQUE_READING_MAX_RATED
from rig.runformat import Run

ARCMIN_PER_REV = 360.0 * 60.0

# The keys every per-run JSON object carries (users' scripts rely on them).
METRIC_KEYS = (
    "lost_motion_arcmin",
    "backlash_arcmin",
    "stiffness_Nm_per_arcmin",
    "loop_area_J",
    "torque_offset_Nm",
)


def loop_centre_arcmin(twist_arcmin: np.ndarray) -> float:
    """Centre of a loop's twist range (arcmin): midway between its 0.5 and 99.5 percentiles.

    Robust to a few outliers; used only to put loops and model loops on a common zero for
    display (the twist zero of a run is arbitrary).
    """
    low, high = np.nanpercentile(twist_arcmin, [0.5, 99.5])
    return 0.5 * float(low + high)


TWIST_COLUMN = "twist_arcmin"
"""The samples' twist column of the Python API (``.to_arrow()``/``.to_pandas()``) and of
every sample export (``rig export``): :func:`sample_twist_arcmin`."""


def run_twist_arcmin(run: Run) -> np.ndarray:
    """Twist of the run in arcmin, as :func:`analyse_run` computes it
    (:func:`analysis.loop.twist_arcmin`): output angle minus input angle / ``test.ratio``
    when both are known, else the output angle alone (input locked). Its zero is the
    encoder's (arbitrary: run-format.md)."""
    ratio = run.test.get("ratio")
    if run.input_angle_deg is not None and ratio:
        return twist_arcmin(run.output_angle_deg, run.input_angle_deg, float(ratio))
    return twist_arcmin(run.output_angle_deg)


def sample_twist_arcmin(run: Run) -> np.ndarray:
    """The ``twist_arcmin`` column (arcmin): :func:`run_twist_arcmin` less its loop centre
    (:func:`loop_centre_arcmin`, midway between the 0.5 and 99.5 percentiles of the twist),
    the zero the loop plots and the model overlay use; the loop's metrics do not depend on
    the zero."""
    twist = run_twist_arcmin(run)
    if not np.isfinite(twist).any():
        return twist
    return twist - loop_centre_arcmin(twist)


def _finite_or_none(value: float | None) -> float | None:
    """JSON has no infinity or NaN: an unknown value is written as null."""
    if value is None or not np.isfinite(value):
        return None
    return float(value)


@dataclass
class RunAnalysis:
    """Everything ``rig analyse`` reports about one run."""

    run: Run
    twist_arcmin: np.ndarray
    loop: LoopResult
    model: LoopModel | None
    assumptions: list[str] = field(default_factory=list)
    rated_torque_Nm: float = 0.0
    lost_motion_pct: float = 3.0
    profile: str = "nabtesco"
    channel_lag_s: float = 0.0
    encoder_faults: list[str] = field(default_factory=list)

    def model_twist_arcmin(self) -> np.ndarray | None:
        """The model loop for this run's torque history, shifted onto the measured twist.

        The twist zero is arbitrary (run-format.md), so the model loop is shifted so that its
        centre (:func:`loop_centre_arcmin`) lies on the measured loop's centre.
        """
        if self.model is None:
            return None
        start_flank = int(self.run.test.get("start_flank", -1) or -1)
        model = self.model.twist_arcmin(self.run.torque_Nm, start_flank=start_flank)
        return model + (loop_centre_arcmin(self.twist_arcmin) - loop_centre_arcmin(model))

    def to_dict(self) -> dict[str, Any]:
        """The JSON object of ``rig analyse --json`` for this run."""
        loop = self.loop.to_dict()
        out: dict[str, Any] = {"run_id": self.run.run_id}
        for key in METRIC_KEYS:
            out[key] = loop.get(key)
        # every other metric the loop computed (per side stiffness, HD K1-K3 ...)
        for key, value in loop.items():
            if key not in out and key not in ("uncertainty", "errors"):
                out[key] = value
        out["uncertainty"] = loop.get("uncertainty", {})
        out["errors"] = loop.get("errors", {})
        out["profile"] = self.profile
        out["lost_motion_pct"] = self.lost_motion_pct
        out["rated_torque_Nm"] = self.rated_torque_Nm
        out["n_samples"] = self.run.n_samples
        out["n_cycles"] = self.loop.n_cycles
        out["channel_lag_s"] = self.channel_lag_s
        out["encoder_faults"] = list(self.encoder_faults)
        if self.model is not None:
            out["model"] = {
                "name": "reference nominal model (rig-run/1)",
                "lost_motion_arcmin": _finite_or_none(
                    self.model.lost_motion_arcmin(self.rated_torque_Nm, self.lost_motion_pct)
                ),
                "backlash_arcmin": _finite_or_none(self.model.backlash_arcmin),
                "stiffness_Nm_per_arcmin": _finite_or_none(self.model.stiffness_Nm_per_arcmin),
                "play_arcmin": _finite_or_none(self.model.play_arcmin),
            }
        else:
            out["model"] = None
        out["assumptions"] = list(self.assumptions)
        out["notes"] = list(self.run.notes)
        return out


UNIT_IDENTITY_KEYS = frozenset({"serial", "design", "name"})
"""Unit keys that name the unit (run-format.md) and are no design data: known keys, never an
"unknown unit key" for the model."""


def nominal_model_for_unit(
    unit: dict[str, Any], rated_torque_Nm: float | None = None
) -> tuple[LoopModel | None, list[str]]:
    """The nominal loop model for a run's ``unit`` object, by ``unit.kind``
    (:func:`analysis.models.by_kind.nominal_model_for_unit`). A unit the model cannot use gives
    no model and says why; never an error, because the measured metrics stand on their own.
    """
    if not unit:
        return None, ["run.json has no unit data: no model prediction"]
    design = {k: v for k, v in unit.items() if k not in UNIT_IDENTITY_KEYS}
    try:
        return model_by_kind(design, rated_torque_Nm)
    except AnalysisError as exc:
        return None, [f"no model prediction: {exc}"]


def resolve_profile(profile: str | None, percent: float | None) -> tuple[str, float]:
    """The lost-motion band: a named vendor profile, or an explicit percent of rated torque."""
    if percent is not None:
        if not 0.0 < percent < 100.0:
            raise RigError(f"--percent must be between 0 and 100, got {percent}")
        return (profile or "custom"), float(percent)
    name = profile or "nabtesco"
    if name not in PROFILES:
        raise RigError(f"unknown profile {name!r}; known: {', '.join(sorted(PROFILES))}")
    return name, float(PROFILES[name])


MIN_LOOP_SAMPLES = 20
"""Fewest samples of a hysteresis loop: four quarters of at least a few readings each."""
TORQUE_READING_MAX = TORQUE_READING_MAX_RATED
"""A torque reading beyond this multiple of the rated torque is no reading (a sensor
overload or a corrupt cell), whatever its sign: nothing in the run may rest on it."""


def check_samples(run: Run, rated_torque_Nm: float) -> None:
    """RigError when the samples cannot be a measured loop: too few rows, a torque beyond
    :data:`TORQUE_READING_MAX` x rated or an angle beyond ``ANGLE_READING_DEG``
    (:mod:`rig.core.ranges`; naming its row), or an output angle that never moves."""
    where = f"{run.path / 'samples.csv' if run.path else run.run_id}"
    if run.n_samples < MIN_LOOP_SAMPLES:
        raise RigError(f"{where}: {run.n_samples} samples; a hysteresis loop needs at least "
                       f"{MIN_LOOP_SAMPLES}")
    torque = np.asarray(run.torque_Nm, dtype=float)
    with np.errstate(invalid="ignore"):
        wild = np.flatnonzero(np.abs(torque) > TORQUE_READING_MAX * rated_torque_Nm)
    if wild.size:
        k = int(wild[0])
        raise RigError(f"{where}: torque_Nm of sample {k + 1} (t = {run.t_s[k]:g} s) is "
                       f"{torque[k]:g} N·m, beyond {TORQUE_READING_MAX:g} x the rated "
                       f"{rated_torque_Nm:g} N·m: not a reading ({wild.size} such samples)")
    for name in ("output_angle_deg", "input_angle_deg"):
        values = getattr(run, name)
        if values is None:
            continue
        with np.errstate(invalid="ignore"):
            wild = np.flatnonzero(np.abs(np.asarray(values, dtype=float))
                                  > ANGLE_READING_DEG.high)
        if wild.size:
            k = int(wild[0])
            raise RigError(f"{where}: {name} of sample {k + 1} (t = {run.t_s[k]:g} s) is "
                           f"{values[k]:g} deg, beyond +-{ANGLE_READING_DEG.high:g} deg: not "
                           f"a reading ({wild.size} such samples)")
    angle = np.asarray(run.output_angle_deg, dtype=float)
    finite = angle[np.isfinite(angle)]
    if finite.size < MIN_LOOP_SAMPLES or float(np.ptp(finite)) == 0.0:
        raise RigError(f"{where}: output_angle_deg never moves"
                       f"{f' (always {finite[0]:g} deg)' if finite.size else ''}: an angle "
                       "that never moves under a moving torque is no measurement")


def analyse_run(
    run: Run,
    *,
    profile: str | None = None,
    percent: float | None = None,
    rated_torque_Nm: float | None = None,
    hd_T1_Nm: float | None = None,
    hd_T2_Nm: float | None = None,
) -> RunAnalysis:
    """Loop metrics of one run and the reference nominal model's prediction for its unit."""
    name, pct = resolve_profile(profile, percent)
    assumptions: list[str] = []
    test = run.test
    rated = rated_torque_Nm if rated_torque_Nm is not None else test.get("rated_torque_Nm")
    if rated is None:
        raise RigError(
            f"run {run.run_id!r}: run.json has no test.rated_torque_Nm; the ±{pct:g} % band "
            "needs it (give --rated-torque)"
        )
    rated = float(rated)
    if not rated > 0:
        raise RigError(f"run {run.run_id!r}: rated torque must be > 0 N·m, got {rated}")
    problem = RATED_TORQUE_NM.problem("rated torque", rated)
    if problem is not None:
        raise RigError(f"run {run.run_id!r}: {problem}")
    check_samples(run, rated)

    ratio = test.get("ratio")
    if run.input_angle_deg is not None and ratio:
        twist = twist_arcmin(run.output_angle_deg, run.input_angle_deg, float(ratio))
    else:
        twist = twist_arcmin(run.output_angle_deg)
        if run.input_angle_deg is not None:
            assumptions.append(
                "input angle recorded but test.ratio not given: twist = output angle alone "
                "(input locked)"
            )

    counts = run.sensors.get("encoder_counts_per_rev")
    resolution = ARCMIN_PER_REV / float(counts) if counts else 0.0
    if not counts:
        assumptions.append(
            "sensors.encoder_counts_per_rev unknown: encoder resolution not in the uncertainty"
        )
    t1 = hd_T1_Nm if hd_T1_Nm is not None else test.get("hd_T1_Nm")
    t2 = hd_T2_Nm if hd_T2_Nm is not None else test.get("hd_T2_Nm")
    loop = analyse_loop(
        run.t_s,
        run.torque_Nm,
        twist,
        rated_torque_Nm=rated,
        lost_motion_pct=pct,
        twist_resolution_arcmin=resolution,
        hd_T1_Nm=None if t1 is None else float(t1),
        hd_T2_Nm=None if t2 is None else float(t2),
        command_Nm=_numeric_column(run, "torque_command_Nm"),
    )

    lag_s = channel_lag_s(run.t_s, run.torque_Nm, twist)
    if lag_s:
        assumptions.append(
            f"the torque channel is {'late' if lag_s > 0 else 'ahead'} by about {abs(lag_s):.3g} s "
            "against the twist (channel alignment): the loop pairs each twist with the torque "
            "of another instant")

    model, model_assumptions = nominal_model_for_unit(run.unit, rated)
    assumptions.extend(model_assumptions)
    faults = encoder_faults(run, twist, loop, model, rated,
                            ARCMIN_PER_REV / float(counts) if counts else 0.0, lag_s)
    assumptions.extend(f"no verdict: {fault}" for fault in faults)
    return RunAnalysis(
        encoder_faults=faults,
        channel_lag_s=lag_s,
        run=run,
        twist_arcmin=twist,
        loop=loop,
        model=model,
        assumptions=assumptions,
        rated_torque_Nm=rated,
        lost_motion_pct=pct,
        profile=name,
    )


def channel_lag_s(t_s: np.ndarray, torque_Nm: np.ndarray, twist: np.ndarray) -> float:
    """Lag (s) of the torque channel behind the twist (negative: ahead), 0 when the channels
    are in step: the shift that best explains the loaded flanks
    (:func:`analysis.channels.lag.channel_lag_samples`, searched up to 10 samples; a lag
    at that bound is at least that large)."""
    from analysis.channels.lag import channel_lag_samples
    from analysis.loop.branches import white_noise_std

    t = np.asarray(t_s, dtype=float)
    torque, tw = np.asarray(torque_Nm, dtype=float), np.asarray(twist, dtype=float)
    ok = np.isfinite(t) & np.isfinite(torque) & np.isfinite(tw)
    if ok.sum() < 200:
        return 0.0
    if not ok.all():  # a long run with no gap is not copied
        t, torque, tw = t[ok], torque[ok], tw[ok]
    del ok
    sigma = max(white_noise_std(tw), 1e-9)
    lag = channel_lag_samples(t, torque, tw, sigma)
    return float(-lag * np.median(np.diff(t))) if lag else 0.0


def encoder_faults(run: Run, twist: np.ndarray, loop: LoopResult, model: LoopModel | None,
                   rated_Nm: float, count_arcmin: float, lag_s: float) -> list[str]:
    """The twist steps and frozen readings the torque does not explain, one line each
    (:func:`analysis.loop.encoder_faults.find_encoder_faults`; issue 33 item 1). The
    stiffness is the unit's nominal (the run's own without a model), the play the nominal's
    (the run's backlash without one). A step the input encoder's own reading accounts for
    names the input encoder."""
    from analysis.loop.branches import white_noise_std
    from analysis.loop.encoder_faults import find_encoder_faults

    metrics = loop.metrics

    def measured(key: str) -> float | None:
        return metrics[key].value if key in metrics else None

    own = measured("stiffness_Nm_per_arcmin")
    if own is not None and own < 0:  # the twist runs against the torque: that is the fault
        return []                    # named (an encoder counting the other way), not a jump
    k = model.stiffness_Nm_per_arcmin if model is not None else None
    if not (k is not None and np.isfinite(k) and k > 0):
        k = measured("stiffness_Nm_per_arcmin")
    if not (k is not None and np.isfinite(k) and k > 0):
        return []
    play = model.play_arcmin if model is not None else None
    if not (play is not None and np.isfinite(play)):
        play = measured("backlash_arcmin") or 0.0
    t = np.asarray(run.t_s, dtype=float)
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    found = find_encoder_faults(
        run.torque_Nm, twist, run.output_angle_deg, loop.branches.sample_direction(),
        rated_torque_Nm=rated_Nm, stiffness_Nm_per_arcmin=float(k), count_arcmin=count_arcmin,
        twist_noise_arcmin=white_noise_std(twist), torque_noise_Nm=white_noise_std(run.torque_Nm),
        torque_offset_Nm=measured("torque_offset_Nm") or 0.0,
        play_arcmin=float(play), row_period_s=dt, channel_lag_s=lag_s)
    ratio = run.test.get("ratio")
    out = []
    for fault in found:
        device = "output encoder"
        if fault.kind == "step" and run.input_angle_deg is not None and ratio:
            d_out = float(run.output_angle_deg[fault.stop] - run.output_angle_deg[fault.start])
            d_in = float(run.input_angle_deg[fault.stop] - run.input_angle_deg[fault.start])
            if abs(d_in / float(ratio)) > abs(d_out):
                device = "input encoder"
        out.append(fault.describe(t, device))
    return out


def _numeric_column(run: Run, name: str) -> np.ndarray | None:
    """A numeric extra column of the run (e.g. the rig's torque command), None if absent."""
    col = run.data.get(name)
    return col if isinstance(col, np.ndarray) else None
