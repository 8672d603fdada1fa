"""The decision: which verdict the evidence gives, by an ordered list of named rules.

Read top to bottom, this is the procedure (docs/diagnosis.md, "The decision, top to bottom"):

1. :func:`gather` collects everything a verdict rests on (:class:`Evidence`): each
   candidate's calibrated false-alarm probability, whether there is a gap to attribute at
   all, the flanks' slopes, the stiffness against seed 004 eq. (8) and, when there is a gap,
   the attribution among the candidates (:func:`attribute`: one effect, a tie, greedy
   additions, or none that closes it) with the series compliance beside it.
2. :func:`decide` walks :data:`RULES` in order; the first rule whose condition holds gives
   the verdict. That is the only place a verdict is set; the report is built from the
   :class:`Decision` and never changes it afterwards.

Every threshold is a field of :class:`analysis.diagnosis.policy.DecisionPolicy`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from analysis.diagnosis.calibration import Calibrated
from analysis.diagnosis.candidates import (
    ARCSEC,
    Candidate,
    Trials,
    _bic,
    _full_fit,
    _sys,
    compliance_rel_se,
    curvature_effect,
    quantisation_floor_arcmin,
    quantisation_share,
    separated,
    series_compliance,
    series_size_arcmin,
    stiffness_gap_tolerance,
)
from analysis.diagnosis.fit import effect_size_arcmin, fit
from analysis.diagnosis.flanks import FlankAsymmetry
from analysis.diagnosis.play_slope import PlayTilt, play_slope_of
from analysis.diagnosis.policy import POLICY, DecisionPolicy
from analysis.effects import CANDIDATES

TAKE_UP_PAIR = ("bearing_clearance", "stiffness_nonlinearity")
"""One flank-curvature family: a clearance taken up and a contact that stiffens."""

NEXT_EXPERIMENT = {
    frozenset({"shaft_compliance", "mesh_stiffness"}):
        "measure the twist across the mesh alone (a second encoder at the gear, or lock the "
        "shafts): from one loop a series compliance and a softer mesh are the same slope",
    frozenset({"runout", "tooth_spacing_error"}):
        "repeat runs at the same positions and add positions a few teeth apart (every "
        "360/z_internal deg): spacing errors repeat per tooth, runout is smooth over the turn",
    frozenset({"runout", "thermal_expansion"}):
        "vary position at constant temperature and temperature at one position (a crossed "
        "design)",
    frozenset({"stiffness_nonlinearity", "bearing_clearance"}):
        "a slow dense ramp through 0-20 % of rated torque: a bearing stage shows a kink at T_b, "
        "contact stiffening a smooth curve",
    frozenset({"friction", "torque_sensor_offset"}):
        "re-zero the torque channel with the unit disengaged, then a loop with dwells at zero",
    frozenset({"backlash", "bearing_clearance"}):
        "measure the bearing clearances and the M values again; a loop at several positions "
        "and temperatures",
}


# ------------------------------------------------------------------------------ attribution


@dataclass
class Attribution:
    """What the candidates say about a gap there is to attribute (:func:`attribute`).
    ``outcome``: ``"one"`` (one effect explains it), ``"play"`` (a clearance/stiffening tie
    settled by the free play), ``"greedy"`` (effects added greedily explain it), ``"tie"``
    (several explain it equally), ``"in_sample"`` (the best fit cannot be held out) or
    ``"none_closes"``. ``effect``: the effect named (the first of ``chosen``); ``names``: the
    candidates an ambiguous or unexplained verdict lists."""

    outcome: str
    effect: str | None
    names: list[str]
    chosen: list[Candidate]
    reason: str
    next_experiment: str | None = None

    @property
    def verdict(self) -> str:
        """The verdict the attribution alone gives (before the series compliance is
        weighed): the effect, ``ambiguous`` or ``unexplained``."""
        if self.effect is not None:
            return self.effect
        return "unexplained" if self.outcome == "none_closes" else "ambiguous"


def _additions(trials: Trials, models: dict[str, Candidate], chosen: list[Candidate],
               fap_alpha: float) -> list[Candidate]:
    """Second (and third) effects: each addition is fitted jointly and kept only when it
    earns its place on the held-out runs (:func:`separated` against the model without it: a
    lower BIC by separation_bic and a consistently smaller held-out residual), removes
    greedy_gain of the systematic held-out gap still left, and has calibrated evidence of its
    own at level alpha."""
    stack, policy, noise = trials.stack, trials.policy, trials.noise
    pair = set(TAKE_UP_PAIR)
    chosen = list(chosen)
    current = chosen[-1]
    for _ in range(policy.max_also):
        have = set(current.effects)
        if have & pair:
            have |= pair  # one flank-curvature family at a time
        # screen: each remaining candidate fitted jointly with what is there, in-sample
        joint = []
        for name in models:
            if name in have:
                continue
            jf = _full_fit(stack, (*current.effects, name))
            gain = _bic(jf) - _bic(current.fit)
            if gain < policy.screen_delta_bic:
                joint.append((gain, name, jf))
        joint.sort(key=lambda g: g[0])
        tried = [trials.evaluate((*current.effects, name), jf)
                 for _, name, jf in joint[:policy.also_trials]]
        left = _sys(current.heldout_rms_arcmin, noise)
        earned = [t for t in tried if t.plausible and t.heldout_runs > 0
                  and _sys(t.heldout_rms_arcmin, noise) ** 2
                  <= (1.0 - policy.greedy_gain) * left ** 2
                  and separated(stack, t, current, policy)
                  and trials.evidence_of(current, t.effects[-1]) <= fap_alpha]
        if not earned:
            break
        current = min(earned, key=lambda t: t.heldout_rms_arcmin)
        chosen.append(current)
    return chosen


def _pool(trials: Trials, models: dict[str, Candidate], fap: dict[str, float],
          k_nom: float) -> list[Candidate]:
    """The candidates that may be attributed: plausible, held out, with calibrated evidence
    at level alpha; of the flank-curvature family only the member its loaded slope names
    (:func:`curvature_effect`), carrying the family's best held-out shape."""
    stack, policy = trials.stack, trials.policy
    pool = [c for c in models.values()
            if c.plausible and c.heldout_runs > 0 and not c.screened_out
            and fap.get(c.effects[0], 0.0) <= policy.alpha]
    curv, curv_why = curvature_effect(models, k_nom, float(np.median(
        [r.amplitude_Nm for r in stack.runs])), stack.bearing_smooth, policy)
    pair = set(TAKE_UP_PAIR)
    in_pool = [c for c in pool if c.effects[0] in pair]
    if curv is not None and in_pool and models.get(curv) in pool:
        pool = [c for c in pool if c.effects[0] not in pair or c.effects[0] == curv]
        rep = min(in_pool, key=lambda c: c.heldout_rms_arcmin)
        if rep.effects[0] != curv:
            named = models[curv]
            named.heldout_rms_arcmin = min(named.heldout_rms_arcmin, rep.heldout_rms_arcmin)
            named.notes.append(curv_why)
        else:
            rep.notes.append(curv_why)
    pool.sort(key=lambda c: c.heldout_rms_arcmin)
    return pool


