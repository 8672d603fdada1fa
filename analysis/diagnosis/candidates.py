"""The candidates: each effect of the vocabulary fitted on all runs and cross-validated.

:class:`Candidate` is one fit (or a combination) with its held-out gap; :class:`Trials` is
what every candidate is judged against (the null fit, its held-out gap, the folds, the
noise); :func:`screen` fits every testable candidate in sample and holds out the best.
:func:`describe_params` turns a fit into physical parameters and checks them against the
unit's tolerance budget; :func:`separated` says whether the held-out runs separate two
candidates; :func:`curvature_effect` names a flank curvature by its loaded slope.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.stats import binomtest

from analysis.diagnosis.data import PreparedRun
from analysis.diagnosis.evidence import calibrated_evidence
from analysis.diagnosis.fit import (
    NONLINEAR,
    LinearFit,
    Stack,
    cached_columns,
    fit,
    fit_profile,
    loop_params,
    predict_run,
    run_lost_motion,
    teeth_of,
)
from analysis.diagnosis.policy import POLICY, DecisionPolicy
from analysis.effects import CANDIDATES, arcmin_to_um, bearing_play_arcmin


@dataclass
class Candidate:
    """One candidate (or a combination) fitted on all runs and cross-validated."""

    effects: tuple[str, ...]
    fit: LinearFit
    heldout_rms_arcmin: float
    heldout_lm_error_arcmin: float
    heldout_runs: int
    scheme: str
    delta_bic: float = 0.0
    params: dict[str, Any] = field(default_factory=dict)
    plausible: bool = True
    notes: list[str] = field(default_factory=list)
    screened_out: bool = False
    heldout_resid: dict[str, np.ndarray] = field(default_factory=dict, repr=False)


def _heldout(stack: Stack, effects: tuple[str, ...], folds: list[list[int]],
             full: LinearFit) -> tuple[float, float, int, dict[str, np.ndarray]]:
    """Pooled held-out RMS twist residual (arcmin), RMS lost-motion error (arcmin), runs."""
    sq, n, lm_err, runs = 0.0, 0, [], 0
    resid: dict[str, np.ndarray] = {}
    for test in folds:
        train = [i for i in range(stack.n_runs) if i not in test]
        if not train:
            continue
        f = fit_profile(stack, ("backlash", *effects), train, start=full.nl, local=True) \
            if any(e in ("friction", "torque_sensor_offset", "stiffness_nonlinearity",
                         "bearing_clearance") for e in effects) \
            else fit(stack, ("backlash", *effects), train)
        params = loop_params(stack, f)
        for i in test:
            r = predict_run(stack, f, ("backlash", *effects), i)
            resid[stack.runs[i].run_id] = r
            sq += float(r @ r)
            n += r.size
            runs += 1
            lm_meas = stack.runs[i].lost_motion_arcmin
            if math.isfinite(lm_meas):
                lm_err.append(run_lost_motion(stack, params, i) - lm_meas)
    rms = math.sqrt(sq / n) if n else math.nan
    lm = math.sqrt(float(np.mean(np.square(lm_err)))) if lm_err else math.nan
    return rms, lm, runs, resid


def _full_fit(stack: Stack, effects: tuple[str, ...]) -> LinearFit:
    """Fit on all runs (profiled nonlinear parameters), with the coefficient covariance."""
    full = fit_profile(stack, ("backlash", *effects)) if any(
        e in ("friction", "torque_sensor_offset", "stiffness_nonlinearity",
              "bearing_clearance") for e in effects) else fit(stack, ("backlash", *effects))
    return fit(stack, ("backlash", *effects), None, full.nl, want_cov=True)


def _insample(stack: Stack, f: LinearFit) -> tuple[float, float]:
    r = np.concatenate(list(f.residual.values()))
    lm_err = []
    params = loop_params(stack, f)
    for i, run in enumerate(stack.runs):
        if math.isfinite(run.lost_motion_arcmin):
            lm_err.append(run_lost_motion(stack, params, i) - run.lost_motion_arcmin)
    lm = math.sqrt(float(np.mean(np.square(lm_err)))) if lm_err else math.nan
    return float(np.sqrt(np.mean(r**2))), lm


ARCSEC = 60.0


def _bic(f: LinearFit) -> float:
    return 2.0 * f.objective + len(f.beta) * math.log(max(f.n, 2))


def _ci(f: LinearFit, name: str, sigma_scale: float) -> float | None:
    if f.cov is None or name not in f.names:
        return None
    j = f.names.index(name)
    v = f.cov[j, j]
    return float(1.96 * math.sqrt(v) * sigma_scale) if v >= 0 and math.isfinite(v) else None


def describe_params(stack: Stack, effects: Sequence[str], f: LinearFit,
                    policy: DecisionPolicy = POLICY) -> tuple[dict[str, Any], bool, list[str]]:
    """Physical parameters of a fit (units in names), 95 % intervals where linear, and the
    plausibility check against the unit's tolerance budget."""
    out: dict[str, Any] = {}
    notes: list[str] = []
    ok = True
    scale = math.sqrt(max(2.0 * f.objective / max(f.n - len(f.beta), 1), 1.0))
    rated = stack.rated_Nm
    unit = dict(stack.runs[0].raw.unit or {})
    for e in effects:
        if e == "friction":
            out["friction_Nm"] = f.nl.get("friction_Nm", 0.0)
            if out["friction_Nm"] > policy.friction_max_share * rated:
                ok = False
                notes.append(f"friction above {policy.friction_max_share * 100:g} % of "
                             "rated torque")
            if out["friction_Nm"] <= policy.friction_allowance * rated:
                ok = False
                notes.append(f"friction {out['friction_Nm']:.3g} N*m within the ordinary "
                             f"friction of every unit and rig ({policy.friction_allowance:.0%} of "
                             "rated): part of the null model, not a finding")
        elif e == "torque_sensor_offset":
            out["offset_Nm"] = f.nl.get("torque_offset_Nm", 0.0)
            nearest = f.nl.get("torque_offset_nearest_zero_Nm", out["offset_Nm"])
            out["offset_nearest_zero_Nm"] = nearest
            if "torque_offset_low_Nm" in f.nl:
                out["offset_interval_Nm"] = [f.nl["torque_offset_low_Nm"],
                                             f.nl["torque_offset_high_Nm"]]
            if abs(nearest) > policy.offset_max_share * rated:
                ok = False
                notes.append(f"torque offset above {policy.offset_max_share * 100:g} % of "
                             "rated torque")
            if stack.offset_veto:
                ok = False
                notes.append(stack.offset_veto)
        elif e == "stiffness_nonlinearity":
            out["soft_twist_arcmin"] = f.coef("soft_twist")
            out["soft_twist_arcmin_ci95"] = _ci(f, "soft_twist", scale)
            out["torque_scale_Nm"] = f.nl.get("stiffening_torque_Nm")
            # a contact's hardening is its Hertzian approach beyond the linear spring, a few
            # um: more extra twist than the whole designed free play is a flank change
            # (play), not a contact layer
            nominal = stack.runs[0].nominal
            play = nominal.play_arcmin if nominal is not None else math.nan
            if math.isfinite(play) and play > 0 and out["soft_twist_arcmin"] > play:
                ok = False
                notes.append(f"contact stiffening's extra twist {out['soft_twist_arcmin']:.3f} "
                             f"arcmin above the nominal free play ({play:.3f} arcmin)")
        elif e == "bearing_clearance":
            ok = _bearing_clearance_params(stack, f, out, notes, policy, unit) and ok
        elif e == "runout":
            ok = _runout_params(stack, f, out, notes, policy, unit) and ok
        elif e == "thermal_expansion":
            c = f.coef("thermal")
            out["coefficient_arcmin_per_K"] = c
            out["coefficient_arcmin_per_K_ci95"] = _ci(f, "thermal", scale)
            out["coefficient_um_per_K"] = float(_um(stack, c))
            if stack.thermal_lag_s > 0.0:
                # the play follows the mesh temperature, lagging the housing sensor
                out["mesh_lag_s"] = stack.thermal_lag_s
            slope = abs(out["coefficient_um_per_K"])
            if "thermal2" in f.names:
                c2 = f.coef("thermal2")
                out["quadratic_arcmin_per_K2"] = c2
                out["quadratic_um_per_K2"] = float(_um(stack, c2))
                # the local coefficient d(play)/dT at the ends of the campaign's range
                temps = [r.mean_temperature_C for r in stack.runs
                         if r.mean_temperature_C is not None]
                ends = [min(temps) - stack.reference_C, max(temps) - stack.reference_C]
                slope = max(abs(out["coefficient_um_per_K"] + 2.0 * out["quadratic_um_per_K2"]
                                * d) for d in ends)
            limit = (policy.thermal_limit_um_per_K if stack.physics is None
                     else stack.physics.thermal_limit_um_per_K)
            if slope > limit:
                ok = False
                notes.append(f"thermal play change above {limit:g} um/K")
        elif e == "tooth_spacing_error":
            teeth = {n: float(b) for n, b in zip(f.names, f.beta, strict=True)
                     if n.startswith("tooth_")}
            vals = np.array(list(teeth.values())) if teeth else np.zeros(1)
            out["play_change_arcmin_rms"] = float(np.std(vals))
            out["play_change_um_rms"] = float(_um(stack, np.std(vals)))
            out["per_tooth_arcmin"] = {k.split("_")[1]: v for k, v in teeth.items()}
            limit = (policy.spacing_limit_um if stack.physics is None
                     else stack.physics.spacing_limit_um)
            if out["play_change_um_rms"] > limit:
                ok = False
                notes.append(f"tooth-to-tooth play change above {limit:g} um rms")
    return out, ok, notes


