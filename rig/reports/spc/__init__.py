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
rig/results/outcome.py): its campaign's, or its single run's.

Per design, for lost motion, backlash and stiffness: the individuals/moving-range chart and
its rule signals (:mod:`analysis.spc`; one-sided, LCL at 0, where the lower 3-sigma limit of
these quantities, which cannot be negative, would fall below zero), Cp/Cpk/Pp/Ppk, and for
lost motion the seed 000 batch band of the design (:func:`rig.plans.campaign_file.batch_band`;
None for
a unit the batch model cannot use). The design is ``unit.design``, else ``unit.model``, else
named by the unit's gear data (kind, teeth, module: :func:`gear_design`); runs with none of
them form the design "(not recorded)".

A design is one build (issue 33 item 17): its runs are grouped by that name *and* by the
build geometry their unit records (:func:`rig.runformat.design.design_key`: teeth, module,
pressure angle, coefficients, face width, center distance, ...; not the inspection data), so
seed 000's pair 1 (center distance 2.5 mm) and pair 3 (2.5222 mm, compensated) are two
designs with their own control limits even where they carry one name or none. Where a name
covers several builds, each is labelled with what differs (``"... [center_distance_mm
2.5222]"``); ``design_key`` and ``design_geometry`` say which build a design is. Runs whose
unit records only part of the geometry (older runs, a unit file without some keys) join the
one build of their name that agrees with every key they do record; if several builds agree
(or none is recorded at all beside a name), they stay a design of their own, labelled with
the keys they lack (``"not recorded"``). ``--design`` takes a name, a label or a key.

Limits: each unit test is charted and judged against its own limits, those of its campaign
(campaign.json ``limits``), or for a run outside campaigns its run.json's. Every point
carries its ``usl``/``lsl``; a metric's ``usl``/``lsl`` and ``capability`` are those common
to all its unit tests, and where the limits differ between unit tests the capability is
given per set of limits (``capability_by_limits``: that set's unit tests, within-sigma of
the whole chart).

The x axis of the charts is the test order within the design (1, 2, ... by start time),
``order`` of each point; the page names each point's unit serial on hover.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from typing import Any

from analysis.errors import AnalysisError
from analysis.loop import PROFILES
from analysis.spc import D2, D4, RULES, capability, imr_chart
from rig.results.outcome import (
    IMPOSSIBLE_BELOW_ZERO,
    finite_number,
    outcome_word,
    recorded_campaign_outcome,
)
from rig.runformat.design import design_geometry, design_key
from rig.store import Store
from rig.store.records import CampaignInfo, RunInfo

SPC_FORMAT = "rig-spc/1"
NO_DESIGN = "(not recorded)"
# metric -> (worst of a unit's runs, limits key of the upper limit, of the lower limit)
METRICS: dict[str, tuple[str, str | None, str | None]] = {
    "lost_motion_arcmin": ("max", "lost_motion_arcmin_max", None),
    "backlash_arcmin": ("max", "backlash_arcmin_max", None),
    "stiffness_Nm_per_arcmin": ("min", None, "stiffness_Nm_per_arcmin_min"),
    "te_pp_arcsec": ("max", "te_pp_max_arcsec", None),
}
"""The charted metrics; ``te_pp_arcsec`` (a transmission error run's peak-to-peak TE, GB/T
35089 transmission accuracy) for the units tested for it."""
LOWER_BOUND: dict[str, float | None] = {
    m: 0.0 if m in IMPOSSIBLE_BELOW_ZERO or m == "te_pp_arcsec" else None for m in METRICS}
"""The smallest value a metric can take (arcmin, N*m/arcmin): none of these is ever
negative, so no chart of them has a lower control limit below 0 (analysis/spc.py)."""
TEETH = (("z_internal", "z_external"), ("z_pinion", "z_gear"))


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
    """The verdict of the unit test (rig/results/outcome.py code; None: not known)."""
    limits: dict[str, Any] = field(default_factory=dict)
    """The limits in force for this unit (its campaign's, or its single run's)."""
    order: int = 0
    """Its place in the design's test order (1 = the first unit tested)."""

    def to_dict(self) -> dict[str, Any]:
        return {"order": self.order, "test_id": self.test_id, "unit_serial": self.unit_serial,
                "started_at": self.started_at, "campaign_id": self.campaign_id,
                "run_ids": self.run_ids, "outcome": self.outcome, "limits": self.limits,
                "verdict": None if self.outcome is None else outcome_word(self.outcome),
                **self.values}


