"""The verdict of a run and of a campaign against their limits, and the one word it is shown as.

Every run.json and campaign.json carries top-level ``limits`` (the limits in force; None =
not checked) and ``outcome``, one of :data:`OUTCOMES`:

- ``"ok"``: completed, and every limit that applies is met;
- ``"not_ok"``: a measured metric is beyond its limit (a unit that failed a limit is not OK
  whatever else happened);
- ``"incomplete"``: the run was aborted (fault, abort, E-stop, recovered after a crash), or a
  limited metric could not be measured (analysis error) or is not a finite number (NaN,
  infinity), or the simulated rig's plant was of another unit kind than the run's unit
  (:func:`plant_mismatch`): no verdict on the unit;
- ``"no_limits"``: completed, but no limit was set: the unit was measured, not judged
  (neither OK nor NOT OK).

A metric the run's design cannot measure is **not applicable**, not a failure: the torsional
stiffness is defined between 50 % and 100 % of the rated torque (seed 000, Fig. 6), so a run
whose amplitude is below 100 % of the rated torque has no stiffness to check.

Everything that shows a verdict (the page, the certificate, the CLI, SPC, the Python API)
shows it as :data:`OUTCOME_WORDS` says: OK / NOT OK / INCOMPLETE / NO LIMITS. Records written
before ``"no_limits"`` existed are read by :func:`recorded_outcome`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

__all__ = ["OUTCOMES", "OUTCOME_WORDS", "OUTCOME_MEANINGS", "LIMIT_KEYS", "run_outcome",
           "campaign_outcome", "impossible_metrics", "not_applicable", "outcome_word",
           "parse_outcome", "limits_set", "finite_number", "metric_check", "recorded_outcome",
           "recorded_campaign_outcome", "is_te_record", "kind_applies", "NON_NEGATIVE",
           "BELOW_ZERO", "AGAINST_TORQUE", "BELOW_NOTE", "below_zero_text",
           "below_zero_keys", "below_zero_note", "twist_against_torque", "plant_mismatch"]

OUTCOMES = ("ok", "not_ok", "incomplete", "no_limits")
OUTCOME_WORDS = {"ok": "OK", "not_ok": "NOT OK", "incomplete": "INCOMPLETE",
                 "no_limits": "NO LIMITS"}
"""Outcome code -> the word every view shows (the only such mapping of the product)."""
OUTCOME_MEANINGS = {"ok": "every limit met", "not_ok": "a limit failed",
                    "incomplete": "no verdict on the unit", "no_limits": "no limits set"}
"""Outcome code -> what it means, in a few words (the certificate, ``rig runs``)."""
NO_OUTCOME = "–"
"""Shown where a run has no verdict yet (running) or none was recorded."""
LIMIT_KEYS = {
    "lost_motion_arcmin_max": ("lost_motion_arcmin", "above"),
    "backlash_arcmin_max": ("backlash_arcmin", "above"),
    "stiffness_Nm_per_arcmin_min": ("stiffness_Nm_per_arcmin", "below"),
    "te_pp_max_arcsec": ("te_pp_arcsec", "above"),
    "te_hysteresis_max_arcmin": ("te_hysteresis_arcmin", "above"),
}
"""Limit key -> (metric key, the side that fails). The ``te_`` limits judge a transmission
error run (run-format.md), the others a hysteresis run; a limit of the other test kind does
not apply to a run (:func:`kind_applies`)."""
TE_KIND = "transmission_error"


def outcome_word(code: Any) -> str:
    """The displayed word of an outcome code ("not_ok" -> "NOT OK"); :data:`NO_OUTCOME` for
    None; a string that is no outcome code (another lab's record) as it is."""
    if code is None or code == "":
        return NO_OUTCOME
    return OUTCOME_WORDS.get(code, str(code))


def _folded(text: str) -> str:
    return " ".join(text.replace("_", " ").replace("-", " ").lower().split())


_ACCEPTED = {_folded(k): k for k in OUTCOMES} | {_folded(w): k for k, w in OUTCOME_WORDS.items()}


def parse_outcome(value: Any) -> str:
    """An outcome code from a code or a displayed word, any case ("NOT OK", "not_ok",
    "No limits" ...); ValueError naming the valid values otherwise."""
    code = _ACCEPTED.get(_folded(value)) if isinstance(value, str) else None
    if code is None:
        raise ValueError(
            f"outcome must be one of {', '.join(OUTCOMES)} (or the words "
            f"{', '.join(OUTCOME_WORDS.values())}, any case), got {value!r}")
    return code


def limits_set(limits: Mapping[str, Any] | None) -> bool:
    """Is any limit of :data:`LIMIT_KEYS` set (not None)?"""
    return isinstance(limits, Mapping) and any(limits.get(k) is not None for k in LIMIT_KEYS)


def finite_number(value: Any) -> bool:
    """Is ``value`` a finite real number (not a bool, NaN or an infinity)?"""
    return (isinstance(value, int | float) and not isinstance(value, bool)
            and math.isfinite(value))


def is_te_record(run: dict[str, Any]) -> bool:
    """Is this record (run.json or a flat one) a transmission error run: ``test.kind`` (or
    ``test_kind``) says so, or, the kind unrecorded, it carries a ``te_`` metric?"""
    test = run.get("test") if isinstance(run.get("test"), dict) else {}
    kind = test.get("kind", run.get("test_kind"))
    if kind is not None:
        return kind == TE_KIND
    metrics = {**run, **(run.get("result") or {})}
    return any(k.startswith("te_") and metrics.get(k) is not None for k in metrics)


def kind_applies(run: dict[str, Any], metric: str) -> bool:
    """Does ``metric`` belong to this run's test kind (``te_`` metrics to a transmission
    error run, the loop's to a hysteresis run)?"""
    return metric.startswith("te_") == is_te_record(run)


def not_applicable(run: dict[str, Any], metric: str) -> str | None:
    """Why ``metric`` does not apply to this run's design (None: it applies)."""
    if not kind_applies(run, metric):
        kind = "transmission error" if is_te_record(run) else "hysteresis"
        return f"not applicable: a {kind} run does not measure it"
    if metric == "stiffness_Nm_per_arcmin":
        test = run.get("test") or {}
        amplitude = run.get("amplitude_pct", test.get("amplitude_pct"))
        if amplitude is not None and float(amplitude) < 100.0:
            return (f"not applicable: the stiffness needs the rated torque, the run reached "
                    f"{float(amplitude):g} % of it")
    return None


IMPOSSIBLE_BELOW_ZERO = ("lost_motion_arcmin", "backlash_arcmin", "stiffness_Nm_per_arcmin",
                         "stiffness_pos_Nm_per_arcmin", "stiffness_neg_Nm_per_arcmin")
"""Metrics that no gear unit can have below zero: a negative stiffness or play means the
torque and twist were not of the same instant or one channel's sign is wrong."""
NON_NEGATIVE = ("lost_motion_arcmin", "backlash_arcmin", "stiffness_Nm_per_arcmin",
                "loop_area_J")
"""Metrics that every view prints as :func:`below_zero_text` says when they come out below
zero (a loop's area is the energy lost per cycle: never below zero either)."""
COVERAGE_K = 2.0
"""Coverage factor of the bound printed for a value below zero: U = k·u (GUM, about 95 %)."""
BELOW_ZERO = "below zero: no measurement"
"""What every view prints instead of a metric of :data:`NON_NEGATIVE` far below zero."""
AGAINST_TORQUE = ("the twist runs against the torque: check the output encoder's counting "
                  "direction")
"""The likely cause of a loop whose stiffness is below zero (an encoder counting the other
way round flips every figure of the loop)."""
BELOW_NOTE = ("a value below zero is no measurement: within three standard uncertainties "
              "u of zero it is printed as \"below resolution (< U)\", U = 2u, else as "
              f"\"{BELOW_ZERO}\"")
"""How the views print a non-negative metric measured below zero (docs/certificate.md)."""


def twist_against_torque(run: dict[str, Any]) -> bool:
    """Does the run's twist fall as its torque rises (its stiffness, N·m/arcmin, below zero),
    flat or run.json record?"""
    stiffness = {**run, **(run.get("result") or {})}.get("stiffness_Nm_per_arcmin")
    return finite_number(stiffness) and stiffness < 0


def below_zero_text(key: str, value: Any, uncertainty: Any, spec: str, unit: str, *,
                    against_torque: bool = False) -> str | None:
    """How a metric that cannot be negative (:data:`NON_NEGATIVE`) measured below zero is
    printed instead of its value: ``below resolution (< U unit)`` when it lies within three
    standard uncertainties of zero (U = 2u, the expanded uncertainty, k = 2, in the metric's
    unit; never for a stiffness), else :data:`BELOW_ZERO` (as :func:`impossible_metrics`
    judges it), with ``(`` :data:`AGAINST_TORQUE` ``)`` when ``against_torque``
    (:func:`twist_against_torque`).
    None for a value printed as it is (zero or above, another metric, not a finite number)."""
    if key not in NON_NEGATIVE or not finite_number(value) or value >= 0:
        return None
    if (not key.startswith("stiffness") and finite_number(uncertainty) and uncertainty > 0
            and value + 3.0 * uncertainty >= 0):
        return f"below resolution (< {format(COVERAGE_K * uncertainty, spec)}{unit})"
    return f"{BELOW_ZERO} ({AGAINST_TORQUE})" if against_torque else BELOW_ZERO


NON_NEGATIVE_LABELS = {"lost_motion_arcmin": "lost motion", "backlash_arcmin": "backlash",
                       "stiffness_Nm_per_arcmin": "stiffness", "loop_area_J": "loop area"}
"""The words of :data:`NON_NEGATIVE` in :func:`below_zero_note`."""


def below_zero_keys(run: dict[str, Any]) -> list[str]:
    """The metrics of :data:`NON_NEGATIVE` that are no measurement (:data:`BELOW_ZERO`) in
    this run (flat or run.json record, uncertainties under ``uncertainty``)."""
    metrics = {**run, **(run.get("result") or {})}
    sigma = metrics.get("uncertainty") or {}
    return [k for k in NON_NEGATIVE
            if below_zero_text(k, metrics.get(k), sigma.get(k), "g", "") == BELOW_ZERO]


def below_zero_note(run: dict[str, Any]) -> str | None:
    """One line for the views that print a run's figures: which metrics are no measurement
    and the likely cause, ``lost motion, loop area below zero: no measurement (the twist
    runs against the torque: ...)``; None when every metric is a measurement."""
    keys = below_zero_keys(run)
    if not keys:
        return None
    words = ", ".join(NON_NEGATIVE_LABELS[k] for k in keys)
    cause = f" ({AGAINST_TORQUE})" if twist_against_torque(run) else ""
    return f"{words} {BELOW_ZERO}{cause}"


CHANNEL_LAG_LIMIT_S = 0.01
"""Torque and twist out of step by this much or more: at the rig's ramp rates (25 N*m/s) a
few % of the rated torque paired with the wrong twist; the loop is no measurement."""


def impossible_metrics(run: dict[str, Any]) -> list[str]:
    """Why the run's figures are no measurement, one line each: channels out of step, a twist
    the torque does not explain (``encoder_faults``: a jump or a frozen encoder reading,
    issue 33 item 1), metrics physically impossible (below zero beyond three of their
    standard uncertainties; a stiffness at or below zero always), naming the likely cause
    (:data:`AGAINST_TORQUE` when the stiffness is below zero)."""
    metrics = {**run, **(run.get("result") or {})}
    sigma = metrics.get("uncertainty") or {}
    label = run.get("label") or run.get("run_id") or "run"
    out = []
    faults = metrics.get("encoder_faults")
    if isinstance(faults, list):
        out.extend(f"run {label}: {fault}: no verdict" for fault in faults[:3]
                   if isinstance(fault, str))
    lag = metrics.get("channel_lag_s")
    if finite_number(lag) and abs(lag) >= CHANNEL_LAG_LIMIT_S:
        out.append(f"run {label}: the torque channel is {'late' if lag > 0 else 'ahead'} by "
                   f"about {abs(lag):.3g} s against the twist (limit {CHANNEL_LAG_LIMIT_S:g} s):"
                   " channels out of step, no verdict")
    cause = (AGAINST_TORQUE if twist_against_torque(run)
             else "torque and twist not of the same instant, or a channel's sign reversed")
    for key in IMPOSSIBLE_BELOW_ZERO:
        value = metrics.get(key)
        if not finite_number(value):
            continue
        u = sigma.get(key) if finite_number(sigma.get(key)) else 0.0
        if (key.startswith("stiffness") and value <= 0) or value + 3.0 * u < 0:
            out.append(f"run {label}: {key} = {value:.4g} is physically impossible ({cause}):"
                       " no verdict")
    return out


UNIT_KIND_WORDS = {"internal_involute": "internal involute pair", "cycloid": "cycloid",
                   "beveloid": "beveloid", "planetary": "planetary"}
"""A unit kind (run.json ``unit.kind``, absent: internal_involute) in words."""


def _kind_words(kind: Any) -> str:
    return UNIT_KIND_WORDS.get(str(kind), str(kind))


def plant_mismatch(run: Mapping[str, Any]) -> str | None:
    """Why a run measured on the simulated rig measured another unit than its own (None: it
    did not, or the rig was real): the simulated devices had a plant of another kind
    (run.json ``simulation.plant_kind``) than the run's unit (``unit.kind``). Recorded by the
    engine as ``result.plant_mismatch``; judged from the record when that is absent (issue 33
    item 10: such a run is never certified OK)."""
    result = run.get("result") if isinstance(run.get("result"), Mapping) else {}
    recorded = result.get("plant_mismatch", run.get("plant_mismatch"))
    if isinstance(recorded, str) and recorded:
        return recorded
    simulation, unit = run.get("simulation"), run.get("unit")
    if not isinstance(simulation, Mapping) or not isinstance(unit, Mapping):
        return None
    plant_kind = simulation.get("plant_kind")
    kind = unit.get("kind") or "internal_involute"
    if not isinstance(plant_kind, str) or plant_kind == kind:
        return None
    return (f"measured on a simulated {_kind_words(plant_kind)} plant, the unit is a "
            f"{_kind_words(kind)}")


def metric_check(run: dict[str, Any], metric: str, bound: Any, worse: str
                 ) -> tuple[str, str | None]:
    """One metric of ``run`` against one limit ``bound`` (``worse``: "above" or "below", the
    side that fails): ("ok" | "not_ok" | "not_applicable" | "not_measured" | "not_finite",
    why in words or None). A value that is not a finite number is never inside a limit."""
    metrics = {**run, **(run.get("result") or {})}
    label = run.get("label") or run.get("run_id") or "run"
    why_not = not_applicable(run, metric)
    if why_not is not None:
        return "not_applicable", f"run {label}: {metric} {why_not}"
    value = metrics.get(metric)
    if value is None:
        why = (metrics.get("errors") or {}).get(metric, "not measured")
        return "not_measured", f"run {label}: {metric} unavailable ({why})"
    if not finite_number(value):
        return "not_finite", (f"run {label}: {metric} = {value!r} is not a finite number: "
                              "no verdict against its limit")
    if (value > bound) if worse == "above" else (value < bound):
        return "not_ok", f"run {label}: {metric} = {value:.4g} is {worse} the limit {bound:g}"
    return "ok", None


def run_outcome(run: dict[str, Any], limits: dict[str, Any] | None
                ) -> tuple[str, list[str], list[str]]:
    """(outcome, failures, not-applicable notes) of one run.

    ``run``: the run's status/reason and metrics, flat (``RunOutcome.to_dict()``) or as
    run.json (metrics under ``result``); ``limits``: the limit keys of :data:`LIMIT_KEYS`.
    """
    label = run.get("label") or run.get("run_id") or "run"
    if run.get("status") != "completed":
        return "incomplete", [f"run {label}: {run.get('status')}: {run.get('reason')}"], []
    mismatch = plant_mismatch(run)
    if mismatch is not None:  # another unit was measured: no verdict on this one
        return "incomplete", [f"run {label}: {mismatch}"], []
    impossible = impossible_metrics(run)
    if impossible:
        return "incomplete", impossible, []
    if not limits_set(limits) or not any(
            (limits or {}).get(k) is not None and kind_applies(run, m)
            for k, (m, _) in LIMIT_KEYS.items()):
        return "no_limits", [], []
    failures: list[str] = []
    missing: list[str] = []
    notes: list[str] = []
    for key, (metric, worse) in LIMIT_KEYS.items():
        bound = (limits or {}).get(key)
        if bound is None:
            continue
        verdict, why = metric_check(run, metric, bound, worse)
        if verdict == "not_applicable":
            notes.append(why or "")
        elif verdict == "not_ok":
            failures.append(why or "")
        elif verdict in ("not_measured", "not_finite"):
            missing.append(why or "")
    if failures:
        return "not_ok", failures + missing, notes
    if missing:
        return "incomplete", missing, notes
    return "ok", [], notes


def campaign_outcome(run_outcomes: list[str], status: str) -> str:
    """A campaign's outcome from its runs' outcomes and its own status: NOT OK if any run is;
    INCOMPLETE if aborted, empty or any run incomplete; NO LIMITS if no run had a limit set;
    else OK."""
    if "not_ok" in run_outcomes:
        return "not_ok"
    if status != "completed" or not run_outcomes or "incomplete" in run_outcomes:
        return "incomplete"
    if all(o == "no_limits" for o in run_outcomes):
        return "no_limits"
    return "ok"


def recorded_outcome(meta: Mapping[str, Any], limits: Mapping[str, Any] | None = None
                     ) -> str | None:
    """The outcome of a run record (run.json, or the index's copy of it) as every view
    shows it. ``limits``: those in force when run.json has none (its campaign's).

    - a running run has none (None);
    - ``"not_ok"``, ``"incomplete"``, ``"no_limits"`` are read as recorded;
    - ``"ok"`` is shown only when the record's own metrics and limits confirm it: an ``"ok"``
      written without any limit set (before ``"no_limits"`` existed) reads ``"no_limits"``,
      and one whose limited metric is not a finite number reads ``"incomplete"``;
    - no outcome recorded (an imported run, another lab's run.json): judged now from its
      status (completed when absent), metrics and limits (:func:`run_outcome`);
    - any other string (another lab's own word) is kept as it is.
    """
    if meta.get("status") == "running":
        return None
    recorded = meta.get("outcome")
    if isinstance(recorded, str) and recorded and recorded not in OUTCOMES:
        return recorded
    if recorded in ("not_ok", "incomplete", "no_limits"):
        return recorded
    run_limits = meta.get("limits") if isinstance(meta.get("limits"), Mapping) else limits
    run = {**meta, "status": meta.get("status") or "completed"}
    return run_outcome(run, dict(run_limits or {}))[0]


def recorded_campaign_outcome(recorded: Any, limits: Mapping[str, Any] | None,
                              run_outcomes: Iterable[str | None], status: str | None
                              ) -> str | None:
    """A campaign's outcome as every view shows it, from campaign.json's ``outcome``
    (``recorded``), its ``limits``, its runs' outcomes (:func:`recorded_outcome`) and status:
    read as :func:`recorded_outcome` reads a run's ("ok" confirmed by the runs; none recorded:
    judged from the runs)."""
    if status == "running":
        return None
    if isinstance(recorded, str) and recorded and recorded not in OUTCOMES:
        return recorded
    if recorded in ("not_ok", "incomplete", "no_limits"):
        return recorded
    runs = [o for o in run_outcomes if o is not None]
    if recorded == "ok" and not runs:
        return "ok" if limits_set(limits) else "no_limits"
    return campaign_outcome(runs, status or "completed")
