"""The production quality view (``rig spc``): the store's tested units as control charts.

One point per *unit test*: the completed runs of one campaign (a unit measured at several
positions, amplitudes ...) or one run outside any campaign, in the order the tests started.
Its value is the unit's worst run: the largest lost motion and backlash, the smallest
stiffness (the campaign limits are checked on every run, and the seed 000 batch band is the
lost motion at the worst position). Metrics are the newest re-analysis of a run (``rig
reanalyse`` after a model or software update) where one is stored, else those stored with
the run (``result``).

A run whose lost motion, backlash or stiffness is stored as something other than a finite
number (NaN, an infinity) is left out of the charts and named under ``excluded`` (the run,
its unit and why), with every other run of its unit test kept. Each unit test carries its
``outcome`` and the displayed word ``verdict`` (OK / NOT OK / INCOMPLETE / NO LIMITS,
rig/outcome.py): its campaign's, or its single run's.

Per design (``unit.design``, else ``unit.model``; runs without one form the design
"(none)"), for lost motion, backlash and stiffness: the individuals/moving-range chart and
its rule signals (:mod:`analysis.spc`), Cp/Cpk/Pp/Ppk against the limits of the design's
newest campaign that has limits, and for lost motion the seed 000 batch band of the design
(:func:`rig.campaign.batch_band`; None for a unit the batch model cannot use).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from typing import Any

from analysis.errors import AnalysisError
from analysis.loop import PROFILES
from analysis.spc import D2, D4, RULES, capability, imr_chart
from rig.outcome import outcome_word, recorded_campaign_outcome
from rig.store import Store
from rig.store.records import CampaignInfo, RunInfo

SPC_FORMAT = "rig-spc/1"
NO_DESIGN = "(none)"
# metric -> (worst of a unit's runs, limits key of the upper limit, of the lower limit)
METRICS: dict[str, tuple[str, str | None, str | None]] = {
    "lost_motion_arcmin": ("max", "lost_motion_arcmin_max", None),
    "backlash_arcmin": ("max", "backlash_arcmin_max", None),
    "stiffness_Nm_per_arcmin": ("min", None, "stiffness_Nm_per_arcmin_min"),
}


@dataclass
class UnitTest:
    """One point of the charts: a unit's campaign (or single run) and its worst metrics."""

    test_id: str
    unit_serial: str | None
    started_at: str
    campaign_id: str | None
    run_ids: list[str] = field(default_factory=list)
    values: dict[str, float | None] = field(default_factory=dict)
    outcome: str | None = None
    """The verdict of the unit test (rig/outcome.py code; None: not known)."""

    def to_dict(self) -> dict[str, Any]:
        return {"test_id": self.test_id, "unit_serial": self.unit_serial,
                "started_at": self.started_at, "campaign_id": self.campaign_id,
                "run_ids": self.run_ids, "outcome": self.outcome,
                "verdict": None if self.outcome is None else outcome_word(self.outcome),
                **self.values}


def not_finite(info: RunInfo) -> list[str]:
    """The charted metrics of a run stored as something other than a finite number, as
    ``metric = value`` (empty: the run can be charted)."""
    out = []
    for metric in METRICS:
        value = (info.metrics or {}).get(metric)
        if isinstance(value, float) and not math.isfinite(value):
            out.append(f"{metric} = {value}")
    return out


def excluded_runs(runs: list[RunInfo]) -> tuple[list[RunInfo], list[dict[str, Any]]]:
    """(the runs that can be charted, the runs left out: run id, unit, campaign and why)."""
    kept, left_out = [], []
    for info in runs:
        bad = not_finite(info)
        if not bad:
            kept.append(info)
            continue
        left_out.append({"run_id": info.run_id, "unit_serial": info.unit_serial,
                         "campaign_id": info.campaign_id, "started_at": info.started_at,
                         "reason": f"{', '.join(bad)}: not a finite number"})
    return kept, left_out


