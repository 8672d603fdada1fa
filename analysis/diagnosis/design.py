"""What a campaign's design can test: its conditions, held-out folds and testable effects.

Conditions are the levels of the factors the campaign varies (position, temperature,
amplitude); folds hold out whole conditions (or repeats for the per-tooth model); an effect
the design cannot test is never fitted and the report says why; the members of the effect
families (runout order 2, a quadratic thermal term, a smooth bearing take-up) are fitted
only when the design supports them and they earn their place.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from analysis.diagnosis.candidates import Candidate, _bic, _heldout, separated
from analysis.diagnosis.fit import (
    Stack,
    fit,
    fit_profile,
    positions_known,
    temperatures_known,
)
from analysis.diagnosis.policy import POLICY, DecisionPolicy
from analysis.diagnosis.thermal_lag import campaign_times, lag_grid_s, with_mesh_temperature
from analysis.effects import CANDIDATES, tooth_pair_phase


def conditions_of(stack: Stack, policy: DecisionPolicy = POLICY
                  ) -> tuple[dict[str, tuple], list[str]]:
    """Each run's condition (levels of the factors the campaign varies) and those factors."""
    runs = stack.runs
    levels: dict[str, list[Any]] = {}
    pos = [None if r.input_angle_deg is None else round(r.input_angle_deg, 1) for r in runs]
    temps = [r.mean_temperature_C for r in runs]
    amps = [r.amplitude_Nm for r in runs]
    levels["position"] = pos
    levels["temperature"] = temperature_levels(temps, policy)
    levels["amplitude"] = [round(a / (policy.amplitude_step * stack.rated_Nm)) for a in amps]
    varied = [k for k, v in levels.items() if len(set(v)) > 1]
    cond = {r.run_id: tuple(levels[k][i] for k in varied) for i, r in enumerate(runs)}
    return cond, varied


def temperature_levels(temps: Sequence[float | None], policy: DecisionPolicy = POLICY
                       ) -> list[int | None]:
    """Each run's temperature level: 0 for all when the campaign does not vary temperature
    (span below TEMPERATURE_SPAN_K: room drift of a few tenths is no factor), else levels
    split where sorted mean temperatures leave a gap of TEMPERATURE_GAP_K. Rounding to a grid
    split 20.12 and 20.66 deg C into two conditions, and a tooth-pair repeat was lost."""
    known = sorted(t for t in temps if t is not None)
    if not known or known[-1] - known[0] < policy.temperature_span_K:
        return [None if t is None else 0 for t in temps]
    level_of: dict[float, int] = {}
    level = 0
    for a, b in zip([known[0], *known], known, strict=False):
        if b - a >= policy.temperature_gap_K:
            level += 1
        level_of[b] = level
    return [None if t is None else level_of[t] for t in temps]


def folds_by_condition(stack: Stack, cond: dict[str, tuple], policy: DecisionPolicy = POLICY
                       ) -> list[list[int]]:
    """Held-out sets: whole conditions (all repeats together), at most MAX_FOLDS folds; with a
    single condition, one run at a time."""
    keys = list(dict.fromkeys(cond[r.run_id] for r in stack.runs))
    if len(keys) < 2:
        groups = [[i] for i in range(stack.n_runs)]
    else:
        groups = [[i for i, r in enumerate(stack.runs) if cond[r.run_id] == k] for k in keys]
    if len(groups) < 2:
        return []
    n = min(policy.max_folds, len(groups))
    folds = [[] for _ in range(n)]
    for j, g in enumerate(groups):
        folds[j % n].extend(g)
    return folds


def folds_by_repeat(stack: Stack, cond: dict[str, tuple],
                    varied: Sequence[str] = (), policy: DecisionPolicy = POLICY) -> list[list[int]]:
    """Held-out sets of repeats: fold r leaves out the r-th run of every repeated condition.
    A repeat is the same tooth pair meshing at the same other conditions: the position enters
    as its tooth-pair phase (analysis.effects.tooth_pair_phase), so positions one repeat
    period apart (one output revolution for 45/40 teeth) are repeats."""
    by: dict[tuple, list[int]] = {}
    pos_at = list(varied).index("position") if "position" in varied else None
    for i, r in enumerate(stack.runs):
        key = cond[r.run_id]
        if pos_at is not None and r.input_angle_deg is not None:
            phase = int(tooth_pair_phase(r.input_angle_deg, stack.z_internal, stack.z_external))
            key = (*key[:pos_at], ("tooth", phase), *key[pos_at + 1:])
        by.setdefault(key, []).append(i)
    reps = [v for v in by.values() if len(v) >= 2]
    if not reps:
        return []
    depth = min(policy.max_folds, max(len(v) for v in reps))
    return [[v[k] for v in reps if k < len(v)] for k in range(depth)]


