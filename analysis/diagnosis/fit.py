"""Fitting the composed loop (analysis.effects) to prepared runs: profile, robust, held out.

Given at most one nonlinear parameter per effect (friction torque, torque offset, stiffening
torque scale, bearing stage torque), the twist is *linear* in everything else: play, compliance,
the runout coefficients, the thermal coefficient, the per-tooth play changes, the stiffening
twist, the bearing compliance and the per-run twist offsets. So each candidate is fitted by
(1) a profile over a grid of its nonlinear parameter, each point a bounded linear least squares
(scipy.optimize.lsq_linear) with Huber re-weighting (robust to the odd impact sample) and the
run offsets projected out, then (2) a bounded scalar refinement (scipy.optimize
.minimize_scalar). Coefficients with a prior (runout, tooth spacing) get Gaussian pseudo-
observations of their plausible size (the tolerance budget), which keeps the nearly collinear
runout terms of one crank turn finite.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy.optimize import lsq_linear, minimize_scalar

from analysis.diagnosis.data import PreparedRun
from analysis.diagnosis.kind_physics import KindPhysics, physics_for_unit
from analysis.effects import (
    LoopParams,
    chain_torque_Nm,
    flank_sign,
    model_lost_motion_arcmin,
    runout_basis,
    runout_harmonic_basis,
    tooth_pair_phase,
    um_to_arcmin,
)
from analysis.errors import AnalysisError

HUBER_C = 2.5
#: Half the 95 % quantile of chi2 with one degree of freedom: a profile-likelihood interval.
PROFILE_95 = 1.92
#: Nonlinear parameter of each effect: (name, lower, upper as fractions of rated torque, log?).
NONLINEAR = {
    "friction": ("friction_Nm", 0.0, 0.2, False),
    "torque_sensor_offset": ("torque_offset_Nm", -0.1, 0.1, False),
    "stiffness_nonlinearity": ("stiffening_torque_Nm", 0.005, 0.6, True),
    "bearing_clearance": ("bearing_stage_torque_Nm", 0.005, 0.6, True),
}


@dataclass(frozen=True, eq=False)
class Stack:
    """All prepared runs of a campaign, concatenated, with the unit's geometry."""

    runs: tuple[PreparedRun, ...]
    z_internal: int
    z_external: int
    module_mm: float
    pressure_angle_deg: float
    runout_budget_arcmin: float  # amplitude prior of each runout coefficient
    spacing_budget_arcmin: float  # prior sd of one tooth's play change
    reference_C: float
    rated_Nm: float
    cache: dict = field(default_factory=dict, repr=False)
    #: Family members the campaign supports (:func:`choose_family_members`): the runout's
    #: twice-per-turn harmonic, the thermal play's quadratic term.
    runout_order2: bool = False
    thermal_quadratic: bool = False
    #: The bearing's soft stage closes smoothly (``T_b tanh(|G| / T_b)``) instead of at a kink.
    bearing_smooth: bool = False
    #: The runs' temperatures are the mesh's, lagging the housing sensor by this time constant
    #: (s; analysis.diagnosis.thermal_lag); 0: the sensor's own.
    thermal_lag_s: float = 0.0
    #: Nonlinear parameters every fit carries as the measuring system's nuisance (the null
    #: included) unless the candidate fits its own: the ordinary friction allowance.
    nuisance_nl: dict = field(default_factory=dict)
    #: Largest ordinary friction (N*m) the nuisance may take.
    nuisance_friction_max_Nm: float = 0.0
    #: Why the play crossings rule a common torque-sensor offset out ('' : they do not).
    offset_veto: str = ""
    #: The unit kind's effect physics (analysis.diagnosis.kind_physics); None: seed 000's.
    physics: KindPhysics | None = None

    @property
    def n_runs(self) -> int:
        return len(self.runs)


def _num(unit: dict, key: str, default: float) -> float:
    value = unit.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return default
    return float(value)


def unit_teeth(unit: dict[str, Any], physics: KindPhysics | None) -> tuple[int, int]:
    """The tooth counts that say which tooth pair a locking position engages: the kind's
    mesh steps per input turn and its mate's (``physics``), else seed 000's ``z_internal``
    and ``z_external`` (45 and 40 when the unit data has none)."""
    if physics is not None:
        return physics.z_input, physics.z_mate
    return int(_num(unit, "z_internal", 45)), int(_num(unit, "z_external", 40))