def _bearing_clearance_params(stack: Stack, f: LinearFit, out: dict[str, Any], notes: list[str],
                              policy: DecisionPolicy, unit: dict[str, Any]) -> bool:
    """A bearing soft stage's parameters; False when its take-up is implausible (a stage
    ending at the search's bound, or more play than budget_factor times the inspected
    clearances give)."""
    ok = True
    m, z1, rated = stack.module_mm, stack.z_internal, stack.rated_Nm
    cb = f.coef("bearing_compliance")
    out["soft_stiffness_Nm_per_arcmin"] = 1.0 / cb if cb > 0 else None
    out["soft_stage_torque_Nm"] = f.nl.get("bearing_stage_torque_Nm")
    clear = unit.get("bearing_clearance_mm")
    take_up = cb * (f.nl.get("bearing_stage_torque_Nm") or 0.0)
    out["take_up_twist_arcmin"] = take_up
    top = NONLINEAR["bearing_clearance"][2] * rated
    if (f.nl.get("bearing_stage_torque_Nm") or 0.0) >= policy.bearing_stage_bound * top:
        # the best soft stage would end beyond the range searched: no take-up that
        # closes inside the loaded range, a slope change over all of it
        ok = False
        notes.append(f"the soft stage does not end inside the loaded range (stage "
                     f"torque at the search's bound, {top:.3g} N*m): a slope change, "
                     "not a clearance taken up")
    if stack.physics is not None:
        clear = None
        if stack.physics.bearing_budget_arcmin is not None:
            out["budget_extra_play_arcmin"] = stack.physics.bearing_budget_arcmin
            budget = stack.physics.bearing_budget_arcmin
            if budget > 0 and take_up > policy.budget_factor * budget:
                ok = False
                notes.append(f"soft stage takes up {take_up:.3f} arcmin, above twice "
                             f"the inspected bearing clearances' play ({budget:.3f} "
                             f"arcmin, {stack.physics.kind} geometry)")
    if isinstance(clear, list) and clear:
        budget = bearing_play_arcmin(clear, stack.pressure_angle_deg, m, z1)
        out["budget_extra_play_arcmin"] = budget
        # the soft stage takes up the clearance: the twist it adds on a flank is
        # bounded by the play the inspected clearances give (seed 000 eqs. 3 + 7),
        # with the same factor two as the runout's
        if budget > 0 and take_up > policy.budget_factor * budget:
            ok = False
            notes.append(f"soft stage takes up {take_up:.3f} arcmin, above twice the "
                         f"inspected bearing clearances' play ({budget:.3f} arcmin)")
    return ok