def _explained(trials: Trials, models: dict[str, Candidate], explaining: list[Candidate],
               nominal_play: float) -> Attribution:
    """One candidate explains the gap: it, unless another ties with it (then the free play
    settles a clearance/stiffening tie, or the design cannot separate them)."""
    stack, policy, noise = trials.stack, trials.policy, trials.noise
    best = explaining[0]
    smooth = models.get("runout")
    if best.effects[0] == "tooth_spacing_error" and smooth is not None and smooth in explaining:
        # per-tooth plays hold any position pattern; the smooth eq. (4) runout, with 4
        # parameters, is preferred unless the per-tooth model beats it on the same held-out
        # repeats
        smooth_rep = trials.evaluate(("runout",), smooth.fit, by_repeat=True)
        if not separated(stack, best, smooth_rep, policy):
            explaining = [smooth] + [c for c in explaining if c is not smooth and c is not best]
            best = smooth
    best_sys = _sys(best.heldout_rms_arcmin, noise)
    ties = [c for c in explaining[1:]
            if _sys(c.heldout_rms_arcmin, noise) <= max(trials.threshold,
                                                        policy.tie_factor * best_sys)
            and c.scheme == best.scheme and not separated(stack, best, c, policy)]
    if ties:
        names = [best.effects[0]] + [c.effects[0] for c in ties]
        winner, why = play_tiebreak(names, models, nominal_play, policy)
        if winner is not None:
            return Attribution("play", winner, [],
                               _additions(trials, models, [models[winner]], policy.alpha),
                               "held-out fits tie; decided by the free play: " + why)
        return Attribution("tie", None, names, [best],
                           "several effects explain the gap equally well under this design",
                           _next(names))
    return Attribution("one", best.effects[0], [],
                       _additions(trials, models, [best], policy.alpha),
                       "one effect explains the held-out gap")