def build_stack(runs: Sequence[PreparedRun]) -> Stack:
    """Stack prepared runs; the unit geometry comes from the first run's unit data."""
    if not runs:
        raise AnalysisError("no runs to diagnose")
    unit = dict(runs[0].raw.unit or {})
    z1 = int(_num(unit, "z_internal", 45))
    z2 = int(_num(unit, "z_external", 40))
    m = _num(unit, "module_mm", 1.0)
    alpha = _num(unit, "pressure_angle_deg", 20.0)
    fr = _num(unit, "runout_internal_mm", 0.02) + _num(unit, "runout_external_mm", 0.02)
    # prior of a runout coefficient: the eq. (4)/(3) play change of the inspected runout
    runout_um = 2.0 * math.tan(math.radians(alpha)) * 1000.0 * max(fr, 0.01) / 2.0
    temps = [r.mean_temperature_C for r in runs if r.mean_temperature_C is not None]
    rated = float(np.median([r.rated_torque_Nm for r in runs]))
    runout_budget = float(um_to_arcmin(runout_um, m, z1))
    spacing_budget = float(um_to_arcmin(4.0, m, z1))
    physics = physics_for_unit(unit, rated)
    if physics is not None:
        # the kind's own geometry (analysis.diagnosis.kind_physics): mesh steps per input
        # turn and the mate's tooth count, its inspected tolerances' play
        z1, z2 = unit_teeth(unit, physics)
        runout_budget = physics.runout_budget_arcmin
        spacing_budget = physics.spacing_prior_arcmin
    return Stack(
        runs=tuple(runs), z_internal=z1, z_external=z2, module_mm=m, pressure_angle_deg=alpha,
        runout_budget_arcmin=runout_budget, spacing_budget_arcmin=spacing_budget,
        reference_C=float(np.mean(temps)) if temps else 20.0,
        rated_Nm=rated, physics=physics,
    )


def positions_known(stack: Stack) -> bool:
    return all(r.input_angle_deg is not None for r in stack.runs)


def temperatures_known(stack: Stack) -> bool:
    return all(r.temperature_C is not None for r in stack.runs)


@dataclass(frozen=True)
class Columns:
    """Design matrix of one run for a set of effects (rows: the run's points)."""

    X: np.ndarray
    names: tuple[str, ...]


def column_names(stack: Stack, effects: Sequence[str], teeth: Sequence[int]) -> list[str]:
    names = ["play", "compliance"]
    if "stiffness_nonlinearity" in effects:
        names.append("soft_twist")
    if "bearing_clearance" in effects:
        names.append("bearing_compliance")
    if "runout" in effects:
        names += ["runout_c1", "runout_s1", "runout_c2", "runout_s2"]
        if stack.runout_order2:
            names += ["runout_h2c", "runout_h2s"]
    if "thermal_expansion" in effects:
        names.append("thermal")
        if stack.thermal_quadratic:
            names.append("thermal2")
    if "tooth_spacing_error" in effects:
        names += [f"tooth_{t}" for t in teeth]
    return names


def run_columns(stack: Stack, run: PreparedRun, effects: Sequence[str], nl: dict[str, float],
                teeth: Sequence[int], chain: RunChain | None = None) -> np.ndarray:
    """Columns (see :func:`column_names`) of one run: the composed loop of analysis.effects
    written as ``twist = X beta + offset``. ``chain``: the run's :class:`RunChain` for ``nl``
    when already known."""
    c = chain if chain is not None else run_chain(run, nl)
    s = c.flank
    tau = np.abs(c.chain_torque_Nm)
    cols = [s / 2.0, s * tau]
    if stack.physics is not None:
        cols = kind_play_and_flank_columns(stack.physics, run.input_angle_deg, s, tau)
    if "stiffness_nonlinearity" in effects:
        cols.append(s * -np.expm1(-tau / nl["stiffening_torque_Nm"]))
    if "bearing_clearance" in effects:
        tb = nl["bearing_stage_torque_Nm"]
        cols.append(s * (tb * np.tanh(tau / tb) if stack.bearing_smooth
                         else np.minimum(tau, tb)))
    if "runout" in effects:
        basis = (runout_basis(run.input_angle_deg or 0.0, stack.z_internal, stack.z_external)
                 if stack.physics is None else stack.physics.runout_basis(
                     run.input_angle_deg or 0.0))
        cols += [s / 2.0 * b for b in basis]
        if stack.runout_order2:
            cols += [s / 2.0 * b for b in runout_harmonic_basis(run.input_angle_deg or 0.0)]
    if "thermal_expansion" in effects:
        temp = run.temperature_C if run.temperature_C is not None else np.full(s.size, math.nan)
        cols.append(s / 2.0 * (temp - stack.reference_C))
        if stack.thermal_quadratic:
            cols.append(s / 2.0 * (temp - stack.reference_C) ** 2)
    if "tooth_spacing_error" in effects:
        tooth = int(tooth_pair_phase(run.input_angle_deg or 0.0, stack.z_internal,
                                     stack.z_external))
        cols += [s / 2.0 * (1.0 if t == tooth else 0.0) for t in teeth]
    return np.column_stack(cols)