def _runout_params(stack: Stack, f: LinearFit, out: dict[str, Any], notes: list[str],
                   policy: DecisionPolicy, unit: dict[str, Any]) -> bool:
    """Runout's parameters (play change, eccentricities); False when the play change is
    above budget_factor times the inspected runout's."""
    ok = True
    c = [f.coef(n) for n in ("runout_c1", "runout_s1", "runout_c2", "runout_s2")]
    # play change = -2 tan(a) (|AB| - a): amplitude in play -> eccentricity (um)
    k = 2.0 * math.tan(math.radians(stack.pressure_angle_deg))
    amp_int = math.hypot(c[0], c[1])
    amp_ext = math.hypot(c[2], c[3])
    amp_2 = math.hypot(f.coef("runout_h2c"), f.coef("runout_h2s"))
    out["amplitude_arcmin"] = amp_int + amp_ext + amp_2
    if stack.physics is not None:
        # the kind's two eccentricity terms may turn at nearly one rate (a cycloid's
        # 1 and (2 z1 - z2) / z1 per crank turn): their split is then not determined
        # by the positions, only the play change over them is
        out["amplitude_arcmin"] = kind_runout_swing_arcmin(stack, c)
    if "runout_h2c" in f.names:
        out["order2_amplitude_arcmin"] = amp_2
        out["order2_play_um"] = float(_um(stack, amp_2))
    out["internal_um"] = float(_um(stack, amp_int)) / k
    out["internal_phase_deg"] = math.degrees(math.atan2(-c[1], -c[0]))
    out["external_um"] = float(_um(stack, amp_ext)) / k
    if stack.physics is not None:
        # the eccentricities by the kind's own center distance -> play (kind_physics)
        out["internal_um"] = stack.physics.eccentricity_um(amp_int)
        out["external_um"] = stack.physics.eccentricity_um(amp_ext)
    out["beta_deg"] = math.degrees(math.atan2(-c[3], -c[2]))
    out["amplitude_um"] = out["internal_um"] + out["external_um"]
    budget = policy.budget_factor * stack.runout_budget_arcmin
    if out["amplitude_arcmin"] > budget:
        ok = False
        notes.append(f"runout play change {out['amplitude_arcmin']:.3f} arcmin above "
                     f"twice the inspected runout's ({budget:.3f} arcmin)")
    return ok