def gear_design(unit: Any) -> str | None:
    """A design named by the unit's gear data where no name is recorded: kind, teeth and
    module (``"internal_involute, 45/40 teeth, module 1 mm"``); None without teeth or
    module."""
    if not isinstance(unit, dict):
        return None
    teeth = next((f"{unit[a]}/{unit[b]} teeth" for a, b in TEETH
                  if isinstance(unit.get(a), int) and isinstance(unit.get(b), int)), None)
    module = unit.get("module_mm")
    module_text = f"module {module:g} mm" if finite_number(module) else None
    if teeth is None and module_text is None:
        return None
    kind = unit.get("kind")
    return ", ".join(p for p in (str(kind) if kind else None, teeth, module_text) if p)


class RunRecords:
    """What the index does not hold of a run: its unit and limits, from its campaign's
    campaign.json (one read for all its runs) or its own run.json (read once)."""

    def __init__(self, campaigns: dict[str, CampaignInfo]) -> None:
        self.campaigns = campaigns
        self._run_json: dict[str, dict[str, Any]] = {}

    def run_json(self, info: RunInfo) -> dict[str, Any]:
        if info.run_id not in self._run_json:
            try:
                meta = json.loads((info.path / "run.json").read_text(encoding="utf-8"))
            except (OSError, ValueError):
                meta = {}
            self._run_json[info.run_id] = meta if isinstance(meta, dict) else {}
        return self._run_json[info.run_id]

    def _campaign_meta(self, info: RunInfo) -> dict[str, Any] | None:
        camp = self.campaigns.get(info.campaign_id or "")
        return None if camp is None else camp.meta

    def unit(self, info: RunInfo) -> dict[str, Any]:
        """The run's ``unit``: its campaign's (campaign.json), else its run.json's."""
        meta = self._campaign_meta(info)
        unit = meta.get("unit") if meta is not None else None
        if not isinstance(unit, dict):
            unit = self.run_json(info).get("unit")
        return unit if isinstance(unit, dict) else {}

    def design(self, info: RunInfo) -> tuple[str, str]:
        """(the design of the run's unit, how it is named: "name", "gear data", "none")."""
        if info.design is not None:
            return str(info.design), "name"
        named = gear_design(self.unit(info))
        return (named, "gear data") if named else (NO_DESIGN, "none")

    def build(self, info: RunInfo) -> tuple[str | None, dict[str, Any]]:
        """(the design key of the run's unit, its build geometry): rig/runformat/design.py."""
        unit = self.unit(info)
        return design_key(unit), design_geometry(unit)

    def limits(self, info: RunInfo) -> dict[str, Any]:
        """The limits in force for the run's unit test: its campaign's (campaign.json, else
        the campaign's summary, else its run.json's), or its own run.json's; only the
        limit keys that are set."""
        camp = self.campaigns.get(info.campaign_id or "")
        found = None
        if camp is not None:
            found = camp.meta.get("limits")
            if not isinstance(found, dict):
                found = (camp.summary or {}).get("limits")
        if not isinstance(found, dict):
            found = self.run_json(info).get("limits")
        keys = {k for _, up, low in METRICS.values() for k in (up, low) if k}
        return {k: v for k, v in (found or {}).items()
                if k in keys and finite_number(v)} if isinstance(found, dict) else {}


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


def unit_tests(runs: list[RunInfo], records: RunRecords | None = None) -> list[UnitTest]:
    """Group completed runs into unit tests (module doc), oldest test first, numbered in
    that order (``order`` 1, 2, ...), each with its own limits (``records``)."""
    tests: dict[str, UnitTest] = {}
    for info in sorted(runs, key=lambda r: r.started_at):
        key = info.campaign_id or info.run_id
        test = tests.get(key)
        if test is None:
            test = tests[key] = UnitTest(
                key, info.unit_serial, info.started_at, info.campaign_id,
                limits=records.limits(info) if records is not None else {})
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
    ordered = sorted(tests.values(), key=lambda t: t.started_at)
    for k, test in enumerate(ordered, start=1):
        test.order = k
    return ordered