def kind_play_and_flank_columns(physics: KindPhysics, input_angle_deg: float | None,
                                s: np.ndarray, tau: np.ndarray) -> list[np.ndarray]:
    """The play and compliance columns in the kind's own nominal shape: the compound
    cycloid's free play at the run's mesh phase relative to its mean over the mesh cycle, and
    its flanks engaging one after another as an equivalent torque (seed 002 eqs. 1-14, seed
    004 eq. 8 per flank; :class:`analysis.diagnosis.kind_physics.CycloidShape`); the pinned
    linear loop's ``s / 2`` and ``s |G|`` for a kind without a shape."""
    shape = physics.cycloid
    if shape is None or input_angle_deg is None:
        return [s / 2.0, s * tau]
    return [s / 2.0 * shape.play_ratio(input_angle_deg),
            s * shape.shape_Nm(input_angle_deg, s, tau)]


def with_kind_play_reference(stack: Stack) -> Stack:
    """The stack with the kind's mesh-phase play change referred to this unit's calibrated
    mean play (the null model's), so that the change is added to the play, not scaled with
    it (:attr:`analysis.diagnosis.kind_physics.CycloidShape.play_reference_arcmin`); the
    stack itself for a kind without one."""
    physics = stack.physics
    if physics is None or physics.cycloid is None:
        return stack
    play = fit(stack, ("backlash",)).coef("play")
    if not play > 0:
        return stack
    shape = replace(physics.cycloid, play_reference_arcmin=float(play))
    return replace(stack, physics=replace(physics, cycloid=shape), cache={})


def flank_band_Nm(run: PreparedRun) -> float:
    """Noise band of the chain torque (N*m) within which the flank is undetermined: three
    block-mean torque sigmas (+1e-4 of rated for a noiseless channel)."""
    return 3.0 * run.sigma_torque_Nm + 1e-4 * run.rated_torque_Nm


def run_floating(run: PreparedRun, nl: dict[str, float]) -> np.ndarray:
    """Points whose chain torque is within the flank band: nothing holds the unit on a flank,
    it floats in the free play (True)."""
    return run_float_masks(run, nl)[0]


@dataclass(frozen=True, eq=False)
class RunChain:
    """What the torque offset and friction of ``nl`` make of one run's torque: the chain
    torque (N*m), the flank in contact (+1/-1) and the float masks of
    :func:`run_float_masks`."""

    run: PreparedRun
    chain_torque_Nm: np.ndarray
    flank: np.ndarray
    floating: np.ndarray
    across: np.ndarray


def run_chain(run: PreparedRun, nl: dict[str, float]) -> RunChain:
    """The run's :class:`RunChain` under the torque offset and friction of ``nl``.

    ``nl["friction_spread_Nm"]`` (the ordinary friction the null model carries): the
    campaign's one friction is an estimate, and a run's own may be lower by up to that much
    (the friction read at the play crossings of one over-the-wire null's runs: 0.016-0.040
    N*m against the campaign's 0.046). Where the lower friction would already have moved the
    chain off the flank the model keeps, the point floats; where it would have put the chain
    on the other flank, the unit may lie anywhere up to that flank (``across``)."""
    torque = run.torque_Nm - nl.get("torque_offset_Nm", 0.0)
    friction = nl.get("friction_Nm", 0.0)
    g = chain_torque_Nm(torque, friction, run.start_flank)
    band = flank_band_Nm(run)
    kept = flank_sign(g, band, run.start_flank)
    floating = np.abs(g) < band
    across = np.zeros(floating.size, dtype=bool)
    spread = min(nl.get("friction_spread_Nm", 0.0), friction)
    if spread > 0:
        g_low = chain_torque_Nm(torque, friction - spread, run.start_flank)
        off_flank = g_low * kept < band  # the lower friction leaves the kept flank
        across = off_flank & (g_low * kept < -band)
        floating = floating | off_flank
    if run.time_unsure is not None and run.time_unsure.any():
        across = across | (floating & run.time_unsure & (g * kept < 0))
    return RunChain(run, g, kept, floating, across)


def cached_chain(stack: Stack, i: int, nl: dict[str, float]) -> RunChain:
    """:func:`run_chain` of run i, memoised per stack, run, torque offset and friction (the
    only parameters it depends on: a grid over any other parameter reuses it)."""
    run = stack.runs[i]
    key = ("chain", i, nl.get("torque_offset_Nm", 0.0), nl.get("friction_Nm", 0.0),
           nl.get("friction_spread_Nm", 0.0))
    hit = stack.cache.get(key)
    if hit is None or hit.run is not run:  # a stack made with other runs may share the cache
        hit = run_chain(run, nl)
        stack.cache[key] = hit
    return hit