def attribute(trials: Trials, models: dict[str, Candidate], fap: dict[str, float],
              sys0: float, nominal_play: float, k_nom: float = math.nan) -> Attribution:
    """Attribute a gap among the candidates: one that leaves at most explained_share of the
    systematic gap (:func:`_explained`), else effects added greedily while each removes
    greedy_gain of what is left; else the best in-sample fit the design cannot hold out
    (a tie), else none closes it."""
    policy, noise, threshold = trials.policy, trials.noise, trials.threshold
    pool = _pool(trials, models, fap, k_nom)
    insample_only = [c for c in models.values() if c.heldout_runs == 0 and not c.screened_out]
    explaining = [c for c in pool if _sys(c.heldout_rms_arcmin, noise)
                  <= max(policy.explained_share * _sys(trials.before(c)[0], noise), threshold)]
    if explaining:
        return _explained(trials, models, explaining, nominal_play)
    chosen: list[Candidate] = []
    current_sys = sys0
    current: Candidate | None = None
    for _ in range(policy.greedy_max_effects):
        options = pool if current is None else [
            trials.evaluate((*current.effects, c.effects[0]))
            for c in pool[:policy.greedy_options] if c.effects[0] not in current.effects]
        options = [c for c in options if c.plausible]
        if not options:
            break
        best = min(options, key=lambda c: c.heldout_rms_arcmin)
        if _sys(best.heldout_rms_arcmin, noise) ** 2 > (1.0 - policy.greedy_gain) * current_sys**2:
            break
        chosen.append(best)
        current, current_sys = best, _sys(best.heldout_rms_arcmin, noise)
        if current_sys <= max(policy.explained_share * sys0, threshold):
            break
    if chosen and current_sys <= max(policy.explained_share * sys0, threshold):
        return Attribution("greedy", chosen[0].effects[0], [],
                           _additions(trials, models, chosen, policy.alpha),
                           "effects added greedily explain the held-out gap")
    names = [c.effects[-1] for c in chosen] or [c.effects[0] for c in pool[:2]]
    if insample_only:
        best_in = min(insample_only, key=lambda c: c.fit.objective)
        # no in-sample evidence against it (BIC within separation_bic of the best held-out
        # candidate's): the design cannot tell, so the verdict is ambiguous, not unexplained
        if best_in.delta_bic < policy.screen_delta_bic and best_in.delta_bic <= min(
                (c.delta_bic for c in pool), default=math.inf) + policy.separation_bic:
            names = [best_in.effects[0], *names]
            return Attribution("in_sample", None, names[:3], chosen,
                               f"{best_in.effects[0]} fits best in-sample but the design "
                               "holds out no repeat to test it", _next(names[:2]))
    return Attribution("none_closes", None, names, chosen,
                       "a systematic gap remains on held-out runs that no candidate closes")


def named_effect(trials: Trials, models: dict[str, Candidate], att: Attribution,
                 k_nom: float) -> tuple[str | None, list[Candidate], str, dict[str, float],
                                        str | None]:
    """The effect an attribution names, and its model list: the larger term of a joint fit
    (by the RMS its own term moves the twist), and within the flank-curvature family the
    member the loaded slope names. Returns (effect, chosen, reason, sizes, curvature name)."""
    effect, chosen, reason = att.effect, list(att.chosen), att.reason
    sizes: dict[str, float] = {}
    if effect in CANDIDATES and len(chosen) > 1:
        joint = chosen[-1]
        sizes = {e: effect_size_arcmin(trials.stack, joint.fit, joint.effects, e)
                 for e in joint.effects}
        largest = max(sizes, key=sizes.get)
        if largest != effect and largest in models:
            effect = largest
            reason += f"; {largest} is the larger term of the joint fit"
            chosen = [models[largest], *chosen[1:]]
    amplitude = float(np.median([r.amplitude_Nm for r in trials.stack.runs]))
    curv_name, _ = curvature_effect(models, k_nom, amplitude, trials.stack.bearing_smooth,
                                    trials.policy)
    if curv_name is not None and effect in TAKE_UP_PAIR and effect != curv_name:
        effect = curv_name  # one take-up family: the loaded slope names it
    return effect, chosen, reason, sizes, curv_name


def series_beside(trials: Trials, chosen: list[Candidate], k_nom: float
                  ) -> dict[str, Any] | None:
    """A series compliance left once the chosen effects are fitted (:func:`series_compliance`),
    with its in-sample shrink: the final model with the loaded compliance held at the
    nominal ``1 / K`` against the fitted one."""
    if not chosen:
        return None
    last = chosen[-1]
    series = series_compliance(last.fit, k_nom, trials.policy)
    if series is None:
        return None
    held = dict(zip(last.fit.names, last.fit.beta.tolist(), strict=True))
    held["compliance"] = 1.0 / k_nom
    stiff = fit(trials.stack, ("backlash", *last.effects), None, last.fit.nl, fixed=held)
    r_fit = np.concatenate(list(last.fit.residual.values()))
    r_nom = np.concatenate(list(stiff.residual.values()))
    if r_nom.size and float(r_nom @ r_nom) > 0:
        series["shrink"] = 1.0 - math.sqrt(float(r_fit @ r_fit) / float(r_nom @ r_nom))
    return series