def testable(stack: Stack, cond: dict[str, tuple], varied: list[str],
             policy: DecisionPolicy = POLICY) -> dict[str, str]:
    """Candidates the design can test -> '' ; others -> why not (:func:`untestable` of the
    runs' locking positions and measured temperatures)."""
    positions = [r.input_angle_deg for r in stack.runs] if positions_known(stack) else [None]
    temps = [r.mean_temperature_C for r in stack.runs if r.mean_temperature_C is not None]
    span: float | None = None
    if temps:
        span = max(float(np.ptp(np.concatenate([r.temperature_C for r in stack.runs]))), 0.0) \
            if temperatures_known(stack) else 0.0
    kind = stack.physics.not_testable if stack.physics is not None else {}
    return untestable(positions, stack.z_internal, stack.z_external, span, kind, policy)


def untestable(positions_deg: Sequence[float | None], z_input: int, z_mate: int,
               temperature_span_K: float | None, kind_not_testable: dict[str, str],
               policy: DecisionPolicy = POLICY) -> dict[str, str]:
    """Each candidate effect -> '' when a campaign of these runs can test it, else why not.

    ``positions_deg``: the runs' input locking angles (deg; None: not known);
    ``z_input``, ``z_mate``: the tooth counts that set which tooth pair a position engages
    (:func:`analysis.effects.tooth_pair_phase`); ``temperature_span_K``: how far the housing
    temperature varies over the campaign (None: not recorded); ``kind_not_testable``: the
    unit kind's effects without a meaning of their own. The same rules decide before a
    campaign is measured (its plan) and after (its runs)."""
    why = {name: "" for name in CANDIDATES}
    if any(p is None for p in positions_deg):
        why["runout"] = why["tooth_spacing_error"] = "input_angle_deg unknown"
    else:
        known = [float(p) for p in positions_deg if p is not None]
        n_pos = len({round(p, 1) for p in known})
        if n_pos < policy.runout_positions:
            why["runout"] = (f"only {n_pos} locking position(s): runout needs "
                             f"{policy.runout_positions} or more")
        if len({int(tooth_pair_phase(p, z_input, z_mate)) for p in known}) < 2:
            why["tooth_spacing_error"] = "one tooth pair only"
    if temperature_span_K is None or temperature_span_K < policy.temperature_span_K:
        why["thermal_expansion"] = (f"temperature does not vary by "
                                    f"{policy.temperature_span_K:g} K or more")
    why["shaft_compliance"] = ("a series compliance changes only the slope: from loops alone it "
                               "is the stiffness parameter (see parameter_error)")
    why.update(kind_not_testable)
    return why


def lagged_thermal_member(stack: Stack, folds: list[list[int]],
                          policy: DecisionPolicy = POLICY) -> Stack | None:
    """The stack with the runs' temperatures replaced by the mesh temperature lagging the
    housing sensor (analysis.diagnosis.thermal_lag), at the time constant that fits the
    thermal play best, when that member earns its place as an added effect does: an in-sample
    BIC lower by separation_bic (the time constant is one more parameter) and a consistently
    smaller residual on the held-out conditions (:func:`separated`). None: the campaign's
    time axis is unknown, the campaign has fewer than thermal_lag_runs runs, or the lag does
    not earn it."""
    times = campaign_times(stack.runs)
    if times is None or not folds or stack.n_runs < policy.thermal_lag_runs:
        return None
    effects = ("backlash", "thermal_expansion")
    plain = fit(stack, effects)

    def member(tau: float) -> tuple[float, Stack, Any]:
        lagged = replace(stack, runs=with_mesh_temperature(stack.runs, times, tau),
                         thermal_lag_s=tau, cache={})
        f = fit(lagged, effects)
        return _bic(f), lagged, f

    grid = lag_grid_s(times)
    tried = [member(float(tau)) for tau in grid]
    best = min(tried, key=lambda m: m[0]) if tried else None
    if best is not None:
        # the time constant between the grid's neighbours of the best (log scale)
        k = next(i for i, m in enumerate(tried) if m is best)
        lo, hi = math.log(grid[max(k - 1, 0)]), math.log(grid[min(k + 1, grid.size - 1)])
        if hi > lo:
            opt = minimize_scalar(lambda u: member(math.exp(u))[0], bounds=(lo, hi),
                                  method="bounded", options={"xatol": 0.02, "maxiter": 8})
            refined = member(math.exp(float(opt.x)))
            best = refined if refined[0] < best[0] else best
    if best is None or best[0] > _bic(plain) - policy.separation_bic - math.log(plain.n):
        return None
    cands = []
    for st, f in ((stack, plain), (best[1], best[2])):
        h, lm, nh, resid = _heldout(st, ("thermal_expansion",), folds, f)
        cands.append(Candidate(("thermal_expansion",), f, h, lm, nh, "leave-one-condition-out",
                               delta_bic=_bic(f), heldout_resid=resid))
    return best[1] if separated(stack, cands[1], cands[0], policy) else None


