"""The ``rig-diagnosis/1`` report of a decision (docs/run-format.md).

Built once from the :class:`analysis.diagnosis.decide.Decision` and the evidence behind it;
nothing here sets or changes the verdict.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from analysis.diagnosis.calibration import floored, resolution
from analysis.diagnosis.candidates import ARCSEC, Candidate, Trials, _sys
from analysis.diagnosis.decide import TAKE_UP_PAIR, Decision, Evidence, play_slope_share
from analysis.diagnosis.fit import LinearFit, Stack
from analysis.diagnosis.where import gap_map, lack_of_fit, per_run_play, play_fourier


@dataclass
class Diagnosis:
    """Result of :func:`diagnose`; :meth:`to_dict` is the ``rig-diagnosis/1`` report."""

    report: dict[str, Any]
    stack: Stack
    base: LinearFit
    models: dict[str, Candidate]

    def to_dict(self) -> dict[str, Any]:
        return self.report


@dataclass
class Gaps:
    """The predictive gap (nominal model as designed) and the structural one (play and
    stiffness calibrated), in sample, with the parameter error between them."""

    pred_rms: float
    pred_lm: float
    base_rms: float
    base_lm: float
    h0: float  # held-out structural gap
    k_nom: float
    k_fit: float
    param_error: dict[str, Any]


@dataclass
class Design:
    """What the campaign varies and how it is held out (analysis.diagnosis.design)."""

    cond: dict[str, tuple]
    varied: list[str]
    cfolds: list[list[int]]
    rfolds: list[list[int]]
    why_not: dict[str, str]


def ranking_of(trials: Trials, ev: Evidence, decision: Decision) -> list[dict[str, Any]]:
    """Every candidate, held-out ones first by their held-out gap, with its evidence; the
    series compliance first when it is the verdict's larger term, last when it is named
    from the calibrated stiffness alone."""
    noise, cal, fap = trials.noise, ev.cal, ev.fap
    ranking = []
    for c in sorted(ev.models.values(),
                    key=lambda c: (c.screened_out, c.heldout_runs == 0, c.heldout_rms_arcmin)):
        b_rms, b_lm = trials.before(c)
        ranking.append({
            "effect": c.effects[0], "shrink": round(trials.shrink(c), 4),
            "gap_after": {"rms_arcsec": c.heldout_rms_arcmin * ARCSEC,
                          "lost_motion_error_arcsec": _nn(c.heldout_lm_error_arcmin * ARCSEC)},
            "gap_before": {"rms_arcsec": b_rms * ARCSEC,
                           "lost_motion_error_arcsec": _nn(b_lm * ARCSEC)},
            "explained_share": round(1.0 - (_sys(c.heldout_rms_arcmin, noise)
                                            / max(_sys(b_rms, noise), 1e-12)) ** 2, 4)
            if _sys(b_rms, noise) > 0 else 0.0,
            "params": _clean(c.params), "plausible": c.plausible, "notes": c.notes,
            "false_alarm_probability": floored(_nn(fap.get(c.effects[0], math.nan)),
                                               trials.replicates),
            "evidence": {"delta_bic": round(c.delta_bic, 1), "heldout_runs": c.heldout_runs,
                         "cv": c.scheme,
                         **({"calibrated": _clean(cal[c.effects[0]].to_dict(
                             trials.replicates))} if c.effects[0] in cal else {})},
        })
    k_nom, k_fit = ev.k_nom, ev.k_fit
    if "shaft_compliance" in decision.candidates and math.isfinite(k_nom) and k_fit < k_nom:
        ks = 1.0 / (1.0 / k_fit - 1.0 / k_nom)
        ranking.append({"effect": "shaft_compliance", "shrink": None,
                        "params": {"stiffness_Nm_per_arcmin": ks},
                        "evidence": {"from": "calibrated stiffness against seed 004 eq. (8)"}})
    if decision.rule == "series_compliance_larger_term":
        series = ev.series
        assert series is not None
        ranking.insert(0, {"effect": "shaft_compliance", "shrink": series["shrink"],
                           "params": series["params"], "plausible": True, "notes": [],
                           "evidence": {"from": series["evidence"], "in_sample": True}})
    return ranking


def also_of(trials: Trials, ev: Evidence, decision: Decision, main: Candidate
            ) -> list[dict[str, Any]]:
    """The effects beside the verdict's, in the order they were added, each shrink against
    the gap the ones before it left; the series compliance first (with the attributed
    effect) when it is the larger term, last when it is left beside the effects."""
    assert ev.attribution is not None
    attributed = ev.effect if ev.effect is not None else ev.attribution.verdict
    also: list[dict[str, Any]] = []
    prev = main
    for c in decision.chosen[1:]:
        listed = [e for e in c.effects if e != attributed and e not in
                  {a["effect"] for a in also}]
        if ev.curvature is not None:
            listed = [ev.curvature if e in TAKE_UP_PAIR else e for e in listed]
            listed = [e for e in listed if e != attributed]
        for e in listed[-1:] if listed else []:
            also.append({"effect": e,
                         "shrink": 1.0 - c.heldout_rms_arcmin / prev.heldout_rms_arcmin,
                         "params": _clean(c.params)})
            if e in ev.sizes:
                also[-1]["size_arcsec"] = ev.sizes[e] * ARCSEC
        prev = c
    if ev.series is not None and "size_arcsec" in ev.series:
        if decision.rule == "series_compliance_larger_term":
            also.insert(0, {"effect": attributed, "shrink": trials.shrink(main),
                            "params": _clean(main.params),
                            "size_arcsec": ev.size_main * ARCSEC})
        else:
            also.append(ev.series)
    return also


def build_report(trials: Trials, ev: Evidence, decision: Decision, gaps: Gaps, design: Design,
                 measurement: dict[str, Any]) -> dict[str, Any]:
    """The ``rig-diagnosis/1`` report of a decision (docs/run-format.md); the verdict is the
    decision's, never changed here."""
    stack, noise, base_c = trials.stack, trials.noise, trials.base_c
    assert base_c is not None
    verdict, chosen = decision.verdict, decision.chosen
    main = chosen[0] if chosen else None
    gb = trials.before(main) if main else (gaps.h0, base_c.heldout_lm_error_arcmin)
    series_alone = verdict == "shaft_compliance" and main is None
    if series_alone and gaps.pred_rms > 0:
        # how far the gap shrinks once the series compliance is added: the predictive gap
        # (nominal stiffness) against the structural one (the calibrated stiffness)
        gb = (gaps.pred_rms, gaps.pred_lm)
    report: dict[str, Any] = {
        "format": "rig-diagnosis/1",
        "model_effects": ["backlash", "mesh_stiffness"],
        "gap_before": {"rms_arcsec": gb[0] * ARCSEC,
                       "lost_motion_error_arcsec": _nn(gb[1] * ARCSEC)},
        "ranking": ranking_of(trials, ev, decision),
        "verdict": verdict,
        "reason": decision.reason,
        "noise_arcsec": noise * ARCSEC,
        "predictive_gap": {"rms_arcsec": gaps.pred_rms * ARCSEC,
                           "lost_motion_error_arcsec": _nn(gaps.pred_lm * ARCSEC),
                           "in_sample": True},
        "structural_gap": {"rms_arcsec": gaps.base_rms * ARCSEC,
                           "lost_motion_error_arcsec": _nn(gaps.base_lm * ARCSEC),
                           "in_sample": True, "heldout_rms_arcsec": gaps.h0 * ARCSEC},
        "parameter_error": _clean(gaps.param_error),
        "play_slope": None if ev.play is None else {
            **ev.play.to_dict(), "share_of_mesh_stiffness": play_slope_share(ev)},
        "design": {"runs": stack.n_runs, "varied": design.varied,
                   "conditions": len(set(design.cond.values())),
                   "folds_condition": len(design.cfolds), "folds_repeat": len(design.rfolds),
                   "untestable": {k: v for k, v in design.why_not.items() if v}},
    }
    if main is not None:
        report["gap_after"] = {"rms_arcsec": main.heldout_rms_arcmin * ARCSEC,
                               "lost_motion_error_arcsec": _nn(main.heldout_lm_error_arcmin
                                                               * ARCSEC)}
        report["shrink"] = trials.shrink(main)
        if decision.rule == "series_compliance_larger_term":
            assert ev.series is not None
            report["shrink"] = ev.series["shrink"]
        gap_sys = _sys(gb[0], noise)
        report["explained_share"] = (1.0 - (_sys(main.heldout_rms_arcmin, noise) / gap_sys)
                                     ** 2 if gap_sys > 0 else 0.0)
        also = also_of(trials, ev, decision, main)
        if also:
            report["also"] = also
    if verdict == "ambiguous" or series_alone:
        report["candidates"] = decision.candidates
        report["next_experiment"] = decision.next_experiment
    if series_alone and gaps.pred_rms > 0:
        report["shrink"] = max(0.0, 1.0 - gaps.base_rms / gaps.pred_rms)
        report["gap_after"] = {"rms_arcsec": gaps.base_rms * ARCSEC,
                               "lost_motion_error_arcsec": _nn(gaps.base_lm * ARCSEC)}
    if verdict == "unexplained":
        report["candidates"] = decision.candidates
        if decision.next_experiment:  # a rule that knows what the gap is likely to be
            report["next_experiment"] = decision.next_experiment
    report.update(_where(trials, ev, design))
    report.update(measurement)
    return report