# -------------------------------------------------------------------------------- evidence


@dataclass
class Evidence:
    """Everything the verdict rules read, gathered before any verdict (:func:`gather`)."""

    trials: Trials
    models: dict[str, Candidate]
    cal: dict[str, Calibrated]
    omni: Calibrated | None
    fap: dict[str, float]
    systematic: bool  # the lack of fit has calibrated evidence at level alpha
    material: bool  # a plausible candidate with evidence closes material_shrink of the gap
    gap: bool  # there is a gap to attribute
    flanks: FlankAsymmetry | None
    flank_finding: bool
    h0: float  # held-out structural gap (arcmin RMS)
    k_nom: float
    k_fit: float
    stiff_dev: float  # calibrated stiffness against seed 004 eq. (8), relative
    share: float  # share of the predictive gap that the parameters take
    attribution: Attribution | None = None
    effect: str | None = None  # the effect the attribution names (named_effect)
    chosen: list[Candidate] = field(default_factory=list)
    reason: str = ""
    sizes: dict[str, float] = field(default_factory=dict)
    curvature: str | None = None
    series: dict[str, Any] | None = None
    series_larger: bool = False  # the series compliance is the larger term
    size_main: float = 0.0
    stiff_rel_se: float = 0.0  # relative standard error of the calibrated stiffness
    stiff_quant: float = 0.0  # half an encoder count over the loaded twist (relative)
    play: PlayTilt | None = None  # torque on twist inside the free play (play_slope)
    zero: dict[str, Any] = field(default_factory=dict)  # torque zero at the play crossings


def _calibrated_gap(trials: Trials, models: dict[str, Candidate], fap: dict[str, float],
                    gap_fap: float, h0: float, prepared: Sequence[Any]
                    ) -> tuple[bool, bool, bool]:
    """(systematic, material, gap). Statistical evidence alone is not a finding: the held-out
    systematic gap must also exceed the noise floor (and the encoder's quantisation RMS,
    whose error lines up with the loading), or a candidate with evidence must close
    material_shrink of the held-out gap (an effect confined to few points is small in an RMS
    over the whole loop). A candidate's evidence counts for "there is a gap" only when it
    also closes material_shrink of it."""
    policy, alpha = trials.policy, trials.policy.alpha
    systematic = gap_fap <= alpha
    material = any(fap.get(n, 1.0) <= alpha and c.heldout_runs > 0 and not c.screened_out
                   and c.plausible and trials.shrink(c) >= policy.material_shrink
                   for n, c in models.items())
    any_effect = any(fap.get(n, 1.0) <= alpha and c.heldout_runs > 0 and not c.screened_out
                     and trials.shrink(c) >= policy.material_shrink for n, c in models.items())
    floor = max(trials.threshold, quantisation_floor_arcmin(prepared))
    sys0 = _sys(h0, trials.noise)
    gap = not ((sys0 <= floor and not material) or not (any_effect or systematic))
    return systematic, material, gap


