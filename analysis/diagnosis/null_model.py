"""The measuring system in the null model: ordinary friction, the torque zero, the lag.

Every candidate is fitted beside this nuisance, so only what goes beyond a sound rig's own
errors can be an effect (docs/diagnosis.md, "The measuring system in the null model").
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from analysis.diagnosis.data import (
    PreparedRun,
    RunInput,
    prepare_run,
    remove_torque_zero,
    smallest_zero_reading,
)
from analysis.diagnosis.fit import (
    HUBER_C,
    Stack,
    build_stack,
    fit,
)
from analysis.diagnosis.policy import POLICY, DecisionPolicy


def nuisance_friction(stack: Stack, policy: DecisionPolicy = POLICY) -> float:
    """The ordinary friction every unit and rig has (N*m): the null model's best Coulomb
    friction between 0 and FRICTION_ALLOWANCE of rated torque (a few grid points). Carried
    by every candidate as the measuring system's nuisance; only friction beyond it is an
    effect."""
    return _nuisance_friction(stack, policy)[1]


def _nuisance_friction(stack: Stack, policy: DecisionPolicy = POLICY) -> tuple[float, float]:
    """(objective, friction N*m) of the null with the best ordinary friction."""
    top = policy.friction_allowance * stack.rated_Nm
    grid = np.concatenate([[0.0], np.geomspace(top / 100.0, top, 7)])
    trials = [(fit(stack, ("backlash",), nl={"friction_Nm": float(v)}).objective, float(v))
              for v in grid]
    return min(trials)


def lag_if_it_helps(runs: Sequence[RunInput], prepared: list[PreparedRun], tp: int,
                    policy: DecisionPolicy = POLICY) -> list[PreparedRun]:
    """The runs with their torque-channel lag taken out where that improves the run's part
    of the null model's objective by more than it costs (BIC: log n per run). The lag is read
    on the loaded flanks alone; a slow change of the unit (a drift, creep) can pass for one
    there and then worsen the whole loop."""
    lagged = [i for i, r in enumerate(prepared) if r.measurement.get("torque_lag_s")]
    if not lagged:
        return prepared
    plain = list(prepared)
    for i in lagged:
        plain[i] = prepare_run(runs[i], tp, correct_lag=False)
    with_lag = _run_objectives(build_stack(prepared), policy)
    without = _run_objectives(build_stack(plain), policy)
    n = sum(r.twist_arcmin.size for r in prepared)
    out = list(plain)
    for i in lagged:
        rid = prepared[i].run_id
        if 2.0 * (without[rid] - with_lag[rid]) >= math.log(max(n, 2)):
            out[i] = prepared[i]
    return out


def _run_objectives(stack: Stack, policy: DecisionPolicy = POLICY) -> dict[str, float]:
    """Each run's share of the null model's robust objective (Huber, noise units), with the
    best ordinary friction."""
    f0 = _nuisance_friction(stack, policy)[1]
    # a run's own friction may be lower than the campaign's one (fit.run_chain), as in the
    # null model the diagnosis goes on with: without it a lag that moves a play crossing's
    # torque past the campaign's friction costs that crossing a whole play, and the lag
    # that the loaded flanks want is refused (an over-the-wire null: 3 of 4 runs' 7 ms)
    null = fit(stack, ("backlash",), nl={"friction_Nm": f0, "friction_spread_Nm": f0})
    out = {}
    for run in stack.runs:
        u = np.abs(null.residual[run.run_id]) / run.sigma_arcmin
        out[run.run_id] = float(np.sum(np.where(u <= HUBER_C, 0.5 * u**2,
                                                 HUBER_C * (u - 0.5 * HUBER_C))))
    return out


def with_measurement_nuisance(prepared: list[PreparedRun], alpha: float,
                              policy: DecisionPolicy = POLICY) -> tuple[Stack, dict[str, Any]]:
    """The stack the diagnosis fits: the ordinary friction carried as a nuisance
    (:func:`nuisance_friction`), and each run's torque zero read at its play crossings taken
    out (analysis.diagnosis.data.remove_torque_zero) when that improves the null model by more
    than the parameters it costs (BIC: log(n) per run read). A crossing read early by a soft
    contact or a take-up near zero torque is no torque zero: such a reading worsens the null
    and is not used."""
    plain = build_stack(prepared)
    obj_plain, f_plain = _nuisance_friction(plain, policy)
    zeroed_runs, zero_report = remove_torque_zero(prepared, alpha,
                                                  policy.zero_allowance * plain.rated_Nm)
    used = False
    stack, f0 = plain, f_plain
    if zero_report.get("runs_read"):
        zeroed = build_stack(zeroed_runs)
        obj_zero, f_zero = _nuisance_friction(zeroed, policy)
        n = sum(r.twist_arcmin.size for r in prepared)
        if 2.0 * (obj_plain - obj_zero) >= zero_report["runs_read"] * math.log(max(n, 2)):
            stack, f0, used = zeroed, f_zero, True
    zero_report["used"] = used
    if f0 >= policy.friction_allowance * stack.rated_Nm * (1.0 - 1e-9):
        # the null wants all the allowance and more: the unit's friction is beyond the
        # ordinary, a candidate's to find; held at the cap in every other candidate it would
        # bend their comparison (a runout against per-tooth plays)
        f0 = 0.0
    veto = ""
    p_common = zero_report.get("common_false_alarm_probability")
    if (zero_report.get("runs_read", 0) >= policy.zero_veto_runs and p_common is not None
            and p_common > alpha):
        # a sensor offset is the same in every run and moves every play crossing by it
        veto = (f"the play crossings of {zero_report['runs_read']} runs put the torque zero "
                f"at {zero_report['common_Nm']:+.4f} N*m, within their own scatter "
                f"({zero_report['scatter_Nm']:.4f} N*m): no common sensor offset")
    elif (read := smallest_zero_reading(prepared)) is not None and \
            abs(read[0]) <= policy.zero_allowance * plain.rated_Nm:
        # the rig read its torque channel at zero command: a constant sensor offset is in
        # every such reading, and one within the re-tare allowance rules it out
        veto = (f"the rig read the torque channel at {read[0]:+.4f} N*m at zero command "
                f"(run {read[1]}), within what a re-tare leaves ({policy.zero_allowance:.2%} of "
                "rated): a constant sensor offset would show in every zero reading")
    elif (zero_report.get("runs_read", 0) >= policy.zero_veto_runs and used
          and abs(zero_report["common_Nm"]) <= policy.zero_allowance * plain.rated_Nm):
        veto = (f"the play crossings put the common torque zero at "
                f"{zero_report['common_Nm']:+.4f} N*m, within what a re-tare and the zero's "
                f"drift leave ({policy.zero_allowance:.2%} of rated): no sensor offset")
    if not used and zero_report.get("runs_read"):
        zero_report["treated_as"] = ("not taken out: the crossings' zeros do not improve the "
                                     "null model by more than they cost")
    return replace(stack, nuisance_nl={"friction_Nm": f0, "friction_spread_Nm": f0}, cache={},
                   offset_veto=veto,
                   nuisance_friction_max_Nm=policy.friction_allowance * stack.rated_Nm), zero_report