def choose_family_members(stack: Stack, cond: dict[str, tuple], varied: Sequence[str],
                          why_not: dict[str, str], folds: list[list[int]],
                          policy: DecisionPolicy = POLICY) -> Stack:
    """The members of the runout, thermal and bearing families the campaign supports. A play
    that changes with the crank angle is a periodic function of it: eq. (4) gives orders 1 and
    (2 z_ext - z_int) / z_ext, an oval (two-lobed) ring, bore or bearing seat order 2
    (:func:`analysis.effects.runout_harmonic_basis`). A play linear in temperature is the
    first term of a Taylor series; expansion coefficients that change with temperature and
    fits that tighten (housing on bearing, bearing on shaft) curve it. A higher term is fitted
    only when the design can determine it (ORDER2_POSITIONS positions; three or more
    temperature levels) and kept only when it earns its place as an added effect does: an
    in-sample BIC lower by SEPARATION_BIC and a consistently smaller residual on the held-out
    conditions (:func:`separated`). A bearing's soft stage ends where the clearance is closed:
    abruptly (a kink, the rollers all in contact at once) or gradually (``T_b tanh(|G| /
    T_b)``: same initial compliance, same take-up ``T_b / K_b``, as the load spreads over
    more rollers); the two shapes have the same parameters, the better fit by SEPARATION_BIC
    is taken."""
    changes: dict[str, bool] = {}

    def earns(effect: str, flag: str) -> bool:
        richer = replace(stack, cache={}, **{flag: True})
        first = fit(stack, ("backlash", effect))
        second = fit(richer, ("backlash", effect))
        if _bic(second) > _bic(first) - policy.separation_bic:
            return False
        if not folds:
            return False
        cands = []
        for st, f in ((stack, first), (richer, second)):
            h, lm, nh, resid = _heldout(st, (effect,), folds, f)
            cands.append(Candidate((effect,), f, h, lm, nh, "leave-one-condition-out",
                                   delta_bic=_bic(f), heldout_resid=resid))
        return separated(stack, cands[1], cands[0], policy)

    n_pos = len({round(r.input_angle_deg, 1) for r in stack.runs
                 if r.input_angle_deg is not None})
    if not why_not.get("runout") and n_pos >= policy.order2_positions and earns("runout",
                                                                           "runout_order2"):
        changes["runout_order2"] = True
    levels = {c[list(varied).index("temperature")] for c in cond.values()} \
        if "temperature" in varied else set()
    if (not why_not.get("thermal_expansion") and len(levels) >= policy.thermal_levels
            and earns("thermal_expansion", "thermal_quadratic")):
        changes["thermal_quadratic"] = True
    if not why_not.get("thermal_expansion") and levels:
        # the lag must earn its place beyond the sensor's play law chosen so far (a curved
        # play is the quadratic's, not a lag's)
        lagged = lagged_thermal_member(replace(stack, cache={}, **changes), folds, policy)
        if lagged is not None:
            stack = lagged
    if not why_not.get("bearing_clearance"):
        first = fit_profile(stack, ("backlash", "bearing_clearance"))
        second = fit_profile(replace(stack, bearing_smooth=True, cache={}),
                             ("backlash", "bearing_clearance"))
        if _bic(second) <= _bic(first) - policy.separation_bic:
            changes["bearing_smooth"] = True
    return replace(stack, cache={}, **changes) if changes else stack