def _where(trials: Trials, ev: Evidence, design: Design) -> dict[str, Any]:
    """Where the gap is (analysis.diagnosis.where), the flanks' slopes and how the decisions
    were calibrated, with the policy they were decided by."""
    stack, base = trials.stack, trials.base
    gm = gap_map(stack, base)
    plays = per_run_play(stack, base)
    fourier = play_fourier(plays)
    replicates = trials.replicates
    return {
        "gap_map": gm,
        "free_play_by_run": plays,
        "free_play_fourier": fourier,
        "lack_of_fit": lack_of_fit(plays, {r.run_id: design.cond[r.run_id]
                                           for r in stack.runs}),
        "localization": _localize(gm, fourier, design.varied),
        "flank_asymmetry": _clean(ev.flanks.to_dict()) if ev.flanks is not None else None,
        "calibration": {
            "alpha": trials.policy.alpha, "replicates": replicates, "seed": trials.seed,
            "method": "moving-block bootstrap of the null model's residuals, run by run; "
                      "scaled chi-square tail; any-candidate correction by the effective "
                      "number of tests (analysis.diagnosis.calibration)",
            "lack_of_fit": _clean(ev.omni.to_dict(replicates)) if ev.omni is not None
            else None,
            "draws": replicates,
            "false_alarm_resolution": resolution(replicates),
            "false_alarm_floor": "every false_alarm_probability reported is at least "
                                 "1 / (draws + 1): below it the scaled chi-square tail is "
                                 "extrapolated beyond what the bootstrap draws observed",
        },
        "decision_policy": trials.policy.to_dict(),
    }


def _localize(gm: dict[str, dict[str, Any]], fourier: dict[str, Any] | None,
              varied: list[str]) -> dict[str, str]:
    name, info = max(gm.items(), key=lambda kv: kv[1]["share"])
    detail = f"{info['share']:.0%} of the squared standardised residual is between {name} bins"
    if name == "position" and fourier is not None:
        k = fourier["dominant_order"]
        amp = fourier["amplitude_arcmin"][k - 1] * ARCSEC
        detail = (f"lost motion varies with input_angle_deg, {k} cycle(s) per revolution "
                  f"dominant ({amp:.1f} arcsec amplitude of the free play)")
    elif name == "temperature":
        detail = "free play varies with temperature_C"
    elif name == "branch":
        detail = "loading and unloading branches separate (a hysteresis the model lacks)"
    elif name == "torque_band":
        worst = max(info["bins"], key=lambda b: b["rms_z"])
        detail = f"residual concentrated at |T| in {worst['bin']} of rated torque"
    elif name == "time_since_reversal":
        detail = "residual depends on the time since the last torque reversal (dwell)"
    return {"where": name, "detail": detail}


def _nn(x: float) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def _clean(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    if isinstance(obj, float | np.floating):
        return _nn(float(obj))
    return obj