def kind_runout_swing_arcmin(stack: Stack, coeffs: Sequence[float]) -> float:
    """The largest runout play change (arcmin) the fitted eccentricity terms give over the
    campaign's span of input angles (the kind's basis,
    analysis.diagnosis.kind_physics.KindPhysics.runout_basis)."""
    angles = [r.input_angle_deg for r in stack.runs if r.input_angle_deg is not None]
    if not angles or stack.physics is None:
        return 0.0
    lo, hi = min(angles), max(max(angles), min(angles) + 360.0)
    grid = np.linspace(lo, hi, 721)
    basis = np.array([stack.physics.runout_basis(a) for a in grid])
    return float(np.max(np.abs(basis @ np.asarray(coeffs, dtype=float))))


def _um(stack: Stack, angle_arcmin: float) -> float:
    """An output angle (arcmin) as circumferential play (um): seed 000 eq. (1), or the unit
    kind's own reference radius (analysis.diagnosis.kind_physics)."""
    if stack.physics is not None:
        return float(stack.physics.arcmin_to_um(angle_arcmin))
    return float(arcmin_to_um(angle_arcmin, stack.module_mm, stack.z_internal))


def _sys(h: float, noise: float) -> float:
    return math.sqrt(max(h * h - noise * noise, 0.0))