def unit_tests(runs: list[RunInfo]) -> list[UnitTest]:
    """Group completed runs into unit tests (module doc), oldest test first."""
    tests: dict[str, UnitTest] = {}
    for info in sorted(runs, key=lambda r: r.started_at):
        key = info.campaign_id or info.run_id
        test = tests.get(key)
        if test is None:
            test = tests[key] = UnitTest(key, info.unit_serial, info.started_at,
                                         info.campaign_id)
        test.run_ids.append(info.run_id)
        for metric, (worst, _, _) in METRICS.items():
            value = (info.metrics or {}).get(metric)
            if not isinstance(value, int | float) or isinstance(value, bool):
                continue
            old = test.values.get(metric)
            pick = max if worst == "max" else min
            test.values[metric] = float(value) if old is None else pick(old, float(value))
    for test in tests.values():
        for metric in METRICS:
            test.values.setdefault(metric, None)
    return sorted(tests.values(), key=lambda t: t.started_at)


def _test_outcomes(tests: list[UnitTest], runs: list[RunInfo],
                   campaigns: dict[str, CampaignInfo], members: dict[str, list[RunInfo]]
                   ) -> None:
    """Each unit test's verdict: its campaign's as recorded (read as every view reads it:
    rig/outcome.py), judged from all its runs (``members``, aborted ones too); else its
    single run's."""
    by_run = {r.run_id: r for r in runs}
    for test in tests:
        info = campaigns.get(test.campaign_id or "")
        if info is None:
            test.outcome = by_run[test.run_ids[0]].outcome
            continue
        summary = info.summary or {}
        test.outcome = recorded_campaign_outcome(
            info.meta.get("outcome") or summary.get("outcome"),
            info.meta.get("limits") or summary.get("limits"),
            [r.outcome for r in members.get(info.campaign_id, [])], info.status)


def _design_context(store: Store, runs: list[RunInfo]) -> dict[str, Any]:
    """Limits, unit data, rated torque and profile of a design: from its newest campaign
    with limits (else the newest campaign), the rated torque else from a run.json."""
    limits: dict[str, Any] = {}
    unit: dict[str, Any] = {}
    rated = None
    profile = None
    source = None
    for cid in dict.fromkeys(r.campaign_id for r in runs[::-1] if r.campaign_id):
        meta = store.get_campaign(cid).meta
        if not unit and isinstance(meta.get("unit"), dict):
            unit = meta["unit"]
            profile = meta.get("profile")
        params = (meta.get("plan") or {}).get("params") or {}
        rated = rated if rated is not None else params.get("rated_torque_Nm")
        if isinstance(meta.get("limits"), dict) and any(
                v is not None for v in meta["limits"].values()):
            limits, source = meta["limits"], cid
            unit = meta.get("unit") or unit
            profile = meta.get("profile", profile)
            break
    if rated is None and runs:
        try:
            run_json = json.loads((runs[-1].path / "run.json").read_text(encoding="utf-8"))
            rated = (run_json.get("test") or {}).get("rated_torque_Nm")
            unit = unit or run_json.get("unit") or {}
            profile = profile or run_json.get("profile")
        except (OSError, ValueError):
            pass
    return {"limits": limits, "limits_from_campaign": source, "unit": unit,
            "rated_torque_Nm": rated, "profile": profile}


def _batch(context: dict[str, Any]) -> dict[str, Any]:
    from rig.campaign import batch_band

    unit, rated = context["unit"], context["rated_torque_Nm"]
    if not unit or rated is None:
        return {"band": None, "why": "no unit design data or rated torque in the store"}
    pct = PROFILES.get(context["profile"] or "nabtesco", 3.0)
    try:
        band = batch_band(unit, float(rated), pct)
    except (AnalysisError, ValueError, TypeError) as exc:
        return {"band": None, "why": str(exc)}
    if band is None:
        return {"band": None, "why": "the seed 000 batch model cannot use this unit "
                "(another kind, or design data missing)"}
    return {"band": band, "why": None}