def _test_outcomes(tests: list[UnitTest], runs: list[RunInfo],
                   campaigns: dict[str, CampaignInfo], members: dict[str, list[RunInfo]]
                   ) -> None:
    """Each unit test's verdict: its campaign's as recorded (read as every view reads it:
    rig/results/outcome.py), judged from all its runs (``members``, aborted ones too); else its
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
    """Unit data, rated torque and profile of a design for its batch band: from its newest
    campaign with limits (else the newest campaign), the rated torque else from a run.json.
    (The charts judge each unit test by its own limits: :meth:`RunRecords.limits`.)"""
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
    from rig.plans.campaign_file import batch_band

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


def _limit(test: UnitTest, key: str | None) -> float | None:
    return None if key is None else test.limits.get(key)


def metric_view(tests: list[UnitTest], metric: str) -> dict[str, Any]:
    """Chart, signals and capability of one metric over the unit tests that have it, each
    against its own limits (module doc)."""
    _, upper_key, lower_key = METRICS[metric]
    points = [t for t in tests if t.values.get(metric) is not None]
    limit_sets = list(dict.fromkeys((_limit(t, lower_key), _limit(t, upper_key))
                                    for t in points))
    common = limit_sets[0] if len(limit_sets) == 1 else (None, None)
    out: dict[str, Any] = {
        "points": [{"order": t.order, "test_id": t.test_id, "unit_serial": t.unit_serial,
                    "started_at": t.started_at, "value": t.values[metric],
                    "lsl": _limit(t, lower_key), "usl": _limit(t, upper_key),
                    "verdict": t.to_dict()["verdict"]} for t in points],
        "lsl": common[0], "usl": common[1], "limits_differ": len(limit_sets) > 1,
        "lower_bound": LOWER_BOUND[metric],
        "chart": None, "capability": None, "capability_by_limits": [], "error": None,
    }
    if len(points) < 2:
        out["error"] = f"{len(points)} unit test(s) with {metric}: a chart needs 2"
        return out
    chart = imr_chart([t.values[metric] for t in points], lower_bound=LOWER_BOUND[metric])
    out["chart"] = chart.to_dict()
    out["capability"] = capability(chart.values, chart.sigma_within,
                                   lsl=out["lsl"], usl=out["usl"])
    if out["limits_differ"]:
        for lsl, usl in limit_sets:
            values = [t.values[metric] for t in points
                      if (_limit(t, lower_key), _limit(t, upper_key)) == (lsl, usl)]
            out["capability_by_limits"].append(
                capability(values, chart.sigma_within, lsl=lsl, usl=usl))
    for v in out["chart"]["violations"]:
        v["test_id"] = points[v["index"]].test_id
        v["unit_serial"] = points[v["index"]].unit_serial
        v["order"] = points[v["index"]].order
        v["verdict"] = points[v["index"]].to_dict()["verdict"]
    return out


def _limit_sets(tests: list[UnitTest]) -> list[dict[str, Any]]:
    """The distinct limits of a design's unit tests, each with how many tests it applies to
    (first seen first)."""
    sets: dict[str, dict[str, Any]] = {}
    for t in tests:
        key = json.dumps(t.limits, sort_keys=True)
        sets.setdefault(key, {"limits": t.limits, "n_tests": 0})["n_tests"] += 1
    return list(sets.values())


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


@dataclass
class Build:
    """The runs of one design: its name, how it is named, its design key and geometry."""

    name: str
    named_by: str
    key: str | None
    geometry: dict[str, Any]
    runs: list[RunInfo] = field(default_factory=list)
    partial: int = 0
    """Runs that joined from units recording only part of this geometry."""
    label: str = ""

    def agrees(self, geometry: dict[str, Any]) -> bool:
        """Does every key of ``geometry`` (a part of a build's) have this build's value?"""
        return all(k in self.geometry and _same(self.geometry[k], v) for k, v in geometry.items())


def _same(a: Any, b: Any) -> bool:
    """One value of a build key, as :func:`rig.runformat.design.design_key` compares them."""
    if isinstance(a, str) or isinstance(b, str):
        return a == b
    return f"{float(a):.9g}" == f"{float(b):.9g}"


def _geometry_text(key: str, value: Any) -> str:
    return f"{key} not recorded" if value is None else f"{key} {value:g}" if isinstance(
        value, float) else f"{key} {value}"


def builds(runs: list[RunInfo], records: RunRecords) -> list[Build]:
    """The runs (oldest first) grouped into designs: by name and design key (module doc),
    partial geometries joined to the one build of their name that agrees, labelled."""
    found: dict[tuple[str, str, str | None], Build] = {}
    for info in runs:
        name, named_by = records.design(info)
        key, geometry = records.build(info)
        build = found.get((name, named_by, key))
        if build is None:
            build = found[name, named_by, key] = Build(name, named_by, key, geometry)
        build.runs.append(info)
    out = list(found.values())
    for part in sorted(out, key=lambda b: -len(b.geometry)):  # the fullest parts first
        hosts = [b for b in out if b is not part and b.name == part.name
                 and len(b.geometry) > len(part.geometry) and b.agrees(part.geometry)]
        if len(hosts) == 1:
            hosts[0].runs = sorted(hosts[0].runs + part.runs, key=lambda r: r.started_at)
            hosts[0].partial += len(part.runs) + part.partial
            out.remove(part)
    for build in out:
        same = [b for b in out if b.name == build.name]
        if len(same) == 1:
            build.label = build.name
            continue
        keys = sorted({k for b in same for k in b.geometry} - {"kind"})
        differ = [k for k in keys if len({b.geometry.get(k) for b in same}) > 1]
        text = ", ".join(_geometry_text(k, build.geometry.get(k)) for k in differ)
        if not build.geometry:
            text = "no geometry recorded"
        build.label = f"{build.name} [{text or build.key}]"
    return sorted(out, key=lambda b: (b.name, b.runs[0].started_at))


def spc_report(store: Store, *, design: str | None = None, since: str | None = None
               ) -> dict[str, Any]:
    """The ``rig spc --json`` document (module doc). ``design``: a design name, the label of
    one build of it, its design key, or the gear-data name of a design without a name
    (:func:`gear_design`)."""
    campaigns = {c.campaign_id: c for c in store.list_campaigns()}
    records = RunRecords(campaigns)
    every = store.list_runs(since=since)
    measured = [r for r in every if r.status == "completed"]
    members: dict[str, list[RunInfo]] = {}
    for info in every:
        if info.campaign_id:
            members.setdefault(info.campaign_id, []).append(info)
    runs = newest_metrics(store, measured)
    chosen = [b for b in builds(runs[::-1], records)  # oldest first
              if design is None or design in (b.name, b.label, b.key)]
    kept = {r.run_id for b in chosen for r in b.runs}
    n_reanalysed = sum(a.metrics != b.metrics for a, b in zip(measured, runs, strict=True)
                       if a.run_id in kept)
    designs = []
    excluded_all = []
    for build in chosen:
        name, named_by = build.label, build.named_by
        group, excluded = excluded_runs(build.runs)
        excluded_all += [{"design": name, **e} for e in excluded]
        tests = unit_tests(group, records)
        _test_outcomes(tests, group, campaigns, members)
        context = _design_context(store, group)
        metrics = {m: metric_view(tests, m) for m in METRICS}
        batch = _batch(context)
        metrics["lost_motion_arcmin"]["batch"] = batch
        designs.append({
            "design": name, "design_named_by": named_by, "design_name": build.name,
            "design_key": build.key, "design_geometry": build.geometry,
            "n_runs_partial_geometry": build.partial,
            "n_runs": len(group), "n_tests": len(tests), "excluded": excluded,
            "limit_sets": _limit_sets(tests),
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