def quantisation_floor_arcmin(runs: Sequence[PreparedRun]) -> float:
    """RMS quantisation error of one output-encoder reading, ``q / sqrt(12)`` (arcmin), the
    median over the runs of the count read from the data's grid
    (:func:`analysis.diagnosis.data.resolution_of`); 0 when no grid is found."""
    qs = [r.measurement.get("twist_resolution_arcsec") for r in runs]
    qs = [q for q in qs if q is not None and math.isfinite(q) and q > 0]
    return float(np.median(qs)) / ARCSEC / math.sqrt(12.0) if qs else 0.0


def heldout_separation(stack: Stack, a: Candidate, b: Candidate) -> tuple[float, float]:
    """Held-out evidence that ``a`` fits better than ``b`` on the same folds: the ratio of their
    pooled held-out mean squared standardised residuals (b over a; each run's residual over its
    block-mean noise) and the share of held-out runs on which ``a``'s is the smaller."""
    sig = {r.run_id: r.sigma_arcmin for r in stack.runs}
    ids = [k for k in a.heldout_resid if k in b.heldout_resid]
    if not ids:
        return 1.0, 0.0
    za = np.array([float(np.sum((a.heldout_resid[k] / sig[k]) ** 2)) for k in ids])
    zb = np.array([float(np.sum((b.heldout_resid[k] / sig[k]) ** 2)) for k in ids])
    ratio = float(zb.sum() / za.sum()) if za.sum() > 0 else math.inf
    return ratio, float(np.mean(za < zb))


def separated(stack: Stack, best: Candidate, other: Candidate,
              policy: DecisionPolicy = POLICY) -> bool:
    """True when ``best`` is clearly better than ``other`` on held-out data (ratio of mean
    squared standardised residuals >= SEPARATION_RATIO, consistently over the held-out runs)
    and on the information criterion (BIC lower by SEPARATION_BIC): then the design separates
    them and the verdict is ``best``, not ``ambiguous``."""
    ratio, wins = heldout_separation(stack, best, other)
    if other.delta_bic - best.delta_bic < policy.separation_bic:
        return False
    n = len([k for k in best.heldout_resid if k in other.heldout_resid])
    if ratio >= policy.separation_ratio and wins >= policy.separation_wins:
        return True
    k = int(round(wins * n))
    return (n > 0 and ratio >= policy.separation_ratio_consistent
            and binomtest(k, n, 0.5, alternative="greater").pvalue <= policy.separation_p)


def compliance_rel_se(f: LinearFit) -> float:
    """Relative standard error of a fit's loaded compliance (the same of its stiffness to
    first order), scaled by the fit's reduced chi-square when above 1; 0 when the fit has no
    covariance."""
    comp = f.coef("compliance")
    if f.cov is None or "compliance" not in f.names or comp <= 0:
        return 0.0
    j = f.names.index("compliance")
    scale = math.sqrt(max(2.0 * f.objective / max(f.n - len(f.beta), 1), 1.0))
    return math.sqrt(max(f.cov[j, j], 0.0)) * scale / comp


def stiffness_gap_tolerance(policy: DecisionPolicy, rel_se: float, quant: float = 0.0
                            ) -> float:
    """The relative departure of the calibrated stiffness from seed 004 eq. (8) that is a gap
    when nothing else is wrong: ``stiffness_gap``, or ``stiffness_se_factor`` standard errors
    (``rel_se``, relative) of the calibrated compliance when the loops measure it less
    well, or ``quant`` (:func:`quantisation_share`) when the encoder's count is coarse
    against the loaded twist."""
    return max(policy.stiffness_gap, policy.stiffness_se_factor * rel_se, quant)


def quantisation_share(runs: Sequence[PreparedRun], k_nom: float) -> float:
    """Half an output-encoder count over the loaded twist (the amplitude over seed 004
    eq. (8)'s stiffness), the largest over the runs: the quantisation's error lines up with
    the loading, so the slope of a loaded branch a few counts long is off by up to about
    this share, and no standard error shows it (relative; 0 when no grid is found)."""
    if not (math.isfinite(k_nom) and k_nom > 0):
        return 0.0
    out = 0.0
    for r in runs:
        q = r.measurement.get("twist_resolution_arcsec")
        if q is None or not (math.isfinite(q) and q > 0) or r.amplitude_Nm <= 0:
            continue
        out = max(out, 0.5 * (q / ARCSEC) / (r.amplitude_Nm / k_nom))
    return out


