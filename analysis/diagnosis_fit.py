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
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import lsq_linear, minimize_scalar

from analysis.diagnosis_data import PreparedRun
from analysis.effects import (
    LoopParams,
    chain_torque_Nm,
    flank_sign,
    model_lost_motion_arcmin,
    runout_basis,
    tooth_pair_index,
    um_to_arcmin,
)
from analysis.errors import AnalysisError

HUBER_C = 2.5
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

    @property
    def n_runs(self) -> int:
        return len(self.runs)


def _num(unit: dict, key: str, default: float) -> float:
    value = unit.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return default
    return float(value)


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
    return Stack(
        runs=tuple(runs), z_internal=z1, z_external=z2, module_mm=m, pressure_angle_deg=alpha,
        runout_budget_arcmin=float(um_to_arcmin(runout_um, m, z1)),
        spacing_budget_arcmin=float(um_to_arcmin(4.0, m, z1)),
        reference_C=float(np.mean(temps)) if temps else 20.0,
        rated_Nm=float(np.median([r.rated_torque_Nm for r in runs])),
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
    if "thermal_expansion" in effects:
        names.append("thermal")
    if "tooth_spacing_error" in effects:
        names += [f"tooth_{t}" for t in teeth]
    return names


def run_columns(stack: Stack, run: PreparedRun, effects: Sequence[str], nl: dict[str, float],
                teeth: Sequence[int]) -> np.ndarray:
    """Columns (see :func:`column_names`) of one run: the composed loop of analysis.effects
    written as ``twist = X beta + offset``."""
    torque = run.torque_Nm - nl.get("torque_offset_Nm", 0.0)
    g = chain_torque_Nm(torque, nl.get("friction_Nm", 0.0), run.start_flank)
    s = flank_sign(g, 3.0 * run.sigma_torque_Nm + 1e-4 * run.rated_torque_Nm, run.start_flank)
    tau = np.abs(g)
    cols = [s / 2.0, s * tau]
    if "stiffness_nonlinearity" in effects:
        cols.append(s * -np.expm1(-tau / nl["stiffening_torque_Nm"]))
    if "bearing_clearance" in effects:
        cols.append(s * np.minimum(tau, nl["bearing_stage_torque_Nm"]))
    if "runout" in effects:
        basis = runout_basis(run.input_angle_deg or 0.0, stack.z_internal, stack.z_external)
        cols += [s / 2.0 * b for b in basis]
    if "thermal_expansion" in effects:
        temp = run.temperature_C if run.temperature_C is not None else np.full(s.size, math.nan)
        cols.append(s / 2.0 * (temp - stack.reference_C))
    if "tooth_spacing_error" in effects:
        tooth = int(tooth_pair_index(run.input_angle_deg or 0.0, stack.z_internal))
        cols += [s / 2.0 * (1.0 if t == tooth else 0.0) for t in teeth]
    return np.column_stack(cols)


def teeth_of(stack: Stack) -> list[int]:
    return sorted({int(tooth_pair_index(r.input_angle_deg or 0.0, stack.z_internal))
                   for r in stack.runs})


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


def _solve(blocks: list[tuple[np.ndarray, np.ndarray, np.ndarray]], lo: np.ndarray,
           hi: np.ndarray, prior: np.ndarray, fixed: np.ndarray | None, iterations: int = 3,
           ) -> tuple[np.ndarray, float, float, int, list[np.ndarray], np.ndarray | None]:
    """Robust bounded LS with per-run offsets projected out. ``blocks``: (X, y, sigma) per
    run. ``fixed``: coefficients held (predictive gap) instead of fitted."""
    p = blocks[0][0].shape[1]
    weights = [np.ones(y.size) for _, y, _ in blocks]
    beta = fixed if fixed is not None else np.zeros(p)
    cov = None
    for _ in range(iterations):
        if fixed is None:
            rows, rhs = [], []
            for (X, y, sig), w in zip(blocks, weights, strict=True):
                ww = w / sig**2
                sw = np.sqrt(ww)
                xm = (ww @ X) / ww.sum()
                ym = (ww @ y) / ww.sum()
                rows.append((X - xm) * sw[:, None])
                rhs.append((y - ym) * sw)
            has_prior = np.isfinite(prior)
            if has_prior.any():
                pr = np.zeros((int(has_prior.sum()), p))
                pr[np.arange(pr.shape[0]), np.flatnonzero(has_prior)] = 1.0 / prior[has_prior]
                rows.append(pr)
                rhs.append(np.zeros(pr.shape[0]))
            A = np.vstack(rows)
            b = np.concatenate(rhs)
            scale = np.sqrt((A**2).sum(axis=0))
            scale[scale == 0] = 1.0
            res = lsq_linear(A / scale, b, bounds=(lo * scale, hi * scale), method="bvls",
                             lsmr_tol="auto")
            beta = res.x / scale
            try:
                cov = np.linalg.pinv(A.T @ A)
            except np.linalg.LinAlgError:
                cov = None
        new_w = []
        for X, y, sig in blocks:
            r = y - X @ beta
            r = r - np.median(r)
            u = np.abs(r) / sig
            new_w.append(np.minimum(1.0, HUBER_C / np.maximum(u, 1e-12)))
        weights = new_w
    objective, chi2, n, residuals = 0.0, 0.0, 0, []
    for (X, y, sig), w in zip(blocks, weights, strict=True):
        r = y - X @ beta
        ww = w / sig**2
        r = r - (ww @ r) / ww.sum()
        u = np.abs(r) / sig
        objective += float(np.sum(np.where(u <= HUBER_C, 0.5 * u**2,
                                           HUBER_C * (u - 0.5 * HUBER_C))))
        chi2 += float(np.sum(u**2))
        n += r.size
        residuals.append(r)
    return beta, objective, chi2, n, residuals, cov


def fit(stack: Stack, effects: Sequence[str], runs: Sequence[int] | None = None,
        nl: dict[str, float] | None = None, fixed: dict[str, float] | None = None,
        ) -> LinearFit:
    """Fit the effects' linear coefficients for given nonlinear ones (``nl``) on ``runs``
    (indices; None: all). ``fixed`` holds play and compliance (predictive gap)."""
    idx = list(range(stack.n_runs)) if runs is None else list(runs)
    nl = dict(nl or {})
    teeth = teeth_of(stack)
    names = column_names(stack, effects, teeth)
    blocks = []
    for i in idx:
        run = stack.runs[i]
        X = run_columns(stack, run, effects, nl, teeth)
        blocks.append((X, run.twist_arcmin, np.full(run.twist_arcmin.size, run.sigma_arcmin)))
    lo, hi, prior = bounds_and_prior(stack, names)
    fixed_beta = None
    if fixed is not None:
        fixed_beta = np.array([fixed.get(nm, 0.0) for nm in names])
    beta, obj, chi2, n, residuals, cov = _solve(blocks, lo, hi, prior, fixed_beta)
    fitres = LinearFit(tuple(names), beta, nl, obj, chi2, n, cov=cov)
    fitres.residual = {stack.runs[i].run_id: r for i, r in zip(idx, residuals, strict=True)}
    return fitres


def nonlinear_of(effects: Sequence[str]) -> list[str]:
    return [e for e in effects if e in NONLINEAR]


def _grid(stack: Stack, effect: str, n: int = 17) -> np.ndarray:
    _, lo, hi, log = NONLINEAR[effect]
    r = stack.rated_Nm
    if log:
        return np.geomspace(lo * r, hi * r, n)
    if lo == 0.0:
        return np.concatenate([[0.0], np.geomspace(2e-4 * r, hi * r, n - 1)])
    return np.linspace(lo * r, hi * r, 2 * n + 1)


def fit_profile(stack: Stack, effects: Sequence[str], runs: Sequence[int] | None = None,
                start: dict[str, float] | None = None, local: bool = False) -> LinearFit:
    """Fit with the nonlinear parameters profiled: a grid (coordinate-wise, each effect's
    parameter in turn) then a bounded scalar refinement. ``start``/``local``: search only near
    a previous optimum (cross-validation folds)."""
    nls = nonlinear_of(effects)
    current = {NONLINEAR[e][0]: (start or {}).get(NONLINEAR[e][0], _grid(stack, e)[
        len(_grid(stack, e)) // 2] if NONLINEAR[e][3] else 0.0) for e in nls}
    best = fit(stack, effects, runs, current)
    for _ in range(2 if len(nls) > 1 else 1):
        for e in nls:
            key = NONLINEAR[e][0]
            grid = _grid(stack, e)
            if local and start is not None and key in start:
                j = int(np.argmin(np.abs(grid - start[key])))
                grid = grid[max(0, j - 2): j + 3]
            results = []
            for v in grid:
                trial = fit(stack, effects, runs, {**current, key: float(v)})
                results.append(trial)
            k = int(np.argmin([r.objective for r in results]))
            a = grid[max(0, k - 1)]
            b = grid[min(grid.size - 1, k + 1)]
            cand = results[k]
            if b > a and e != "torque_sensor_offset":
                def obj(v: float, key: str = key, held: dict = current) -> float:
                    return fit(stack, effects, runs, {**held, key: v}).objective

                opt = minimize_scalar(obj, bounds=(a, b), method="bounded",
                                      options={"xatol": 1e-4 * stack.rated_Nm, "maxiter": 12})
                if opt.fun < cand.objective:
                    cand = fit(stack, effects, runs, {**current, key: float(opt.x)})
            elif b > a:  # the offset moves flank switches: a fine grid, no gradients
                fine = np.linspace(a, b, 21)
                trials = [fit(stack, effects, runs, {**current, key: float(v)}) for v in fine]
                j = int(np.argmin([t.objective for t in trials]))
                if trials[j].objective < cand.objective:
                    cand = trials[j]
            current = dict(cand.nl)
            best = cand
    return best


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
        bearing_compliance_arcmin_per_Nm=f.coef("bearing_compliance"),
        bearing_stage_torque_Nm=f.nl.get("bearing_stage_torque_Nm", 0.0),
        thermal_arcmin_per_K=f.coef("thermal"),
        thermal_reference_C=stack.reference_C,
        torque_offset_Nm=f.nl.get("torque_offset_Nm", 0.0),
        spacing_play_arcmin=teeth,
    )


def predict_run(stack: Stack, f: LinearFit, effects: Sequence[str], i: int) -> np.ndarray:
    """Residual (arcmin) of run i under fit f, with the run's own free twist offset."""
    run = stack.runs[i]
    teeth = teeth_of(stack)
    X = run_columns(stack, run, effects, f.nl, teeth)
    r = run.twist_arcmin - X @ f.beta
    return r - r.mean()


def run_lost_motion(stack: Stack, params: LoopParams, i: int) -> float:
    """Lost motion (arcmin, +-3 % of rated) the model predicts for run i's conditions."""
    run = stack.runs[i]
    return model_lost_motion_arcmin(
        params, run.rated_torque_Nm, 3.0, input_angle_deg=run.input_angle_deg,
        temperature_C=run.mean_temperature_C, z_internal=stack.z_internal,
        z_external=stack.z_external, amplitude_Nm=run.amplitude_Nm)