def run_float_masks(run: PreparedRun, nl: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
    """(floating, across): ``floating`` as :func:`run_floating`; ``across`` the floating
    points just after a burst of rows stamped on arrival or in the first block after a play
    crossing (``run.time_unsure``; :func:`analysis.diagnosis.data.landed_blocks`) whose chain
    torque, inside its noise band, already points away from the flank last touched. The
    crossing inside the burst (or the block) was not observed at its torque, so the unit may
    already have switched: it may lie anywhere in the play (:func:`censor_floating`). With a
    friction spread in ``nl`` the points whose flank a run's lower friction leaves float too,
    and those it puts past the other side's band are ``across`` (:func:`run_chain`).
    Elsewhere the centre
    rule holds: a unit held on the other flank at zero torque shows a torque-sensor offset."""
    c = run_chain(run, nl)
    return c.floating, c.across


def censor_floating(r: np.ndarray, X: np.ndarray, beta: np.ndarray, floating: np.ndarray,
                    across: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Residuals (arcmin) with the float across the play modelled: a floating point may lie
    anywhere between the flank it last touched (the model's value) and the centre of the play
    (half the play towards the other flank), at no cost; beyond the centre only the excess
    counts, outwards the full residual. A point of ``across`` (its chain torque, inside the
    noise band, already points to the other flank: :func:`run_float_masks`) may lie anywhere
    up to the other flank. Returns (effective residual, inside mask). Column 0 of X is
    ``s / 2`` (the play column), ``beta[0]`` the play."""
    if not floating.any():
        return r, np.zeros(r.size, dtype=bool)
    s = 2.0 * X[:, 0]
    full = max(float(beta[0]), 0.0)
    reach = np.full(r.size, full / 2.0)
    if across is not None:
        reach[across] = full
    d = s * r  # > 0: beyond the kept flank outwards; < 0: drifted towards the centre
    inside = floating & (d <= 0) & (d >= -reach)
    past = floating & (d < -reach)
    out = r.copy()
    out[inside] = 0.0
    out[past] = r[past] + s[past] * reach[past]
    return out, inside


def teeth_of(stack: Stack) -> list[int]:
    """The tooth pairs (phase indices) the runs' input angles engage, memoised per stack."""
    hit = stack.cache.get("teeth")
    if hit is None or hit[0] is not stack.runs:  # a stack with other runs may share the cache
        hit = (stack.runs, sorted({int(tooth_pair_phase(r.input_angle_deg or 0.0,
                                                        stack.z_internal, stack.z_external))
                                   for r in stack.runs}))
        stack.cache["teeth"] = hit
    return list(hit[1])


def bounds_and_prior(stack: Stack, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray,
                                                                   np.ndarray]:
    """Lower, upper bounds and prior standard deviations (inf: none) of the coefficients."""
    lo, hi, prior = [], [], []
    for name in names:
        if name in ("play",):
            lo.append(-np.inf), hi.append(np.inf), prior.append(np.inf)
        elif name in ("compliance", "soft_twist", "bearing_compliance"):
            lo.append(0.0), hi.append(np.inf), prior.append(np.inf)
        elif name.startswith("runout"):
            lo.append(-np.inf), hi.append(np.inf), prior.append(stack.runout_budget_arcmin)
        elif name.startswith("tooth"):
            lo.append(-np.inf), hi.append(np.inf), prior.append(stack.spacing_budget_arcmin)
        else:
            lo.append(-np.inf), hi.append(np.inf), prior.append(np.inf)
    return np.array(lo), np.array(hi), np.array(prior)


@dataclass
class LinearFit:
    """A fit: coefficients, per-run offsets, residuals (arcmin) and robust objective."""

    names: tuple[str, ...]
    beta: np.ndarray
    nl: dict[str, float]
    objective: float
    chi2: float
    n: int
    residual: dict[str, np.ndarray] = field(default_factory=dict)
    cov: np.ndarray | None = None

    def coef(self, name: str, default: float = 0.0) -> float:
        return float(self.beta[self.names.index(name)]) if name in self.names else default


def _run_starts(run: np.ndarray) -> np.ndarray | None:
    """First point of each run when the runs are stacked one after another, else None."""
    if run.size and np.all(run[1:] >= run[:-1]):
        return np.flatnonzero(np.r_[True, run[1:] != run[:-1]])
    return None


def _centre(values: np.ndarray, weights: np.ndarray, run: np.ndarray, n_runs: int,
            starts: np.ndarray | None | bool = False) -> np.ndarray:
    """Subtract each run's weighted mean (columns of a 2-D array, or a 1-D array).
    ``starts``: :func:`_run_starts` of ``run`` when already known."""
    wsum = np.bincount(run, weights, minlength=n_runs)
    wsum[wsum == 0] = 1.0
    if values.ndim == 1:
        means = np.bincount(run, weights * values, minlength=n_runs) / wsum
        return values - means[run]
    if starts is False:
        starts = _run_starts(run)
    if starts is not None:  # runs stacked one after another
        sums = np.zeros((n_runs, values.shape[1]))
        sums[run[starts]] = np.add.reduceat(weights[:, None] * values, starts, axis=0)
    else:
        sums = np.stack([np.bincount(run, weights * values[:, j], minlength=n_runs)
                         for j in range(values.shape[1])], axis=1)
    return values - (sums / wsum[:, None])[run]


def _solve(X: np.ndarray, y: np.ndarray, sig: np.ndarray, run: np.ndarray, n_runs: int,
           lo: np.ndarray, hi: np.ndarray, prior: np.ndarray, fixed: np.ndarray | None,
           iterations: int = 3, want_cov: bool = False, floating: np.ndarray | None = None,
           across: np.ndarray | None = None,
           ) -> tuple[np.ndarray, float, float, np.ndarray, np.ndarray | None]:
    """Robust bounded LS with per-run offsets projected out (``run``: run index per point).
    ``fixed``: coefficients held (predictive gap) instead of fitted. Huber re-weighting.
    ``floating``: points floating in the play (:func:`censor_floating`); those inside their
    interval get no weight, those past the centre are fitted to the centre."""
    p = X.shape[1]
    w = np.ones(y.size)
    beta = fixed if fixed is not None else np.zeros(p)
    has_prior = np.isfinite(prior)
    pr = np.zeros((int(has_prior.sum()), p))
    pr[np.arange(pr.shape[0]), np.flatnonzero(has_prior)] = 1.0 / prior[has_prior]
    inv_var = 1.0 / sig**2
    A = None
    X0 = X
    flt = floating if floating is not None and floating.any() else None
    starts = _run_starts(run)
    for _ in range(iterations if fixed is None else 2):
        ww = w * inv_var
        if fixed is None:
            sw = np.sqrt(ww)
            A = np.vstack([_centre(X, ww, run, n_runs, starts) * sw[:, None], pr])
            b = np.concatenate([_centre(y, ww, run, n_runs) * sw, np.zeros(pr.shape[0])])
            scale = np.sqrt((A**2).sum(axis=0))
            scale[scale == 0] = 1.0
            x, *_ = np.linalg.lstsq(A / scale, b, rcond=None)
            beta = x / scale
            if np.any(beta < lo - 1e-12) or np.any(beta > hi + 1e-12):
                res = lsq_linear(A / scale, b, bounds=(lo * scale, hi * scale), method="bvls")
                beta = res.x / scale
        r = _centre(y - X0 @ beta, ww, run, n_runs)
        u = np.abs(r) / sig
        w = np.minimum(1.0, HUBER_C / np.maximum(u, 1e-12))
        if flt is not None:
            r_eff, inside = censor_floating(r, X0, beta, flt, across)
            w = np.minimum(1.0, HUBER_C / np.maximum(np.abs(r_eff) / sig, 1e-12))
            w[inside] = 0.0
            past = flt & ~inside & (2.0 * X0[:, 0] * r < 0)
            X = X0.copy()
            X[past] = 0.0  # fitted to the centre of the play (the run offset)
    ww = w * inv_var
    r = _centre(y - X0 @ beta, ww, run, n_runs)
    float_cost = 0.0
    if flt is not None:
        r, inside = censor_floating(r, X0, beta, flt, across)
        # a floating point inside its interval costs what a fitted point costs on average
        # (E[u^2 / 2] = 1/2): letting points float is no free lunch for a candidate
        float_cost = 0.5 * float(inside.sum())
    u = np.abs(r) / sig
    objective = float(np.sum(np.where(u <= HUBER_C, 0.5 * u**2, HUBER_C * (u - 0.5 * HUBER_C))))
    objective += float_cost
    cov = None
    if want_cov and A is not None:
        cov = np.linalg.pinv(A.T @ A)
    return beta, objective, float(np.sum(u**2)), r, cov


def fit(stack: Stack, effects: Sequence[str], runs: Sequence[int] | None = None,
        nl: dict[str, float] | None = None, fixed: dict[str, float] | None = None,
        want_cov: bool = False) -> LinearFit:
    """Fit the effects' linear coefficients for given nonlinear ones (``nl``) on ``runs``
    (indices; None: all). ``fixed`` holds play and compliance (predictive gap)."""
    idx = list(range(stack.n_runs)) if runs is None else list(runs)
    nl = {**stack.nuisance_nl, **(nl or {})}
    teeth = teeth_of(stack)
    names = column_names(stack, effects, teeth)
    X = np.vstack([cached_columns(stack, i, effects, nl, teeth) for i in idx])
    y = np.concatenate([stack.runs[i].twist_arcmin for i in idx])
    sig = np.concatenate([np.full(stack.runs[i].twist_arcmin.size, stack.runs[i].sigma_arcmin)
                          for i in idx])
    run = np.concatenate([np.full(stack.runs[i].twist_arcmin.size, k)
                          for k, i in enumerate(idx)])
    lo, hi, prior = bounds_and_prior(stack, names)
    fixed_beta = None
    if fixed is not None:
        fixed_beta = np.array([fixed.get(nm, 0.0) for nm in names])
    chains = [cached_chain(stack, i, nl) for i in idx]
    floating = np.concatenate([c.floating for c in chains])
    across = np.concatenate([c.across for c in chains])
    beta, obj, chi2, r, cov = _solve(X, y, sig, run, len(idx), lo, hi, prior, fixed_beta,
                                     want_cov=want_cov, floating=floating, across=across)
    fitres = LinearFit(tuple(names), beta, nl, obj, chi2, int(y.size), cov=cov)
    fitres.residual = {stack.runs[i].run_id: r[run == k] for k, i in enumerate(idx)}
    return fitres


def cached_columns(stack: Stack, i: int, effects: Sequence[str], nl: dict[str, float],
                   teeth: Sequence[int]) -> np.ndarray:
    """:func:`run_columns`, memoised per stack, run, effects and nonlinear values."""
    key = (id(stack), stack.runout_order2, stack.thermal_quadratic, stack.bearing_smooth, i,
           tuple(effects),
           tuple(sorted(nl.items())))
    hit = stack.cache.get(key)
    if hit is None:
        hit = run_columns(stack, stack.runs[i], effects, nl, teeth,
                          cached_chain(stack, i, nl))
        stack.cache[key] = hit
    return hit


def nonlinear_of(effects: Sequence[str]) -> list[str]:
    return [e for e in effects if e in NONLINEAR]


#: The ordinary friction (a nuisance of every fit, analysis.diagnosis.with_measurement_nuisance)
#: profiled beside a candidate whose parameter it trades off with.
ORDINARY_FRICTION = "ordinary_friction"


def _nl_key(effect: str) -> str:
    return "friction_Nm" if effect == ORDINARY_FRICTION else NONLINEAR[effect][0]


def _nl_grid(stack: Stack, effect: str) -> np.ndarray:
    if effect == ORDINARY_FRICTION:
        top = stack.nuisance_friction_max_Nm
        return np.concatenate([[0.0], np.geomspace(top / 100.0, top, 7)])
    return _grid(stack, effect)


def _nl_start(stack: Stack, effect: str) -> float:
    if effect == ORDINARY_FRICTION:
        return float(stack.nuisance_nl.get("friction_Nm", 0.0))
    grid = _grid(stack, effect)
    return float(grid[len(grid) // 2]) if NONLINEAR[effect][3] else 0.0


def _grid(stack: Stack, effect: str, n: int = 13) -> np.ndarray:
    _, lo, hi, log = NONLINEAR[effect]
    r = stack.rated_Nm
    if effect == "torque_sensor_offset":
        return offset_grid(stack, lo * r, hi * r)
    if log:
        return np.geomspace(lo * r, hi * r, n)
    if lo == 0.0:
        return np.concatenate([[0.0], np.geomspace(2e-4 * r, hi * r, n - 1)])
    return np.linspace(lo * r, hi * r, 2 * n + 1)


def offset_grid(stack: Stack, lo: float, hi: float, most: int = 160) -> np.ndarray:
    """Candidate torque offsets (N*m): the objective is piecewise constant in the offset, with
    steps where a point's chain torque crosses the flank band, so the candidates are the
    midpoints between those crossing offsets (at most ``most``, by quantile)."""
    vals = []
    for run in stack.runs:
        delta = 3.0 * run.sigma_torque_Nm + 1e-4 * run.rated_torque_Nm
        t = run.torque_Nm[(run.torque_Nm > lo - delta) & (run.torque_Nm < hi + delta)]
        vals += [t - delta, t + delta]
    v = np.unique(np.clip(np.concatenate(vals + [np.array([0.0])]), lo, hi))
    mids = np.concatenate([[0.0], 0.5 * (v[1:] + v[:-1])]) if v.size > 1 else np.array([0.0])
    mids = np.unique(mids)
    if mids.size > most:
        mids = np.unique(np.append(np.quantile(mids, np.linspace(0, 1, most)), 0.0))
    return mids


def fit_profile(stack: Stack, effects: Sequence[str], runs: Sequence[int] | None = None,
                start: dict[str, float] | None = None, local: bool = False) -> LinearFit:
    """Fit with the nonlinear parameters profiled: a grid (coordinate-wise, each effect's
    parameter in turn) then a bounded scalar refinement. ``start``/``local``: search only near
    a previous optimum (cross-validation folds)."""
    nls = nonlinear_of(effects)
    if ("torque_sensor_offset" in effects and "friction" not in effects
            and stack.nuisance_friction_max_Nm > 0):
        # an offset moves both flank switches one way, friction splits them: with the
        # ordinary friction held at the null's value the offset would make up for it
        nls.append(ORDINARY_FRICTION)
    current = {_nl_key(e): (start or {}).get(_nl_key(e), _nl_start(stack, e)) for e in nls}
    best = fit(stack, effects, runs, current)
    for _ in range(2 if len(nls) > 1 else 1):
        for e in nls:
            key = _nl_key(e)
            grid = _nl_grid(stack, e)
            if local and start is not None and key in start:
                j = int(np.argmin(np.abs(grid - start[key])))
                grid = np.unique(np.append(grid[max(0, j - 1): j + 2], start[key]))
            results = []
            for v in grid:
                trial = fit(stack, effects, runs, {**current, key: float(v)})
                results.append(trial)
            k = int(np.argmin([r.objective for r in results]))
            a = grid[max(0, k - 1)]
            b = grid[min(grid.size - 1, k + 1)]
            cand = results[k]
            if local:
                pass
            elif b > a and e != "torque_sensor_offset":
                def obj(v: float, key: str = key, held: dict = current) -> float:
                    return fit(stack, effects, runs, {**held, key: v}).objective

                opt = minimize_scalar(obj, bounds=(a, b), method="bounded",
                                      options={"xatol": 1e-4 * stack.rated_Nm, "maxiter": 10})
                if opt.fun < cand.objective:
                    cand = fit(stack, effects, runs, {**current, key: float(opt.x)})
            elif b > a:  # the offset moves flank switches: a finer grid, no gradients
                fine = np.linspace(a, b, 9)
                trials = [fit(stack, effects, runs, {**current, key: float(v)}) for v in fine]
                j = int(np.argmin([t.objective for t in trials]))
                if trials[j].objective < cand.objective:
                    cand = trials[j]
                # the objective is flat between flank switches: the data bound the offset to
                # that interval only. Its 95 % profile-likelihood interval (objective within
                # chi2_1(0.95) / 2 = 1.92 of the best); take its middle and keep its bounds
                # (plausibility is judged at the bound nearest zero)
                objs = np.array([r.objective for r in results])
                flat = objs <= cand.objective + PROFILE_95
                lo_j = hi_j = k
                while lo_j > 0 and flat[lo_j - 1]:
                    lo_j -= 1
                while hi_j < grid.size - 1 and flat[hi_j + 1]:
                    hi_j += 1
                if hi_j > lo_j:
                    mid = 0.5 * (float(grid[lo_j]) + float(grid[hi_j]))
                    trial = fit(stack, effects, runs, {**current, key: mid})
                    if trial.objective <= cand.objective + PROFILE_95:
                        cand = trial
                    span = (float(grid[lo_j]), float(grid[hi_j]))
                    cand.nl["torque_offset_nearest_zero_Nm"] = (
                        0.0 if span[0] <= 0.0 <= span[1] else min(span, key=abs))
                    cand.nl["torque_offset_low_Nm"], cand.nl["torque_offset_high_Nm"] = span
            current = dict(cand.nl)
            best = cand
    return best


#: Linear coefficients (name prefixes) and nonlinear parameters of each candidate's own term.
OWN_TERMS = {
    "friction": ((), ("friction_Nm",)),
    "torque_sensor_offset": ((), ("torque_offset_Nm",)),
    "stiffness_nonlinearity": (("soft_twist",), ()),
    "bearing_clearance": (("bearing_compliance",), ()),
    "runout": (("runout_",), ()),
    "thermal_expansion": (("thermal",), ()),
    "tooth_spacing_error": (("tooth_",), ()),
}


CROSSING_SHARE = 0.05
"""Half-width of the play-crossing band (share of a run's torque amplitude) left out of an
effect's size, beside the fitted friction and sensor offset that move the flank change."""


def on_flanks(run: PreparedRun, f: LinearFit) -> np.ndarray:
    """Blocks of ``run`` on a flank, away from the play crossing: |T| beyond 5 % of the
    amplitude and beyond twice the fitted friction plus the sensor offset."""
    band = max(CROSSING_SHARE * run.amplitude_Nm,
               2.0 * abs(f.nl.get("friction_Nm", 0.0)) + abs(f.nl.get("torque_offset_Nm", 0.0)))
    keep = np.abs(run.torque_Nm) > band
    return keep if keep.sum() >= 4 else np.ones_like(keep, dtype=bool)


def effect_size_arcmin(stack: Stack, f: LinearFit, effects: Sequence[str], name: str) -> float:
    """RMS (arcmin) of one effect's own term in a joint fit: the fitted twist minus the twist
    with that effect switched off (its coefficients zeroed, its friction/offset set to 0),
    each run's mean removed (the twist zero is free). Friction's size is read on the flanks
    (:func:`on_flanks`): its loop signature is the branch separation 2 T_c / K there (seed 000
    Fig. 6's hysteresis), while in the crossing band switching it off moves the whole-play
    step of the flank change. A sensor offset keeps its band: at a commanded zero it holds
    the unit on the other flank for the whole dwell, a real twist difference of the play."""
    coefs, nls = OWN_TERMS.get(name, ((), ()))
    beta0 = np.array([0.0 if any(n.startswith(c) for c in coefs) else b
                      for n, b in zip(f.names, f.beta, strict=True)])
    nl0 = {k: (0.0 if k in nls else v) for k, v in f.nl.items()}
    teeth = teeth_of(stack)
    sq, n = 0.0, 0
    for run in stack.runs:
        full = run_columns(stack, run, ("backlash", *effects), f.nl, teeth) @ f.beta
        off = run_columns(stack, run, ("backlash", *effects), nl0, teeth) @ beta0
        d = full - off
        if name == "friction":
            d = d[on_flanks(run, f)]
        d = d - d.mean()
        sq += float(d @ d)
        n += d.size
    return math.sqrt(sq / n) if n else 0.0


def loop_params(stack: Stack, f: LinearFit) -> LoopParams:
    """The analysis.effects parameters of a fit."""
    comp = f.coef("compliance")
    teeth = {int(n.split("_")[1]): float(b) for n, b in zip(f.names, f.beta, strict=True)
             if n.startswith("tooth_")}
    return LoopParams(
        play_arcmin=f.coef("play"),
        stiffness_Nm_per_arcmin=1.0 / comp if comp > 0 else math.inf,
        friction_Nm=f.nl.get("friction_Nm", 0.0),
        soft_twist_arcmin=f.coef("soft_twist"),
        stiffening_torque_Nm=f.nl.get("stiffening_torque_Nm", 1.0),
        runout_coeffs_arcmin=tuple(f.coef(n) for n in
                                   ("runout_c1", "runout_s1", "runout_c2", "runout_s2")),
        runout_order2_arcmin=(f.coef("runout_h2c"), f.coef("runout_h2s")),
        bearing_compliance_arcmin_per_Nm=f.coef("bearing_compliance"),
        bearing_stage_torque_Nm=f.nl.get("bearing_stage_torque_Nm", 0.0),
        thermal_arcmin_per_K=f.coef("thermal"),
        thermal_arcmin_per_K2=f.coef("thermal2"),
        thermal_reference_C=stack.reference_C,
        torque_offset_Nm=f.nl.get("torque_offset_Nm", 0.0),
        spacing_play_arcmin=teeth,
        runout_order=None if stack.physics is None else stack.physics.runout_order,
    )


def predict_run(stack: Stack, f: LinearFit, effects: Sequence[str], i: int) -> np.ndarray:
    """Residual (arcmin) of run i under fit f, with the run's own free twist offset."""
    run = stack.runs[i]
    teeth = teeth_of(stack)
    X = run_columns(stack, run, effects, f.nl, teeth)
    floating, across = run_float_masks(run, f.nl)
    r = run.twist_arcmin - X @ f.beta
    keep = ~floating
    r = r - (r[keep].mean() if keep.any() else r.mean())
    return censor_floating(r, X, f.beta, floating, across)[0]


def run_lost_motion(stack: Stack, params: LoopParams, i: int) -> float:
    """Lost motion (arcmin, +-3 % of rated) the model predicts for run i's conditions."""
    run = stack.runs[i]
    return model_lost_motion_arcmin(
        params, run.rated_torque_Nm, 3.0, input_angle_deg=run.input_angle_deg,
        temperature_C=run.mean_temperature_C, z_internal=stack.z_internal,
        z_external=stack.z_external, amplitude_Nm=run.amplitude_Nm)
