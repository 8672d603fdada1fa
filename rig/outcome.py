"""OK / not OK / incomplete: the verdict of a run and of a campaign against their limits.

Every run.json and campaign.json carries top-level ``limits`` (the limits in force; None =
not checked) and ``outcome``:

- ``"ok"``: completed, and every limit that applies is met;
- ``"not_ok"``: a measured metric is beyond its limit (a unit that failed a limit is not OK
  whatever else happened);
- ``"incomplete"``: the run was aborted (fault, abort, E-stop, recovered after a crash) or a
  limited metric could not be measured (analysis error): no verdict on the unit.

A metric the run's design cannot measure is **not applicable**, not a failure: the torsional
stiffness is defined between 50 % and 100 % of the rated torque (seed 000, Fig. 6), so a run
whose amplitude is below 100 % of the rated torque has no stiffness to check.
"""

from __future__ import annotations

from typing import Any

__all__ = ["OUTCOMES", "LIMIT_KEYS", "run_outcome", "campaign_outcome", "impossible_metrics",
           "not_applicable"]

OUTCOMES = ("ok", "not_ok", "incomplete")
LIMIT_KEYS = {
    "lost_motion_arcmin_max": ("lost_motion_arcmin", "above"),
    "backlash_arcmin_max": ("backlash_arcmin", "above"),
    "stiffness_Nm_per_arcmin_min": ("stiffness_Nm_per_arcmin", "below"),
}
"""Limit key -> (metric key, the side that fails)."""


def not_applicable(run: dict[str, Any], metric: str) -> str | None:
    """Why ``metric`` does not apply to this run's design (None: it applies)."""
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


CHANNEL_LAG_LIMIT_S = 0.01
"""Torque and twist out of step by this much or more: at the rig's ramp rates (25 N*m/s) a
few % of the rated torque paired with the wrong twist; the loop is no measurement."""


def impossible_metrics(run: dict[str, Any]) -> list[str]:
    """Metrics that are physically impossible (below zero beyond three of their standard
    uncertainties; a stiffness at or below zero always), one line each."""
    metrics = {**run, **(run.get("result") or {})}
    sigma = metrics.get("uncertainty") or {}
    label = run.get("label") or run.get("run_id") or "run"
    out = []
    lag = metrics.get("channel_lag_s")
    if isinstance(lag, int | float) and abs(lag) >= CHANNEL_LAG_LIMIT_S:
        out.append(f"run {label}: the torque channel is {'late' if lag > 0 else 'ahead'} by "
                   f"about {abs(lag):.3g} s against the twist (limit {CHANNEL_LAG_LIMIT_S:g} s):"
                   " channels out of step, no verdict")
    for key in IMPOSSIBLE_BELOW_ZERO:
        value = metrics.get(key)
        if not isinstance(value, int | float):
            continue
        u = sigma.get(key) if isinstance(sigma.get(key), int | float) else 0.0
        if (key.startswith("stiffness") and value <= 0) or value + 3.0 * u < 0:
            out.append(f"run {label}: {key} = {value:.4g} is physically impossible (torque and "
                       "twist not of the same instant, or a channel's sign reversed): "
                       "no verdict")
    return out


def run_outcome(run: dict[str, Any], limits: dict[str, Any] | None
                ) -> tuple[str, list[str], list[str]]:
    """(outcome, failures, not-applicable notes) of one run.

    ``run``: the run's status/reason and metrics, flat (``RunOutcome.to_dict()``) or as
    run.json (metrics under ``result``); ``limits``: the limit keys of :data:`LIMIT_KEYS`.
    """
    metrics = {**run, **(run.get("result") or {})}
    label = run.get("label") or run.get("run_id") or "run"
    if run.get("status") != "completed":
        return "incomplete", [f"run {label}: {run.get('status')}: {run.get('reason')}"], []
    impossible = impossible_metrics(run)
    if impossible:
        return "incomplete", impossible, []
    failures: list[str] = []
    missing: list[str] = []
    notes: list[str] = []
    for key, (metric, worse) in LIMIT_KEYS.items():
        bound = (limits or {}).get(key)
        if bound is None:
            continue
        why_not = not_applicable(run, metric)
        if why_not is not None:
            notes.append(f"run {label}: {metric} {why_not}")
            continue
        value = metrics.get(metric)
        if value is None:
            why = (metrics.get("errors") or {}).get(metric, "not measured")
            missing.append(f"run {label}: {metric} unavailable ({why})")
        elif (value > bound) if worse == "above" else (value < bound):
            failures.append(f"run {label}: {metric} = {value:.4g} is {worse} the limit "
                            f"{bound:g}")
    if failures:
        return "not_ok", failures + missing, notes
    if missing:
        return "incomplete", missing, notes
    return "ok", [], notes


def campaign_outcome(run_outcomes: list[str], status: str) -> str:
    """A campaign's outcome from its runs' outcomes and its own status."""
    if "not_ok" in run_outcomes:
        return "not_ok"
    if status != "completed" or not run_outcomes or "incomplete" in run_outcomes:
        return "incomplete"
    return "ok"
