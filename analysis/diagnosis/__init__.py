"""Sim-to-real gap diagnosis: where model and measurement disagree, which unmodelled effect
causes it, and how far the gap shrinks once it is added, measured on held-out runs.

Reads only the runs (:class:`analysis.diagnosis.data.RunInput`: unit data, test conditions,
samples); never generator labels or true parameters. Steps:

1. Predictive gap: the reference nominal model as designed (run-format.md), run offsets free.
   Structural gap: the same with its own global parameters (play, stiffness) calibrated.
2. Where: gap map of the calibrated model's standardised residuals; each run's free play and
   its Fourier series over the eccentric-shaft angle; lack of fit against repeats.
3. Which: every candidate of :data:`analysis.effects.CANDIDATES` the design can test is
   fitted (profiled nonlinear parameter, robust bounded linear LS, analysis.diagnosis.fit) and
   cross-validated leaving out whole conditions (positions/temperatures/amplitudes), or repeats
   for the per-tooth spacing model; greedy additions while each closes a significant part of
   what is left. Verdict ``none`` when the held-out structural gap is within the noise,
   ``ambiguous`` when candidates tie or the design cannot separate them, ``unexplained`` when a
   systematic gap remains that no candidate closes.
4. How far: RMS twist residual and lost-motion error before/after on held-out runs.

The modules, in the order :func:`diagnose` uses them: ``data`` and ``null_model`` (the runs
and the measuring system), ``design`` (conditions, folds, what can be tested),
``candidates`` (fits, held-out gaps, parameters), ``evidence``/``calibration`` (false-alarm
probabilities), ``decide`` (the evidence gathered, then the verdict by the first of an ordered
list of named rules: the only place a verdict is set) and ``report`` (built once from the
decision). Every threshold is a field of ``policy.DecisionPolicy``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from analysis.diagnosis.calibration import REPLICATES
from analysis.diagnosis.candidates import (
    ARCSEC,
    Candidate,
    Trials,
    _ci,
    _insample,
    compliance_rel_se,
    describe_params,
    heldout_separation,
    kind_runout_swing_arcmin,
    quantisation_floor_arcmin,
    quantisation_share,
    screen,
    separated,
    series_compliance,
    series_size_arcmin,
    stiffness_gap_tolerance,
    take_up_completion,
    tangent_stiffness_at_amplitude,
)
from analysis.diagnosis.candidates import curvature_effect as curvature_effect
from analysis.diagnosis.data import TARGET_POINTS, PreparedRun, RunInput, prepare_run
from analysis.diagnosis.decide import (
    NEXT_EXPERIMENT,
    RULES,
    Decision,
    Evidence,
    Rule,
    gather,
    play_tiebreak,
)
from analysis.diagnosis.decide import decide as decide_verdict
from analysis.diagnosis.design import (
    choose_family_members,
    conditions_of,
    folds_by_condition,
    folds_by_repeat,
    temperature_levels,
    testable,
)
from analysis.diagnosis.evidence import calibrated_evidence
from analysis.diagnosis.fit import fit, with_kind_play_reference
from analysis.diagnosis.flanks import flank_asymmetry
from analysis.diagnosis.null_model import (
    lag_if_it_helps,
    nuisance_friction,
    with_measurement_nuisance,
)
from analysis.diagnosis.policy import POLICY, DecisionPolicy
from analysis.diagnosis.report import Design, Diagnosis, Gaps, _clean, build_report
from analysis.diagnosis.report_measurement import measurement_report
from analysis.effects import CANDIDATES
from analysis.errors import AnalysisError

__all__ = [
    "ARCSEC", "NEXT_EXPERIMENT", "POLICY", "RULES", "Candidate", "Decision", "DecisionPolicy",
    "Diagnosis", "Evidence", "Rule", "RunInput", "choose_family_members", "conditions_of",
    "curvature_effect", "describe_params", "diagnose", "folds_by_condition",
    "folds_by_repeat", "heldout_separation", "kind_runout_swing_arcmin", "lag_if_it_helps",
    "nuisance_friction", "play_tiebreak", "quantisation_floor_arcmin", "separated",
    "series_compliance", "series_size_arcmin", "take_up_completion",
    "tangent_stiffness_at_amplitude", "temperature_levels", "testable",
    "with_measurement_nuisance",
]

# The thresholds live in DecisionPolicy (analysis.diagnosis.policy); these names stay
# importable for callers of the earlier module constants (the same values, read-only copies).
ALPHA = POLICY.alpha
MATERIAL_SHRINK = POLICY.material_shrink
FRICTION_ALLOWANCE = POLICY.friction_allowance
ZERO_ALLOWANCE = POLICY.zero_allowance
SERIES_SHARE = POLICY.series_share
NONE_SIGMAS = POLICY.none_sigmas
EXPLAINED_SHARE = POLICY.explained_share
GREEDY_GAIN = POLICY.greedy_gain
TIE_FACTOR = POLICY.tie_factor
SEPARATION_RATIO = POLICY.separation_ratio
SEPARATION_WINS = POLICY.separation_wins
SEPARATION_BIC = POLICY.separation_bic
SEPARATION_RATIO_CONSISTENT = POLICY.separation_ratio_consistent
SEPARATION_P = POLICY.separation_p
PLAY_PRESENT = POLICY.play_present
PLAY_ABSENT = POLICY.play_absent
STIFFNESS_TOLERANCE = POLICY.stiffness_tolerance
MAX_FOLDS = POLICY.max_folds
MAX_ALSO = POLICY.max_also
ALSO_TRIALS = POLICY.also_trials
SCREEN_KEEP = POLICY.screen_keep
SCREEN_DELTA_BIC = POLICY.screen_delta_bic
TEMPERATURE_SPAN_K = POLICY.temperature_span_K
TEMPERATURE_GAP_K = POLICY.temperature_gap_K
ORDER2_POSITIONS = POLICY.order2_positions
TAKE_UP_COMPLETE = POLICY.take_up_complete


def diagnose(runs: Sequence[RunInput], *, target_points: int | None = None,
             alpha: float | None = None, replicates: int = REPLICATES, seed: int = 0,
             policy: DecisionPolicy | None = None) -> Diagnosis:
    """Diagnose a campaign (see the module docstring); raises AnalysisError on bad input.
    ``alpha``: the level at which an effect is called (each candidate's false-alarm
    probability, :mod:`analysis.diagnosis.calibration`); ``replicates``, ``seed``: of the
    block bootstrap that calibrates it; ``policy``: the thresholds of every decision
    (:class:`analysis.diagnosis.policy.DecisionPolicy`, :data:`POLICY` when not given;
    ``alpha``, when given, replaces its level). The report records the policy used under
    ``decision_policy``. The procedure, in order:"""
    if not runs:
        raise AnalysisError("a diagnosis needs at least one run")
    policy = _policy_of(alpha, policy)
    tp = TARGET_POINTS if target_points is None else target_points
    # 1. the runs reduced, the measuring system's nuisance in the null model, the design
    stack, prepared, zero_report, design = _prepare(runs, tp, policy)
    # 2. the predictive and structural gaps; what every candidate is judged against
    trials, gaps = _gaps(stack, prepared, design, policy, replicates, seed)
    # 3. every testable candidate screened, the best held out
    models = screen(trials, design.why_not)
    # 4. calibrated evidence: each testable candidate and the null's lack of fit, by a block
    #    bootstrap of the null's residuals (analysis.diagnosis.calibration)
    testable_names = [n for n in CANDIDATES if not design.why_not.get(n)]
    cal, omni = calibrated_evidence(trials.stack, trials.base, (), testable_names, replicates,
                                    seed, omnibus=True)
    flanks = flank_asymmetry(trials.stack, trials.base)
    # 5. the evidence gathered, then the verdict by the first rule that applies
    nom = prepared[0].nominal
    assert nom is not None
    ev = gather(trials, models, cal, omni, flanks, gaps.h0, gaps.k_nom, gaps.k_fit,
                gaps.param_error.get("share_of_predictive_gap", 0.0), nom.play_arcmin,
                prepared, zero_report)
    decision = decide_verdict(ev)
    # 6. the report, built once from the decision
    measurement = _measurement(runs, prepared, trials, zero_report, tp)
    report = build_report(trials, ev, decision, gaps, design, measurement)
    return Diagnosis(report=report, stack=trials.stack, base=trials.base, models=models)


def _policy_of(alpha: float | None, policy: DecisionPolicy | None) -> DecisionPolicy:
    """The policy a diagnosis uses: the given one (or :data:`POLICY`), with ``alpha`` as its
    level when given."""
    policy = POLICY if policy is None else policy
    if alpha is not None and alpha != policy.alpha:
        if not 0.0 < alpha < 1.0:
            raise AnalysisError(f"alpha must be between 0 and 1, got {alpha!r}")
        policy = replace(policy, alpha=float(alpha))
    if not 0.0 < policy.alpha < 1.0:
        raise AnalysisError(f"alpha must be between 0 and 1, got {policy.alpha!r}")
    return policy


def _prepare(runs: Sequence[RunInput], tp: int, policy: DecisionPolicy
             ) -> tuple[Any, list[PreparedRun], dict[str, Any], Design]:
    """The runs reduced (analysis.diagnosis.data), their torque lag taken out where it helps,
    the measuring system's nuisance carried by the null model, the unit kind's nominal
    shape, and the campaign's design: conditions, held-out folds, what it can test and the
    members of the effect families it supports."""
    prepared: list[PreparedRun] = [prepare_run(r, tp) for r in runs]
    if any(r.nominal is None for r in prepared):
        raise AnalysisError("the reference nominal model needs each run's unit data "
                            "(run.json 'unit'); a run has none usable")
    prepared = lag_if_it_helps(runs, prepared, tp, policy)
    stack, zero_report = with_measurement_nuisance(prepared, policy.alpha, policy)
    stack = with_kind_play_reference(stack)  # the unit kind's nominal shape (kind_physics)
    prepared = list(stack.runs)
    cond, varied = conditions_of(stack, policy)
    cfolds = folds_by_condition(stack, cond, policy)
    rfolds = folds_by_repeat(stack, cond, varied, policy)
    why_not = testable(stack, cond, varied, policy)
    stack = choose_family_members(stack, cond, varied, why_not, cfolds, policy)
    return stack, prepared, zero_report, Design(cond, varied, cfolds, rfolds, why_not)


def _gaps(stack: Any, prepared: list[PreparedRun], design: Design, policy: DecisionPolicy,
          replicates: int, seed: int) -> tuple[Trials, Gaps]:
    """The noise and the "within the noise" threshold, the predictive gap (nominal model as
    designed, run offsets free) and the structural one (play and stiffness calibrated), and
    the parameter error between them."""
    noise = math.sqrt(float(np.mean(np.concatenate(
        [np.full(r.twist_arcmin.size, r.sigma_arcmin**2) for r in prepared]))))
    # the threshold follows from the measured noise (which holds the channels' resolution,
    # analysis.diagnosis.data.resolution_of) and the campaign design: the systematic part of
    # a held-out RMS over N points is known to about noise * (2 / N)^(1/4)
    n_points = sum(r.twist_arcmin.size for r in prepared)
    threshold = max(policy.none_sigmas, (2.0 / max(n_points, 1)) ** 0.25) * noise
    nom = prepared[0].nominal
    assert nom is not None
    k_nom = nom.stiffness_Nm_per_arcmin
    fixed = {"play": nom.play_arcmin, "compliance": 1.0 / k_nom if math.isfinite(k_nom) else 0.0}
    predictive = fit(stack, ("backlash",), fixed=fixed)
    base = fit(stack, ("backlash",), want_cov=True)
    pred_rms, pred_lm = _insample(stack, predictive)
    base_rms, base_lm = _insample(stack, base)
    trials = Trials(stack, design.cfolds, design.rfolds, base, noise, threshold, base_rms,
                    base_lm, policy, replicates, seed)
    base_c = trials.base_c
    assert base_c is not None
    h0 = base_c.heldout_rms_arcmin if base_c.heldout_runs else base_rms
    # parameter error of the nominal model (predictive minus structural)
    k_fit = 1.0 / base.coef("compliance") if base.coef("compliance") > 0 else math.inf
    scale = math.sqrt(max(2.0 * base.objective / max(base.n - 2, 1), 1.0))
    param_error: dict[str, Any] = {
        "play_arcmin": {"nominal": nom.play_arcmin, "calibrated": base.coef("play"),
                        "ci95": _ci(base, "play", scale)},
        "stiffness_Nm_per_arcmin": {"nominal": k_nom if math.isfinite(k_nom) else None,
                                    "calibrated": k_fit if math.isfinite(k_fit) else None},
    }
    if math.isfinite(k_nom) and k_nom > 0 and math.isfinite(k_fit):
        # the departure is a finding in itself (issue 31 item 2): its ratio and standard error
        rel_se = compliance_rel_se(base)
        quant = quantisation_share(prepared, k_nom)
        param_error["stiffness_Nm_per_arcmin"].update(
            ratio=k_fit / k_nom, relative_se=rel_se, quantisation_share=quant,
            gap_tolerance=stiffness_gap_tolerance(policy, rel_se, quant))
    if pred_rms > 0:
        param_error["share_of_predictive_gap"] = max(0.0, 1.0 - (base_rms / pred_rms) ** 2)
    return trials, Gaps(pred_rms, pred_lm, base_rms, base_lm, h0, k_nom, k_fit, param_error)


def _measurement(runs: Sequence[RunInput], prepared: list[PreparedRun], trials: Trials,
                 zero_report: dict[str, Any], tp: int) -> dict[str, Any]:
    """The measuring system's part of the report, and the unit kind's effect physics with
    the effects that have no meaning of their own in its geometry (never fitted)."""
    stack = trials.stack
    out: dict[str, Any] = {"measurement": _clean(measurement_report(
        runs, prepared, stack, trials.base, zero_report, tp, trials.policy.alpha))}
    if stack.physics is not None:
        out["kind_physics"] = _clean(stack.physics.to_dict())
        out["not_testable"] = dict(stack.physics.not_testable)
    return out
