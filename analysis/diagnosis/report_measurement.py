"""The report's ``measurement`` key: what the measuring system added to each run, and how much
of the null model's gap each of those took (issue 20, point 1).

For each nuisance the null model (free play, stiffness, run offsets) is fitted once with all
of them taken out (the diagnosis' own null) and once with that one left in; ``gap_share`` is
the share of the null's mean squared standardised residual that taking it out removed
(0: it changed nothing; close to 1: without it the measurement would have looked like a gap).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from analysis.diagnosis.data import PreparedRun, RunInput, prepare_run, remove_torque_zero
from analysis.diagnosis.fit import LinearFit, Stack, build_stack, fit


def _msr(f: LinearFit) -> float:
    return f.chi2 / max(f.n, 1)


def _share(with_: float, without: float) -> float | None:
    if not (math.isfinite(with_) and math.isfinite(without)) or without <= 0:
        return None
    return max(0.0, 1.0 - with_ / without)


def _null(stack: Stack, nuisance_nl: dict[str, float]) -> LinearFit:
    return fit(replace(stack, nuisance_nl=dict(nuisance_nl), cache={}), ("backlash",))


def _restacked(runs: Sequence[RunInput], tp: int, alpha: float, nuisance_nl: dict[str, float],
               zero_used: bool, **flags: bool) -> LinearFit:
    prepared = [prepare_run(r, tp, with_lost_motion=False, **flags) for r in runs]
    if zero_used:
        prepared, _ = remove_torque_zero(prepared, alpha)
    return _null(build_stack(prepared), nuisance_nl)


def _per_run(prepared: Sequence[PreparedRun], key: str) -> dict[str, Any]:
    return {r.run_id: r.measurement.get(key) for r in prepared}


def measurement_report(runs: Sequence[RunInput], prepared: Sequence[PreparedRun], stack: Stack,
                       base: LinearFit, zero: dict[str, Any], tp: int, alpha: float
                       ) -> dict[str, Any]:
    """The ``measurement`` entry of the diagnosis report (see the module docstring)."""
    nl = dict(stack.nuisance_nl)
    used = bool(zero.get("used"))
    msr = _msr(base)
    out: dict[str, Any] = {}

    lags = [r.measurement.get("torque_lag_s", 0.0) for r in prepared]
    taken = any(r.measurement.get("torque_lag_taken_out") for r in prepared)
    lag_share = 0.0
    if taken:
        lag_share = _share(msr, _msr(_restacked(runs, tp, alpha, nl, used, correct_lag=False)))
    out["torque_lag"] = {
        "what": "lag of the torque channel behind the twist (a first-order filter's time "
                "constant or a transport delay: the same at the loop's frequencies), taken "
                "out by reading the torque channel at the shifted time",
        "per_run_s": _per_run(prepared, "torque_lag_s"),
        "median_s": float(np.median(lags)) if lags else 0.0,
        "taken_out": taken,
        "gap_share": lag_share,
    }

    ringing = [int(r.measurement.get("transient_samples", 0)) for r in prepared]
    ring_share = None
    if any(ringing):
        ring_share = _share(msr, _msr(_restacked(runs, tp, alpha, nl, used,
                                                 exclude_transients=False)))
    out["impact_transients"] = {
        "what": "samples left out after each flank impact until the twist's second "
                "difference stayed inside its noise band for 3 samples",
        "per_run_samples": _per_run(prepared, "transient_samples"),
        "crossings_per_run": _per_run(prepared, "crossings"),
        "gap_share": ring_share if any(ringing) else 0.0,
    }

    zero_share = 0.0
    removed = [r.zero_removed_Nm for r in stack.runs]
    if any(z is not None for z in removed):
        undone = [r if r.zero_removed_Nm is None else
                  replace(r, torque_Nm=r.torque_Nm + r.zero_removed_Nm)
                  for r in stack.runs]
        zero_share = _share(msr, _msr(_null(replace(stack, runs=tuple(undone)), nl)))
    out["torque_zero"] = {
        "what": "torque zero of each run read at its play crossings (the re-tare residual "
                "and its drift); friction at the crossings for reference",
        **zero, "gap_share": zero_share,
    }

    f0 = float(nl.get("friction_Nm", 0.0))
    out["ordinary_friction"] = {
        "what": "Coulomb friction every unit and rig has, up to 1 % of rated torque: carried "
                "by the null model and every candidate; a run's own friction may be lower by "
                "up to it, so near a play crossing where that decides the flank the point "
                "floats in the play",
        "friction_Nm": f0,
        "share_of_rated": f0 / stack.rated_Nm if stack.rated_Nm > 0 else None,
        "gap_share": _share(msr, _msr(_null(stack, {}))) if f0 > 0 else 0.0,
    }

    q_tw = [r.measurement.get("twist_resolution_arcsec", 0.0) for r in prepared]
    q_tq = [r.measurement.get("torque_resolution_Nm", 0.0) for r in prepared]
    noise = [r.measurement.get("twist_noise_arcsec", 0.0) for r in prepared]
    quant_var = [(q / math.sqrt(12.0)) ** 2 for q in q_tw]
    out["resolution"] = {
        "what": "encoder and torque ADC resolution read from the data's grid; its share is "
                "that of the twist noise variance (quantisation error q^2 / 12)",
        "twist_arcsec": float(np.median(q_tw)) if q_tw else 0.0,
        "torque_Nm": float(np.median(q_tq)) if q_tq else 0.0,
        "twist_noise_arcsec": float(np.median(noise)) if noise else 0.0,
        "noise_share": float(np.median([qv / n**2 if n > 0 else 0.0
                                        for qv, n in zip(quant_var, noise, strict=True)]))
        if noise else 0.0,
    }
    tb = [r.measurement.get("time_base", {}) for r in prepared]
    out["sample_times"] = {
        "what": "sample interval, its jitter and the gaps (dropped rows); block means never "
                "span a gap. Rows stamped on arrival after a stall (restamped: later than "
                "their sampling time by over half an interval) are left out: their torque "
                "belongs to another moment than their twist",
        "interval_s": float(np.median([d.get("interval_s", math.nan) for d in tb])),
        "jitter_s": float(np.max([d.get("jitter_s", 0.0) for d in tb])),
        "gaps": int(sum(d.get("gaps", 0) for d in tb)),
        "longest_gap_s": float(np.max([d.get("longest_gap_s", 0.0) for d in tb])),
        "missing_share": float(np.mean([d.get("missing_share", 0.0) for d in tb])),
        "restamped": int(sum(d.get("restamped", 0) for d in tb)),
    }
    return out