def series_compliance(f: LinearFit, k_nom: float, policy: DecisionPolicy = POLICY
                      ) -> dict[str, Any] | None:
    """A series compliance left once the effects are fitted: the loaded stiffness of the final
    model more than the tolerance (STIFFNESS_TOLERANCE or two standard errors) below seed 004
    eq. (8). From loops it cannot be told from a softer mesh, so it is only ever listed beside
    an effect (``also``), with the series stiffness ``1 / (1/K - 1/K_nom)``."""
    comp = f.coef("compliance")
    if comp <= 0 or not math.isfinite(k_nom) or k_nom <= 0:
        return None
    k_load = 1.0 / comp
    rel_se = compliance_rel_se(f)
    tol = max(policy.stiffness_tolerance, policy.stiffness_se_factor * rel_se)
    if k_load >= k_nom * (1.0 - tol):
        return None
    return {"effect": "shaft_compliance", "shrink": 0.0, "shrink_in_sample": True,
            "params": {"stiffness_Nm_per_arcmin": 1.0 / (1.0 / k_load - 1.0 / k_nom),
                       "loaded_stiffness_Nm_per_arcmin": k_load},
            "evidence": f"loaded stiffness {k_load:.3g} N*m/arcmin with the effects fitted, "
                        f"{1 - k_load / k_nom:.0%} below seed 004 eq. (8)"}


def series_size_arcmin(stack: Stack, f: LinearFit, effects: Sequence[str], k_nom: float
                       ) -> float:
    """RMS (arcmin) of the series-compliance term of a fit: the flank twist of the fitted
    loaded compliance minus that of the nominal ``1 / K``, each run's mean removed."""
    c = f.coef("compliance") - 1.0 / k_nom
    sq, n = 0.0, 0
    for i in range(stack.n_runs):
        col = cached_columns(stack, i, ("backlash", *effects), f.nl, teeth_of(stack))[:, 1]
        d = col * c
        d = d - d.mean()
        sq += float(d @ d)
        n += d.size
    return math.sqrt(sq / n) if n else 0.0


def curvature_effect(models: dict[str, Candidate], k_nom: float,
                     amplitude_Nm: float | None = None, smooth: bool = False,
                     policy: DecisionPolicy = POLICY) -> tuple[str | None, str]:
    """Name the flank curvature by what physically differs: a bearing clearance being taken
    up adds compliance only below its closing torque and leaves the mesh's nominal slope at
    load (seed 004 eq. 8); Hertzian contact stiffening makes the contact itself stiffer as the
    load grows, so the tangent stiffness at load exceeds the nominal linear (secant) value.
    Read on the best take-up fit (extra twist + linear slope): loaded stiffness within
    the tolerance of the nominal (the larger of STIFFNESS_TOLERANCE and two standard errors
    of the fitted compliance) -> bearing clearance, stiffer -> contact stiffening, softer ->
    undecided. A nominal loaded slope with a take-up still under TAKE_UP_COMPLETE at the
    amplitude and a tangent stiffness there measurably below the nominal is a contact that
    hardens over the whole range (stiffening): a clearance closes inside the loaded range.
    Returns (effect or None, why)."""
    members = [models[n] for n in ("stiffness_nonlinearity", "bearing_clearance")
               if n in models and models[n].heldout_runs > 0]
    if not members:
        members = [models[n] for n in ("stiffness_nonlinearity", "bearing_clearance")
                   if n in models]
    if not members or not math.isfinite(k_nom) or k_nom <= 0:
        return None, ""
    # the member of the take-up family (smooth saturating, or a kinked soft stage) that fits
    # the held-out runs best gives the loaded slope
    c = min(members, key=lambda m: m.heldout_rms_arcmin)
    comp = c.fit.coef("compliance")
    if comp <= 0:
        return "stiffness_nonlinearity", "the flank is rigid at load: the contact stiffens"
    k_load = 1.0 / comp
    rel_se = compliance_rel_se(c.fit)
    tol = max(policy.stiffness_tolerance, policy.stiffness_se_factor * rel_se)
    dev = k_load / k_nom - 1.0
    text = (f"stiffness at load {k_load:.3g} N*m/arcmin once the small-torque take-up is "
            f"fitted, nominal {k_nom:.3g} (seed 004 eq. 8)")
    if dev > tol:
        return "stiffness_nonlinearity", text + ": stiffer at load, the contact hardens"
    if abs(dev) <= tol:
        k_end = tangent_stiffness_at_amplitude(c, amplitude_Nm, smooth)
        done = take_up_completion(c, amplitude_Nm, smooth)
        if (k_end is not None and k_end < k_nom * (1.0 - tol)
                and done < policy.take_up_complete):
            return "stiffness_nonlinearity", text + (
                f", but at the largest torque the take-up is only {done:.0%} complete and the "
                f"tangent stiffness still {k_end:.3g}: the flank goes on hardening up to the "
                "amplitude, as a contact does; a clearance closes inside the loaded range")
        return "bearing_clearance", text + ": the nominal slope is left, a clearance taken up"
    return None, ""