def gather(trials: Trials, models: dict[str, Candidate], cal: dict[str, Calibrated],
           omni: Calibrated | None, flanks: FlankAsymmetry | None, h0: float, k_nom: float,
           k_fit: float, share: float, nominal_play: float, prepared: Sequence[Any],
           zero: dict[str, Any] | None = None) -> Evidence:
    """Everything the verdict rests on, before any verdict: the calibrated evidence, whether
    there is a gap, and (when there is) its attribution with the series compliance beside
    it. A candidate whose evidence is within chance is noted as such. ``zero``: the torque
    zero read at the runs' play crossings (:func:`analysis.diagnosis.data.remove_torque_zero`)."""
    policy, alpha = trials.policy, trials.policy.alpha
    fap = {n: c.false_alarm_probability for n, c in cal.items()}
    gap_fap = omni.false_alarm_probability if omni is not None else 1.0
    for name, c in models.items():
        if len(c.effects) == 1 and fap.get(name, 1.0) > alpha and not c.screened_out:
            c.notes.append(f"evidence within what this campaign's own errors give by chance "
                           f"(false-alarm probability {fap.get(name, 1.0):.2g} > {alpha:g})")
    systematic, material, gap = _calibrated_gap(trials, models, fap, gap_fap, h0, prepared)
    flank_finding = bool(not gap and flanks is not None and flanks.finding(
        alpha, policy.stiffness_tolerance, trials.threshold, policy.flank_runs))
    stiff_dev = (k_fit / k_nom - 1.0) if math.isfinite(k_nom) and math.isfinite(k_fit) else 0.0
    ev = Evidence(trials, models, cal, omni, fap, systematic, material, gap, flanks,
                  flank_finding, h0, k_nom, k_fit, stiff_dev, share,
                  stiff_rel_se=compliance_rel_se(trials.base), play=play_slope_of(prepared),
                  stiff_quant=quantisation_share(prepared, k_nom), zero=dict(zero or {}))
    if not gap:
        return ev
    sys0 = _sys(h0, trials.noise)
    att = attribute(trials, models, fap, max(sys0, trials.threshold * (1.0 + 1e-9)),
                    nominal_play, k_nom)
    ev.attribution = att
    ev.effect, ev.chosen, ev.reason, ev.sizes, ev.curvature = named_effect(trials, models, att,
                                                                           k_nom)
    ev.series = series_beside(trials, ev.chosen, k_nom)
    last = ev.chosen[-1] if ev.chosen else None
    if (ev.series is not None and last is not None
            and att.verdict not in ("shaft_compliance", "unexplained")
            and not set(TAKE_UP_PAIR) & set(last.effects)):
        # (a take-up's loaded slope is what names it: not read as a series compliance)
        stack = trials.stack
        size_series = series_size_arcmin(stack, last.fit, last.effects, k_nom)
        ev.size_main = max(effect_size_arcmin(stack, last.fit, last.effects, e)
                           for e in last.effects)
        ev.series["size_arcsec"] = size_series * ARCSEC
        ev.series_larger = size_series > ev.size_main
    return ev


# ----------------------------------------------------------------------------------- rules


@dataclass(frozen=True)
class Decision:
    """The verdict and what goes with it; set once, by :func:`decide`."""

    verdict: str
    rule: str
    reason: str
    candidates: list[str]
    next_experiment: str | None
    chosen: list[Candidate]


@dataclass(frozen=True)
class Rule:
    """One rule of the decision: its name, its physical reason, the verdict it gives (None:
    the effect the attribution names), when it applies, and the report's reason text."""

    name: str
    reason: str
    verdict: str | None
    applies: Callable[[Evidence], bool]
    why: Callable[[Evidence], str]
    candidates: Callable[[Evidence], list[str]] = lambda ev: []
    next_experiment: Callable[[Evidence], str | None] = lambda ev: None
    chosen: Callable[[Evidence], list[Candidate]] = lambda ev: []


SERIES_PAIR = ["shaft_compliance", "mesh_stiffness"]
NEXT_EXPERIMENT_STIFFER = ("measure a loop with the output decoupled from anything but the "
                           "loading drive (seals, cables, fixture bearings off): a parallel "
                           "load path carries torque inside the free play and goes with it")


def _outcome(ev: Evidence, *outcomes: str) -> bool:
    return ev.gap and ev.attribution is not None and ev.attribution.outcome in outcomes


def _below_model(ev: Evidence) -> bool:
    return ev.stiff_dev < -ev.trials.policy.stiffness_tolerance


def _gap_tolerance(ev: Evidence) -> float:
    return stiffness_gap_tolerance(ev.trials.policy, ev.stiff_rel_se, ev.stiff_quant)


def _softer_than_model(ev: Evidence) -> bool:
    return not ev.gap and ev.stiff_dev < -_gap_tolerance(ev)


def _stiffer_than_model(ev: Evidence) -> bool:
    return not ev.gap and ev.stiff_dev > _gap_tolerance(ev)


def _ratio_text(ev: Evidence) -> str:
    return (f"calibrated loaded stiffness {ev.k_fit:.3g} N*m/arcmin, "
            f"{ev.k_fit / ev.k_nom:.3f} times seed 004 eq. (8)'s {ev.k_nom:.3g} "
            f"({ev.stiff_dev:+.1%}, beyond the {_gap_tolerance(ev):.1%} a null "
            "campaign's stiffness stays within)")