def metric_view(tests: list[UnitTest], metric: str, limits: dict[str, Any]) -> dict[str, Any]:
    """Chart, signals and capability of one metric over the unit tests that have it."""
    _, upper_key, lower_key = METRICS[metric]
    points = [t for t in tests if t.values.get(metric) is not None]
    out: dict[str, Any] = {
        "points": [{"test_id": t.test_id, "unit_serial": t.unit_serial,
                    "started_at": t.started_at, "value": t.values[metric],
                    "verdict": t.to_dict()["verdict"]} for t in points],
        "usl": limits.get(upper_key) if upper_key else None,
        "lsl": limits.get(lower_key) if lower_key else None,
        "chart": None, "capability": None, "error": None,
    }
    if len(points) < 2:
        out["error"] = f"{len(points)} unit test(s) with {metric}: a chart needs 2"
        return out
    chart = imr_chart([t.values[metric] for t in points])
    out["chart"] = chart.to_dict()
    out["capability"] = capability(chart.values, chart.sigma_within,
                                   lsl=out["lsl"], usl=out["usl"])
    for v in out["chart"]["violations"]:
        v["test_id"] = points[v["index"]].test_id
        v["unit_serial"] = points[v["index"]].unit_serial
        v["verdict"] = points[v["index"]].to_dict()["verdict"]
    return out


def newest_metrics(store: Store, runs: list[RunInfo]) -> list[RunInfo]:
    """The runs with their newest re-computed metrics (``rig reanalyse`` after a model or
    software update; the latest by computation time without an error), else as measured.
    """
    newest: dict[str, dict[str, Any]] = {}
    for result in store.results():  # oldest first: later ones replace earlier ones
        if result.get("run_id") and result.get("metrics") and not result.get("error"):
            newest[result["run_id"]] = result
    out = []
    for info in runs:
        result = newest.get(info.run_id)
        if result is not None:
            info = replace(info, metrics={**(info.metrics or {}), **result["metrics"]})
        out.append(info)
    return out


def spc_report(store: Store, *, design: str | None = None, since: str | None = None
               ) -> dict[str, Any]:
    """The ``rig spc --json`` document (module doc)."""
    every = store.list_runs(design=design, since=since)
    measured = [r for r in every if r.status == "completed"]
    campaigns = {c.campaign_id: c for c in store.list_campaigns()}
    members: dict[str, list[RunInfo]] = {}
    for info in every:
        if info.campaign_id:
            members.setdefault(info.campaign_id, []).append(info)
    runs = newest_metrics(store, measured)
    n_reanalysed = sum(a.metrics != b.metrics for a, b in zip(measured, runs, strict=True))
    groups: dict[str, list[RunInfo]] = {}
    for info in runs[::-1]:  # oldest first
        groups.setdefault(info.design or NO_DESIGN, []).append(info)
    designs = []
    excluded_all = []
    for name, all_runs in sorted(groups.items()):
        group, excluded = excluded_runs(all_runs)
        excluded_all += [{"design": name, **e} for e in excluded]
        tests = unit_tests(group)
        _test_outcomes(tests, group, campaigns, members)
        context = _design_context(store, group)
        metrics = {m: metric_view(tests, m, context["limits"]) for m in METRICS}
        batch = _batch(context)
        metrics["lost_motion_arcmin"]["batch"] = batch
        designs.append({
            "design": name, "n_runs": len(group), "n_tests": len(tests),
            "excluded": excluded,
            "limits": context["limits"], "limits_from_campaign": context["limits_from_campaign"],
            "tests": [t.to_dict() for t in tests], "metrics": metrics,
        })
    return {
        "format": SPC_FORMAT, "store": store.location, "design": design, "since": since,
        "constants": {"d2": D2, "D4": D4, "sigma_limits": 3.0},
        "rules": RULES,
        "metrics_source": "the newest re-analysis of each run where one is stored (rig "
                          "reanalyse), else the metrics measured with the run",
        "n_runs_reanalysed": n_reanalysed,
        "point": "one per unit test (a campaign, or a run outside campaigns): the worst run "
                 "(max lost motion and backlash, min stiffness)",
        "designs": designs,
        "excluded": excluded_all,
    }