def take_up_completion(c: Candidate, amplitude_Nm: float | None, smooth: bool = False
                       ) -> float:
    """Share of a take-up fit's total extra twist reached at the amplitude (N*m):
    ``1 - exp(-A / T_s)`` for the saturating curve, ``tanh(A / T_b)`` for the smooth soft
    stage, ``min(A / T_b, 1)`` for the kinked one; 1 when unknown."""
    if not (amplitude_Nm is not None and math.isfinite(amplitude_Nm) and amplitude_Nm > 0):
        return 1.0
    if "stiffening_torque_Nm" in c.fit.nl and c.fit.nl["stiffening_torque_Nm"] > 0:
        return float(-math.expm1(-amplitude_Nm / c.fit.nl["stiffening_torque_Nm"]))
    tb = c.fit.nl.get("bearing_stage_torque_Nm", 0.0)
    if tb > 0:
        return math.tanh(amplitude_Nm / tb) if smooth else min(amplitude_Nm / tb, 1.0)
    return 1.0


def tangent_stiffness_at_amplitude(c: Candidate, amplitude_Nm: float | None,
                                   smooth: bool = False) -> float | None:
    """Tangent stiffness (N*m/arcmin) of a take-up fit at the campaign's loading amplitude
    (median over runs): the loaded compliance plus what the take-up still adds there,
    ``d / T_s exp(-A / T_s)`` for the saturating curve, the soft stage's compliance while
    ``A < T_b`` for the kinked one. A clearance is closed long before rated torque (its
    tangent is the mesh's there); a contact that hardens over the whole range is still
    softer than its asymptote at the largest torque the campaign reaches."""
    if not (amplitude_Nm is not None and math.isfinite(amplitude_Nm) and amplitude_Nm > 0):
        return None
    a = float(amplitude_Nm)
    comp = c.fit.coef("compliance")
    if "stiffening_torque_Nm" in c.fit.nl and "soft_twist" in c.fit.names:
        ts = c.fit.nl["stiffening_torque_Nm"]
        comp += c.fit.coef("soft_twist") / ts * math.exp(-a / ts) if ts > 0 else 0.0
    elif "bearing_stage_torque_Nm" in c.fit.nl:
        tb = c.fit.nl["bearing_stage_torque_Nm"]
        if smooth and tb > 0:
            if a / tb < 50.0:
                comp += c.fit.coef("bearing_compliance") / math.cosh(a / tb) ** 2
        elif a < tb:
            comp += c.fit.coef("bearing_compliance")
    return 1.0 / comp if comp > 0 else None