def _flanks_why(ev: Evidence) -> str:
    fl = ev.flanks
    assert fl is not None
    return (f"the loaded stiffness differs between the flanks: "
            f"{fl.stiffness_positive_Nm_per_arcmin:.3g} N*m/arcmin positive, "
            f"{fl.stiffness_negative_Nm_per_arcmin:.3g} negative "
            f"({fl.relative:+.0%} compliance, p = {fl.p_value:.2g} over "
            f"{fl.runs} runs, {fl.size_arcmin * ARCSEC:.2f} arcsec at the "
            "amplitude); no effect of the vocabulary makes the slope depend on the flank "
            "(a torque channel whose gain depends on the sign, or flanks of unequal "
            "contact)")


def play_slope_share(ev: Evidence) -> float:
    """The slope of torque on twist inside the play (the weaker half of the crossings) as a
    share of seed 004 eq. (8)'s stiffness (0 when not read)."""
    weak = ev.play.weaker() if ev.play is not None else None
    if weak is None or not (math.isfinite(ev.k_nom) and ev.k_nom > 0):
        return 0.0
    return weak.slope_Nm_per_arcmin / ev.k_nom


def _torque_inside_play(ev: Evidence) -> bool:
    policy = ev.trials.policy
    if ev.play is None or ev.play.behind is None or ev.play.ahead is None:
        return False
    b, a = ev.play.behind.slope_Nm_per_arcmin, ev.play.ahead.slope_Nm_per_arcmin
    return (play_slope_share(ev) >= policy.play_slope_share
            and min(ev.play.behind.z, ev.play.ahead.z) >= policy.play_slope_z
            and min(a, b) >= policy.play_slope_agreement * max(a, b))


def _play_why(ev: Evidence) -> str:
    assert ev.play is not None and ev.play.behind is not None and ev.play.ahead is not None
    b, a = ev.play.behind, ev.play.ahead
    return (f"torque rises with twist inside the free play on both halves of the crossings: "
            f"{b.slope_Nm_per_arcmin:.3g} and {a.slope_Nm_per_arcmin:.3g} N*m/arcmin "
            f"(at least {play_slope_share(ev):.1%} of seed 004 eq. (8)'s {ev.k_nom:.3g}, "
            f"{min(a.z, b.z):.0f} standard errors or more, {a.samples + b.samples} samples in "
            f"{max(a.runs, b.runs)} runs); off both flanks no gear effect carries torque: a "
            "load path in parallel with the gear (a seal, a cable carrier, the fixture)")


def _offset_at_crossings(ev: Evidence) -> bool:
    """The play crossings of zero_veto_runs runs or more put the torque zero beyond the
    re-tare allowance on the rising and the falling crossings alike, beyond chance (one-sided
    t-tests against the allowance at level alpha: data.beyond_allowance_probability), and
    nothing vetoes a sensor offset (a zero reading at zero command within the allowance)."""
    policy, z = ev.trials.policy, ev.zero
    p = z.get("beyond_allowance_false_alarm_probability")
    return (not ev.gap and not ev.trials.stack.offset_veto and p is not None
            and z.get("runs_read", 0) >= policy.zero_veto_runs and p <= policy.alpha)


def _offset_why(ev: Evidence) -> str:
    z = ev.zero
    return (f"the play crossings of {z['runs_read']} runs put the torque zero at "
            f"{z['common_Nm']:+.4f} N*m (run-to-run scatter {z['scatter_Nm']:.4f} N*m), beyond "
            f"the {z['allowance_Nm']:.4f} N*m a re-tare leaves (one-sided t-test over the runs, "
            f"p = {z['beyond_allowance_false_alarm_probability']:.2g}); the loop fit's block means "
            "do not show it: the offset puts only a few samples of each crossing on the "
            "other side of the reading's zero")


def _series_takes_gap(ev: Evidence) -> bool:
    return (_outcome(ev, "none_closes") and not ev.material and not ev.systematic
            and _below_model(ev) and ev.share >= ev.trials.policy.series_share)