@dataclass
class Trials:
    """What every candidate is fitted and judged against: the campaign's stack and held-out
    folds, the null fit (play and stiffness calibrated) and its held-out gap, the noise and
    the "within the noise" threshold, and the calibration's draws."""

    stack: Stack
    cfolds: list[list[int]]
    rfolds: list[list[int]]
    base: LinearFit
    noise: float
    threshold: float
    base_rms: float
    base_lm: float
    policy: DecisionPolicy
    replicates: int
    seed: int
    base_c: Candidate | None = None
    base_rep: tuple[float, float, int] | None = None

    def __post_init__(self) -> None:
        self.base_c = self.evaluate(())
        if self.rfolds:
            h, lm, nh, _ = _heldout(self.stack, (), self.rfolds, self.base)
            self.base_rep = (h, lm, nh)

    def evaluate(self, effects: tuple[str, ...], start: LinearFit | None = None,
                 by_repeat: bool = False) -> Candidate:
        """A candidate (or combination) fitted on all runs and cross-validated: leaving out
        whole conditions, or repeats for the per-tooth model (or when ``by_repeat``)."""
        stack = self.stack
        full = start if start is not None else _full_fit(stack, effects)
        folds, scheme = self.cfolds, "leave-one-condition-out"
        if "tooth_spacing_error" in effects or by_repeat:
            folds, scheme = self.rfolds, "leave-one-repeat-out"
        resid: dict[str, np.ndarray] = {}
        if folds:
            h, lm, nh, resid = _heldout(stack, effects, folds, full)
        else:
            (h, lm), nh, scheme = _insample(stack, full), 0, "in-sample (no held-out design)"
        cand = Candidate(effects, full, h, lm, nh, scheme,
                         delta_bic=_bic(full) - _bic(self.base), heldout_resid=resid)
        cand.params, cand.plausible, cand.notes = describe_params(stack, effects, full,
                                                                  self.policy)
        return cand

    def before(self, c: Candidate) -> tuple[float, float]:
        """The null's gap (RMS, lost-motion error) on the same held-out runs as ``c``'s."""
        if c.scheme == "leave-one-repeat-out" and self.base_rep is not None:
            return self.base_rep[0], self.base_rep[1]
        if c.heldout_runs == 0:
            return self.base_rms, self.base_lm
        assert self.base_c is not None
        return self.base_c.heldout_rms_arcmin, self.base_c.heldout_lm_error_arcmin

    def shrink(self, c: Candidate) -> float:
        b = self.before(c)[0]
        return 1.0 - c.heldout_rms_arcmin / b if b > 0 else 0.0

    def evidence_of(self, current: Candidate, name: str) -> float:
        """Calibrated false-alarm probability of adding ``name`` to ``current``."""
        add, _ = calibrated_evidence(self.stack, current.fit, current.effects, [name],
                                     self.replicates, self.seed)
        return add[name].false_alarm_probability if name in add else 1.0


def screen(trials: Trials, why_not: dict[str, str]) -> dict[str, Candidate]:
    """Fast screening: in-sample fits of every testable candidate; held-out fits of the best
    ``screen_keep`` by BIC that gain at least ``screen_delta_bic`` on the null."""
    stack, policy = trials.stack, trials.policy
    models: dict[str, Candidate] = {}
    screened: dict[str, LinearFit] = {}
    for name in CANDIDATES:
        if not why_not.get(name):
            screened[name] = _full_fit(stack, (name,))
    base_bic = _bic(trials.base)
    order = sorted(screened, key=lambda n: _bic(screened[n]))
    for rank, name in enumerate(order):
        dbic = _bic(screened[name]) - base_bic
        if rank < policy.screen_keep and dbic < policy.screen_delta_bic:
            models[name] = trials.evaluate((name,), screened[name])
        else:
            f = screened[name]
            h, lm = _insample(stack, f)
            cand = Candidate((name,), f, h, lm, 0, "screened out (in-sample fit only)",
                             delta_bic=dbic, screened_out=True)
            cand.params, cand.plausible, cand.notes = describe_params(stack, (name,), f, policy)
            models[name] = cand
    return models