RULES: tuple[Rule, ...] = (
    Rule("torque_inside_the_play",
         "the torque read inside the free play rises with the twist, on both halves of the "
         "crossings alike (play_slope_agreement), by at least play_slope_share of seed 004 "
         "eq. (8)'s stiffness and play_slope_z standard errors (a crossing's dynamics or a "
         "friction's rise after a start tilt one half far more): off both flanks no effect "
         "of the vocabulary carries torque (friction reads one level per direction), so a "
         "load path in parallel with the gear is outside the vocabulary, whatever a "
         "candidate absorbs of it (issue 31 item 4)",
         "unexplained",
         _torque_inside_play, _play_why,
         next_experiment=lambda ev: NEXT_EXPERIMENT_STIFFER),
    Rule("flank_slopes_differ",
         "no gap beyond chance by the candidates or the lack of fit, but the two flanks' loaded "
         "slopes differ beyond chance and beyond stiffness_tolerance: no effect of the "
         "vocabulary makes a flank-dependent slope, so this is a real gap the model lacks",
         "unexplained",
         lambda ev: not ev.gap and ev.flank_finding, _flanks_why),
    Rule("stiffness_below_model",
         "no structural gap, but the calibrated loaded stiffness is below seed 004 eq. (8) "
         "by more than stiffness_gap (or its standard errors): a compliance in series with "
         "the mesh (shaft, coupling) is the unmodelled effect; a softer mesh looks the same "
         "in loops, so both are named with the experiment that separates them. A gap the "
         "calibration absorbs is still a gap to the user (issue 31 item 2)",
         "shaft_compliance",
         _softer_than_model,
         lambda ev: (f"no structural gap beyond the model's, but the {_ratio_text(ev)}: a "
                     "series compliance (or a softer mesh than the model)"),
         candidates=lambda ev: list(SERIES_PAIR),
         next_experiment=lambda ev: NEXT_EXPERIMENT[frozenset(SERIES_PAIR)]),
    Rule("stiffness_above_model",
         "no structural gap, but the calibrated loaded stiffness is above seed 004 eq. (8) "
         "by more than stiffness_gap over the whole loaded range: no effect of the vocabulary "
         "stiffens a unit linearly (a contact stiffening bends the curve, it does not raise "
         "the slope everywhere); a load path in parallel with the gear (a seal, a cable "
         "carrier, the fixture) or a mesh stiffer than the model",
         "unexplained",
         _stiffer_than_model,
         lambda ev: (f"no structural gap beyond the model's, but the {_ratio_text(ev)}: "
                     "stiffer than the model over the whole range, which no effect of the "
                     "vocabulary gives (a load path in parallel with the gear, or a mesh "
                     "stiffer than seed 004 eq. 8)"),
         next_experiment=lambda ev: NEXT_EXPERIMENT_STIFFER),
    Rule("torque_zero_at_the_crossings",
         "no structural gap, but the torque read at the moment the twist jumps across the free "
         "play (the unit's true torque is zero there) is the same non-zero value in every run, "
         "beyond the zero allowance by more than the runs' scatter on the rising and on the "
         "falling crossings alike (zero_veto_runs runs or more, one-sided at alpha each): a "
         "constant torque-sensor offset moves every play crossing "
         "by itself, while a friction splits the loading and unloading crossings and cancels "
         "in their mean, and a re-tare residual differs from run to run. The loop fit misses "
         "it when the offset puts only a few samples of a crossing on the other side of the "
         "reading's zero, which a block mean averages away",
         "torque_sensor_offset",
         _offset_at_crossings, _offset_why,
         next_experiment=lambda ev: NEXT_EXPERIMENT[
             frozenset({"friction", "torque_sensor_offset"})]),
    Rule("within_noise",
         "the held-out structural gap is within the noise (or the encoder's quantisation) "
         "and neither a candidate nor the lack of fit has calibrated evidence that closes a "
         "material part of it: the nominal model with its parameters calibrated explains "
         "the runs",
         "none",
         lambda ev: not ev.gap,
         lambda ev: (f"held-out structural gap {ev.h0 * ARCSEC:.2f} arcsec RMS against noise "
                     f"{ev.trials.noise * ARCSEC:.2f} arcsec; no candidate and no lack of fit "
                     "beyond what this campaign's own errors give by chance at level "
                     f"{ev.trials.policy.alpha:g}")),
    Rule("series_compliance_takes_the_gap",
         "no candidate closes the structural gap and its lack of fit is within chance, while "
         "at least series_share of the gap to the nominal model is a loaded slope below "
         "seed 004 eq. (8): the series compliance is the effect (a lack of fit beyond chance "
         "stays unexplained: a creep also lowers the fitted slope)",
         "shaft_compliance",
         _series_takes_gap,
         lambda ev: (f"the calibrated stiffness is {-ev.stiff_dev:.0%} below seed 004 eq. (8) "
                     f"and takes {ev.share:.0%} of the gap to the nominal model: a series "
                     "compliance (or a softer mesh than the model); a structural gap no "
                     f"candidate closes remains ({ev.h0 * ARCSEC:.2f} arcsec RMS held out)"),
         candidates=lambda ev: list(SERIES_PAIR),
         next_experiment=lambda ev: NEXT_EXPERIMENT[frozenset(SERIES_PAIR)]),
    Rule("series_compliance_larger_term",
         "once the attributed effects are fitted, the loaded stiffness is still below seed "
         "004 eq. (8) and that series compliance moves the twist more than the largest "
         "effect's own term: it is the verdict, the effects go under also",
         "shaft_compliance",
         lambda ev: ev.gap and ev.series_larger,
         lambda ev: ev.reason + ("; a series compliance (loaded stiffness below seed 004 "
                                 "eq. 8) is the larger term"),
         candidates=lambda ev: list(ev.attribution.names) if ev.attribution else [],
         next_experiment=lambda ev: ev.attribution.next_experiment if ev.attribution else None,
         chosen=lambda ev: ev.chosen),
    Rule("design_cannot_separate",
         "several candidates explain the gap equally well on the held-out runs (or the best "
         "cannot be held out by this design): the verdict lists them with the experiment "
         "that would tell them apart",
         "ambiguous",
         lambda ev: _outcome(ev, "tie", "in_sample"),
         lambda ev: ev.reason,
         candidates=lambda ev: list(ev.attribution.names) if ev.attribution else [],
         next_experiment=lambda ev: ev.attribution.next_experiment if ev.attribution else None,
         chosen=lambda ev: ev.chosen),
    Rule("no_candidate_closes",
         "a systematic gap remains on held-out runs that no plausible candidate with "
         "calibrated evidence closes (alone or added greedily): outside the vocabulary",
         "unexplained",
         lambda ev: _outcome(ev, "none_closes"),
         lambda ev: ev.reason,
         candidates=lambda ev: list(ev.attribution.names) if ev.attribution else [],
         chosen=lambda ev: ev.chosen),
    Rule("effect_explains",
         "one effect (alone, after a tie settled by the free play, or the first of effects "
         "added greedily) leaves at most explained_share of the systematic held-out gap; the "
         "verdict is the larger term of the joint fit, named within the flank-curvature "
         "family by the loaded slope",
         None,
         lambda ev: _outcome(ev, "one", "play", "greedy"),
         lambda ev: ev.reason,
         chosen=lambda ev: ev.chosen),
)
"""The decision's rules in the order they are tried; the first that applies decides."""


def decide(ev: Evidence, rules: Sequence[Rule] = RULES) -> Decision:
    """The verdict: the first rule of ``rules`` (in order) that applies. The only place a
    verdict is set."""
    for rule in rules:
        if rule.applies(ev):
            verdict = rule.verdict if rule.verdict is not None else ev.effect
            assert verdict is not None
            return Decision(verdict, rule.name, rule.why(ev), rule.candidates(ev),
                            rule.next_experiment(ev), rule.chosen(ev))
    raise AssertionError("no rule applies")  # within_noise and the attribution cover all


def rules_table(rules: Sequence[Rule] = RULES) -> list[dict[str, str]]:
    """The rules in order, as docs/diagnosis.md lists them."""
    return [{"rule": r.name, "verdict": r.verdict or "(the attributed effect)",
             "reason": r.reason} for r in rules]


# ----------------------------------------------------------------------------- the tie-break


def play_tiebreak(names: Sequence[str], models: dict[str, Candidate],
                  nominal_play_arcmin: float, policy: DecisionPolicy = POLICY
                  ) -> tuple[str | None, str]:
    """Settle a bearing_clearance / stiffness_nonlinearity tie by the free play: the bearings'
    radial clearances add play (seed 000 eqs. 3 + 7, budget from the inspected
    ``bearing_clearance_mm``), contact stiffening adds none. Returns (effect or None, why)."""
    pair = {"bearing_clearance", "stiffness_nonlinearity"}
    if set(names) != pair or not math.isfinite(nominal_play_arcmin):
        return None, ""
    bearing = models["bearing_clearance"]
    budget = bearing.params.get("budget_extra_play_arcmin")
    if not budget or budget <= 0:
        return None, ""
    excess = [models[n].fit.coef("play") - nominal_play_arcmin for n in pair]
    if min(excess) >= policy.play_present * budget:
        return "bearing_clearance", (
            f"calibrated free play {min(excess):+.3f} arcmin above the nominal, as the inspected "
            f"bearing clearances add ({budget:.3f} arcmin, seed 000 eqs. 3 + 7)")
    if max(excess) <= policy.play_absent * budget:
        return "stiffness_nonlinearity", (
            f"calibrated free play within {max(excess):+.3f} arcmin of the nominal: no extra "
            f"play of bearing clearances ({budget:.3f} arcmin expected)")
    return None, ""


def _next(names: Sequence[str]) -> str:
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            key = frozenset({names[i], names[j]})
            if key in NEXT_EXPERIMENT:
                return NEXT_EXPERIMENT[key]
    return ("vary the factor the candidates depend on differently (position, temperature, "
            "amplitude, dwell) and repeat runs at the same conditions")

