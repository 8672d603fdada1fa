"""The test certificate of a unit: one page, HTML and PDF, from a stored run or a campaign.

What it shows comes from the record only (run.json, campaign.json, samples): the header
(:mod:`rig.reports.certificate.header`), the unit data, the sensors with their calibration
references,
the loop, the metrics with their uncertainties against the limits in force, the outcome
(OK / NOT OK / INCOMPLETE / NO LIMITS, rig/results/outcome.py), for a campaign the lost motion
against the input position with the nominal model and the production batch band, and the
diagnosis verdict when one was made for the campaign (a rig-diagnosis/1 file in its folder,
the page's diagnosis cache, or a result of ``rig reanalyse`` in the store). Drawn by the
jinja2 template rig/templates/certificate.html; the PDF by WeasyPrint.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rig.core.errors import RigError
from rig.core.redact import redact
from rig.reports.certificate.header import NOT_RECORDED, header_fields, template_env, utc_text
from rig.results.outcome import (  # the below-zero words: one place for every view
    BELOW_NOTE,
    LIMIT_KEYS,
    OUTCOME_MEANINGS,
    OUTCOME_WORDS,
    below_zero_text,
    finite_number,
    is_te_record,
    metric_check,
    recorded_campaign_outcome,
    recorded_outcome,
    run_outcome,
)
from rig.runformat import CAMPAIGN_JSON, RUN_JSON, Campaign, Run, read_run, read_run_or_campaign
from rig.store import Store
from rig.store.ids import ID_PATTERN, StoreError, UnknownIdError

__all__ = ["CertificateError", "Subject", "certificate_context", "render_certificate",
           "html_to_pdf", "certificate_pdf", "resolve_subject", "write_certificate",
           "certificate_bytes"]

log = logging.getLogger(__name__)

METRIC_VERDICTS = {"ok": "OK", "not_ok": "NOT OK", "not_applicable": "not applicable",
                   "not_measured": "not measured", "not_finite": "not a number"}
"""A metric against its limit (rig/results/outcome.py ``metric_check``), in the result column."""
METRICS = (
    ("lost_motion_arcmin", "lost motion", "arcmin", ".3f"),
    ("backlash_arcmin", "backlash", "arcmin", ".3f"),
    ("stiffness_Nm_per_arcmin", "torsional stiffness", "N·m/arcmin", ".2f"),
    ("loop_area_J", "loop area (hysteresis loss)", "mJ", ".3f"),
    ("torque_offset_Nm", "torque offset", "N·m", ".4f"),
)
"""(result key, label, unit, format) of the metrics on the certificate."""
SHOWN_SCALE = {"loop_area_J": 1e3}
"""Result key -> the factor from the record's unit to the unit shown: the loop area is
recorded in J and shown in mJ, as the control page and ``rig analyse`` show it."""
TE_METRICS = (
    ("te_pp_arcsec", "transmission error, peak-to-peak (GB/T 35089)", "arcsec", ".1f"),
    ("te_pp_forward_arcsec", "  forward", "arcsec", ".1f"),
    ("te_pp_reverse_arcsec", "  reverse", "arcsec", ".1f"),
    ("te_total_Fi_arcsec", "F'i, total single-flank composite (ISO 1328-1)", "arcsec", ".1f"),
    ("te_tooth_fi_arcsec", "f'i, tooth-to-tooth (ISO 1328-1)", "arcsec", ".1f"),
    ("te_hysteresis_arcmin", "hysteresis (lost motion under the brake)", "arcmin", ".3f"),
)
"""The metrics of a transmission error run's certificate (run-format.md)."""
TE_CAMPAIGN_METRICS = tuple({m[0]: m for m in TE_METRICS}[k] for k in (
    "te_pp_arcsec", "te_tooth_fi_arcsec", "te_hysteresis_arcmin", "te_pp_forward_arcsec",
    "te_pp_reverse_arcsec", "te_total_Fi_arcsec"))
"""The same, ordered for a campaign's table (its first three are its columns)."""
LIMIT_OF_METRIC = {metric: (key, side) for key, (metric, side) in LIMIT_KEYS.items()}
DIAGNOSIS_FORMAT = "rig-diagnosis/1"
IN_HEADER = ("serial", "kind", "design")
"""Unit keys the header shows: the unit table leaves them out when the header has their value."""
CALIBRATION_ORDER = ("sensor", "id", "certificate", "date", "due", "due_date", "uncertainty")


class CertificateError(RigError):
    """A certificate cannot be made (no such run or campaign, nothing to certify)."""


@dataclass
class Subject:
    """What a certificate is of: a run or campaign folder, and the store holding it (if known;
    the store is asked only for a campaign's stored diagnosis)."""

    path: Path
    store: Store | None = None


# --------------------------------------------------------------------------- resolving


def resolve_subject(target: str, store: str | Path, samples: str | Path | None = None
                    ) -> Subject:
    """A run or campaign folder path, else a run or campaign id of the store ``store``.
    CertificateError (one line) when it is neither."""
    path = Path(target)
    if path.exists():
        if path.is_file() and path.name in (RUN_JSON, CAMPAIGN_JSON):
            path = path.parent
        if not (path / RUN_JSON).is_file() and not (path / CAMPAIGN_JSON).is_file():
            raise CertificateError(f"{target}: not a run folder (no {RUN_JSON}) or a campaign "
                                   f"folder (no {CAMPAIGN_JSON})")
        return Subject(path.resolve(), _store_beside(path.resolve()))
    if ID_PATTERN.fullmatch(target) is None:
        raise CertificateError(f"{target}: no such run or campaign folder (and not a run or "
                               "campaign id)")
    try:
        st = Store(store, create=False, recover=False, samples=samples)
    except StoreError as exc:
        raise CertificateError(f"{target}: no such folder, and as an id: {exc}") from exc
    try:
        return Subject(st.get_run(target).path, st)
    except UnknownIdError:
        pass
    try:
        return Subject(st.get_campaign(target).path, st)
    except UnknownIdError:
        raise CertificateError(f"{target}: no such folder, and no run or campaign with that id "
                               f"in the store {st.location}") from None


def _store_beside(folder: Path) -> Store | None:
    """The folder store holding ``folder`` (runs/<id>, campaigns/<id>, campaigns/<id>/<run>)."""
    for root in (folder.parent.parent, folder.parent.parent.parent):
        if (root / "index.sqlite").is_file():
            try:
                return Store(root, create=False, recover=False)
            except (StoreError, OSError) as exc:
                log.warning("store at %s not opened: %s", root, exc)
                return None
    return None


def _read(path: Path) -> tuple[Campaign, bool]:
    """The subject as a campaign (a single run as a one-run campaign) and whether it is a
    campaign. A campaign's run folders that campaign.json does not list (aborted runs) are
    read too: the certificate names every run measured."""
    is_camp = (path / CAMPAIGN_JSON).is_file()
    try:
        campaign = read_run_or_campaign(path, allow_truncated_tail=True)
    except RigError:
        if not is_camp:
            raise
        # every run aborted: campaign.json lists none; the record still has a verdict
        meta = json.loads((path / CAMPAIGN_JSON).read_text(encoding="utf-8"))
        if not isinstance(meta, dict) or meta.get("runs"):
            raise
        campaign = Campaign(meta=meta, runs=[], path=path)
    if is_camp:
        listed = {r.path.name for r in campaign.runs if r.path is not None}
        for sub in sorted(p for p in path.iterdir() if p.is_dir() and p.name not in listed):
            if (sub / RUN_JSON).is_file():
                try:
                    campaign.runs.append(read_run(sub, allow_truncated_tail=True))
                except RigError as exc:
                    log.warning("run folder %s not read: %s", sub, exc)
        campaign.runs.sort(key=lambda r: str(r.meta.get("started_at") or ""))
    return campaign, is_camp


# --------------------------------------------------------------------------- figures of a run


def _fmt(value: Any, spec: str) -> str | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return format(value, spec)


def _limit_text(bound: Any, side: str | None, unit: str) -> str | None:
    if bound is None:
        return None
    return f"{'≤' if side == 'above' else '≥'} {bound:g} {unit}"


def _scaled(value: Any, factor: float) -> Any:
    """A recorded number times ``factor`` (to the unit shown); anything else as it is."""
    if factor == 1.0 or isinstance(value, bool) or not isinstance(value, int | float):
        return value
    return value * factor


def _metric_rows(meta: dict[str, Any], metrics: tuple[tuple[str, str, str, str], ...] = METRICS
                 ) -> list[dict[str, Any]]:
    """One row per metric of a run.json: value ± uncertainty, nominal model, limit, verdict;
    ``below`` (with the unit) and ``below_short`` (without) for a metric that cannot be
    negative measured below zero (:func:`below_zero_text`), printed instead of the value."""
    result = meta.get("result") or {}
    unc = result.get("uncertainty") or {}
    model = result.get("model") or {}
    limits = meta.get("limits") or {}
    rows = []
    for key, label, unit, spec in metrics:
        factor = SHOWN_SCALE.get(key, 1.0)
        value = _scaled(result.get(key), factor)
        u = _scaled(unc.get(key), factor)
        limit_key, side = LIMIT_OF_METRIC.get(key, (None, None))
        bound = limits.get(limit_key) if limit_key else None
        check, why = ("", None) if bound is None else metric_check(meta, key, bound, side)
        verdict = METRIC_VERDICTS.get(check, "")
        rows.append({
            "key": key, "label": label, "unit": unit, "value": _fmt(value, spec),
            "uncertainty": _fmt(u, spec) if value is not None else None,
            "below": below_zero_text(key, value, u, spec, f" {unit}"),
            "below_short": below_zero_text(key, value, u, spec, ""),
            "model": _fmt(_scaled(model.get(key), factor), spec),
            "limit": _limit_text(bound, side, unit),
            "verdict": verdict,
            "why": (why if check in ("not_applicable", "not_finite") else None)
            or (result.get("errors") or {}).get(key),
        })
    return rows


def _run_outcome(meta: dict[str, Any], limits: dict[str, Any] | None = None
                 ) -> tuple[str, list[str]]:
    """(outcome, causes) of a run.json as every view reads it (rig/results/outcome.py
    ``recorded_outcome``: an "ok" only where the record's metrics and limits confirm it);
    ``limits``: the campaign's, for a run.json without its own."""
    run_limits = meta.get("limits") if isinstance(meta.get("limits"), dict) else limits
    computed, causes, _ = run_outcome({**meta, "status": meta.get("status") or "completed"},
                                      run_limits)
    outcome = recorded_outcome(meta, limits)
    return (outcome if outcome in OUTCOME_WORDS else computed), causes


def _value_text(value: Any) -> str:
    if isinstance(value, list | tuple):
        return ", ".join(_value_text(v) for v in value)
    if isinstance(value, dict):
        return "; ".join(f"{k}: {_value_text(v)}" for k, v in value.items())
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


CALIBRATION_HEADINGS = {"sensor": "sensor", "id": "id / serial", "certificate": "certificate",
                        "date": "calibrated", "due": "due", "due_date": "due",
                        "uncertainty": "uncertainty"}
"""run.json calibration key -> its column heading on the certificate (others: the key)."""


def _calibration(meta: dict[str, Any]) -> dict[str, Any]:
    """The run's calibration references as a table: a list of ``{"sensor": ..}`` entries or a
    mapping sensor -> entry; with the messages of calibrations past due at the start (those
    rows' due dates marked) and the override (reason, operator, time) when one was given."""
    from rig.store.records import past_due

    raw = meta.get("calibration")
    entries: list[dict[str, Any]] = []
    if isinstance(raw, dict):
        for name, entry in raw.items():
            entries.append({"sensor": name, **entry} if isinstance(entry, dict)
                           else {"sensor": name, "reference": entry})
    elif isinstance(raw, list):
        entries = [e for e in raw if isinstance(e, dict)]
    keys = list(dict.fromkeys(k for e in entries for k in e))
    columns = [k for k in CALIBRATION_ORDER if k in keys] + \
        [k for k in keys if k not in CALIBRATION_ORDER]
    rows = []
    for entry in entries:
        due = entry.get("due") or entry.get("due_date")
        try:
            late = bool(due) and bool(past_due([{"sensor": entry.get("sensor"), "due": due}],
                                               meta.get("started_at")))
        except ValueError:
            late = False
        rows.append({"cells": [_value_text(entry[k]) if entry.get(k) is not None else ""
                               for k in columns], "past_due": late})
    due = [{"sensor": e.get("sensor"), "due": e.get("due") or e.get("due_date")}
           for e in entries if e.get("due") or e.get("due_date")]
    try:
        warnings = past_due(due, meta.get("started_at"))
    except ValueError:
        warnings = []
    return {"columns": columns, "headings": [CALIBRATION_HEADINGS.get(k, k) for k in columns],
            "rows": rows, "warnings": warnings,
            "override": _override(meta.get("calibration_override"), bool(warnings))}


def _override(override: Any, warned: bool) -> dict[str, Any] | None:
    """run.json ``calibration_override`` (rig/hardware/calibration.py: reason, operator, time,
    expired; or a bare reason) for the template; the ``expired`` messages only where the
    past-due lines above do not say it already."""
    if override in (None, False, ""):
        return None
    if not isinstance(override, dict):
        return {"reason": _value_text(override), "operator": None, "time": None, "more": []}
    more = [f"{k}: {_value_text(v)}" for k, v in override.items()
            if k not in ("reason", "operator", "time") and v not in (None, "", [])
            and not (k == "expired" and warned)]
    time = override.get("time")
    return {"reason": _value_text(override.get("reason")) if override.get("reason") is not None
            else "not recorded",
            "operator": _value_text(override["operator"]) if override.get("operator") else None,
            "time": utc_text(time) if time else None, "more": more}


VERDICT_WEIGHT = {"not_ok": 0, "incomplete": 1}
"""Which runs a campaign's verdict rests on: its NOT OK runs, else its INCOMPLETE ones, else all."""


def verdict_run(runs: list[Run], outcomes: list[str]) -> int | None:
    """The index of the run a campaign's verdict rests on: of the runs with the worst outcome
    (NOT OK, else INCOMPLETE, else any), the one with the largest recorded lost motion
    (arcmin); None for no runs or none with a recorded lost motion."""
    if not runs:
        return None
    worst = min(VERDICT_WEIGHT.get(o, 2) for o in outcomes)

    def lost_motion(i: int) -> float:
        value = (runs[i].meta.get("result") or {}).get("lost_motion_arcmin")
        return float(value) if finite_number(value) else float("-inf")

    best = max((i for i, o in enumerate(outcomes) if VERDICT_WEIGHT.get(o, 2) == worst),
               key=lost_motion)
    return best if lost_motion(best) > float("-inf") else None


def _loop_figure(runs: list[Run], title: str | None, rests_on: int | None = None
                 ) -> tuple[str | None, list[str], list[Any]]:
    """The loops of the runs that can be analysed (SVG URI), why the others cannot, and the
    analyses. ``rests_on``: the index (in ``runs``) of the run whose figures the box shows,
    named "worst run" (a campaign's :func:`verdict_run`); else the box's default."""
    from rig.reports.certificate.plots import loop_svg
    from rig.reports.loop_plots import run_name, worst_run
    from rig.results.analyse import analyse_run

    items, notes, box = [], [], None
    for i, run in enumerate(runs):
        try:
            items.append(analyse_run(run, profile=run.meta.get("profile")))
        except Exception as exc:  # an aborted or short run has no loop to draw
            notes.append(f"run {run.meta.get('label') or run.run_id}: no loop drawn ({exc})")
            continue
        if i == rests_on:
            box = len(items) - 1
    if not items:
        return None, notes, []
    heading = None
    if rests_on is not None and len(runs) > 1:
        if box is not None:
            heading = f"worst run: {run_name(runs[rests_on].meta, runs[rests_on].run_id)}"
        else:  # its loop cannot be drawn: the box says whose figures it shows instead
            box = worst_run(items)
            heading = ("largest lost motion drawn: "
                       f"{run_name(items[box].run.meta, items[box].run.run_id)}")
    return loop_svg(items, title=title, box=box, box_heading=heading), notes, items


def _te_section(run: Run) -> dict[str, Any] | None:
    """A transmission error run's section: its TE curve (SVG URI) with the peak-to-peak
    limit, the largest orders, the encoder eccentricity removed, and ``meta`` with ``result``
    (the record's own, or computed now when it has none)."""
    from rig.reports.certificate.plots import svg_uri
    from rig.reports.te_plots import plot_te
    from rig.results.te import analyse_te_run

    meta = dict(run.meta)
    try:
        item = analyse_te_run(run, with_model=False)
    except Exception as exc:  # an aborted or short run has no curve to draw
        return {"meta": meta, "figure": None, "orders": [], "eccentricity": None,
                "notes": [f"no TE curve drawn ({exc})"]}
    result = meta.get("result") or {}
    if result.get("te_pp_arcsec") is None:
        meta["result"] = {**item.result_record(), **result}
        result = meta["result"]
    limit = (meta.get("limits") or {}).get("te_pp_max_arcsec")
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        path = plot_te(item, Path(tmp) / "te.svg", title="",
                       limit_arcsec=float(limit) if finite_number(limit) else None)
        figure = svg_uri(path.read_bytes())
    orders = sorted((o for o in result.get("te_orders") or []
                     if o.get("direction") == "forward"),
                    key=lambda o: -float(o.get("amplitude_arcsec") or 0.0))[:5]
    ecc = result.get("encoder_eccentricity") or {}
    test = meta.get("test") or {}
    return {"meta": meta, "figure": figure, "notes": [],
            "orders": [f"{o['order']:g}/{str(o['per']).replace('_', ' ')}: "
                       f"{o['amplitude_arcsec']:.1f}″ at {o['phase_deg']:.0f}°" for o in orders],
            "eccentricity": (f"encoder eccentricity {ecc['amplitude_arcsec']:.1f}″ removed "
                             f"({ecc.get('source', 'calibration')})" if ecc.get("removed")
                             else "encoder eccentricity not removed (no calibration)"),
            "conditions": (f"input {test.get('input_speed_rpm', '?')} rpm, brake "
                           f"{test.get('brake_torque_Nm', '?')} N·m, ratio "
                           f"{test.get('ratio', '?')}")}


# --------------------------------------------------------------------------- campaign


def _drawn_model(analyses: list[Any]) -> float | None:
    """The nominal model's lost motion (arcmin) of the first drawn loop that has one: what the
    loop figure's model line and box show."""
    for item in analyses:
        model = item.to_dict().get("model") or {}
        if finite_number(model.get("lost_motion_arcmin")):
            return float(model["lost_motion_arcmin"])
    return None


def _position_figure(campaign: Campaign, runs: list[Run], limits: dict[str, Any],
                     drawn_model: float | None = None) -> dict[str, Any]:
    """Lost motion against the input position with the nominal model and the batch band of the
    design: the band as the campaign stored it (``summary.batch``), else computed the same way
    (:func:`rig.plans.campaign_file.batch_band`). The model as recorded (the summary's, else a
    run's), else ``drawn_model`` (arcmin: the loop figure's, as for an aborted campaign whose
    runs were not analysed when it stopped)."""
    from rig.reports.certificate.plots import position_svg

    summary = campaign.meta.get("summary") or {}
    points = []
    for run in runs:
        result = run.meta.get("result") or {}
        angle = (run.meta.get("test") or {}).get("input_angle_deg")
        value = result.get("lost_motion_arcmin")
        if isinstance(angle, int | float) and isinstance(value, int | float):
            points.append({"input_angle_deg": float(angle), "lost_motion_arcmin": float(value),
                           "uncertainty": (result.get("uncertainty") or {}).get(
                               "lost_motion_arcmin")})
    model = (summary.get("model") or {}).get("lost_motion_arcmin")
    if model is None:
        models = (((r.meta.get("result") or {}).get("model") or {}).get("lost_motion_arcmin")
                  for r in runs)
        model = next((m for m in models if m is not None), drawn_model)
    # the band as the campaign stored it (None: the batch model cannot use this unit)
    batch = summary["batch"] if "batch" in summary else _batch_band(campaign, runs)
    kind = str((campaign.meta.get("unit") or (runs[0].meta.get("unit") if runs else None)
                or {}).get("kind") or "internal_involute")
    from analysis.models.by_kind import MODEL_NAMES

    names = MODEL_NAMES.get(kind, (f"nominal model of kind {kind}", "the design's tolerances"))
    out: dict[str, Any] = {"figure": None, "batch": batch, "model": _fmt(model, ".3f"),
                           "n_points": len(points), "kind": kind, "model_name": names[0],
                           "band_source": names[1], "advice": _advice_text(batch),
                           "relation": (batch or {}).get("nominal_relation")}
    if points:
        out["figure"] = position_svg(points, model, batch, limits.get("lost_motion_arcmin_max"))
    if batch and batch.get("band_95_arcmin"):
        low, high = batch["band_95_arcmin"]
        out["band"] = f"{low:.3f} .. {high:.3f} arcmin"
    return out


def _run_design(meta: dict[str, Any]) -> dict[str, Any]:
    """A single run's unit kind, its nominal model (name, lost motion at the run's profile)
    and its batch band (:func:`rig.plans.campaign_file.batch_band` at the run's rated torque), as a
    campaign's position figure names them."""
    from analysis.loop import PROFILES
    from analysis.models.by_kind import MODEL_NAMES
    from rig.plans.campaign_file import batch_band

    unit = meta.get("unit") or {}
    result = meta.get("result") or {}
    kind = str(unit.get("kind") or "internal_involute")
    names = MODEL_NAMES.get(kind, (f"nominal model of kind {kind}", "the design's tolerances"))
    rated = (meta.get("test") or {}).get("rated_torque_Nm")
    pct = result.get("lost_motion_pct") or PROFILES.get(result.get("profile") or "nabtesco", 3.0)
    batch = None
    if unit and isinstance(rated, int | float) and rated > 0:
        try:
            batch = batch_band(unit, float(rated), float(pct))
        except (RigError, ValueError, TypeError) as exc:
            log.warning("no batch band: %s", exc)
    out: dict[str, Any] = {"kind": kind, "model_name": names[0], "band_source": names[1],
                           "model": _fmt((result.get("model") or {}).get("lost_motion_arcmin"),
                                         ".3f"),
                           "band": None, "advice": _advice_text(batch),
                           "relation": (batch or {}).get("nominal_relation")}
    if batch and batch.get("band_95_arcmin"):
        low, high = batch["band_95_arcmin"]
        out["band"] = f"{low:.3f} .. {high:.3f} arcmin"
    return out


def _advice_text(batch: dict[str, Any] | None) -> str | None:
    """The compensation advice of a cycloid or beveloid batch band, in words (None: none)."""
    advice = (batch or {}).get("advice") or {}
    band = advice.get("band_95_arcmin")
    if not band:
        return None
    if "rotation_modification_mm" in advice:
        what = f"rotation modification Delta2 = {advice['rotation_modification_mm']:.4f} mm"
    elif "axial_shift_mm" in advice:
        what = f"gear axial position {advice['axial_shift_mm']:+.3f} mm"
    else:
        return None
    return (f"{what} gives {band[0]:.3f} .. {band[1]:.3f} arcmin with at most "
            f"{100 * advice.get('binding_fraction', 0.0):.1f} % of units binding")


def _batch_band(campaign: Campaign, runs: list[Run]) -> dict[str, Any] | None:
    from analysis.loop import PROFILES
    from rig.plans.campaign_file import batch_band

    unit = campaign.meta.get("unit") or (runs[0].unit if runs else {})
    rated = next((r.test.get("rated_torque_Nm") for r in runs
                  if r.test.get("rated_torque_Nm")), None)
    if not unit or rated is None:
        return None
    try:
        return batch_band(unit, float(rated),
                          PROFILES.get(campaign.meta.get("profile") or "nabtesco", 3.0))
    except (RigError, ValueError, TypeError) as exc:
        log.warning("no batch band: %s", exc)
        return None


def _diagnosis_line(folder: Path, campaign_id: str | None, store: Store | None) -> str | None:
    """The verdict of a diagnosis made for this campaign, in one line; None if none was."""
    found: list[tuple[dict[str, Any], str]] = []
    for path in sorted(folder.glob("*.json")):
        if path.name == CAMPAIGN_JSON:
            continue
        doc = _json_or_none(path)
        if doc is not None and doc.get("format") == DIAGNOSIS_FORMAT:
            found.append((doc, f"{path.name} in the campaign folder"))
    if campaign_id and store is not None:
        cached = _json_or_none(store.root / "web" / "diagnosis" / f"{campaign_id}.json")
        if cached is not None:
            found.append((cached, "the control page's diagnosis"))
        try:
            results = store.results(campaign_id=campaign_id)
        except (StoreError, ValueError) as exc:
            log.warning("stored results of %s not read: %s", campaign_id, exc)
            results = []
        for res in results[::-1]:
            if isinstance(res.get("diagnosis"), dict):
                found.append((res["diagnosis"], f"rig reanalyse, backlash-rig "
                              f"{res.get('software_version')}, {res.get('computed_at')}"))
                break
    for doc, source in found:
        verdict = doc.get("verdict")
        if isinstance(verdict, str) and verdict:
            reason = doc.get("reason")
            text = f"{verdict}" + (f" — {reason}" if reason else "")
            return f"{text} (from {source})"
    return None


def _json_or_none(path: Path) -> dict[str, Any] | None:
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return doc if isinstance(doc, dict) else None


# --------------------------------------------------------------------------- the page


def certificate_context(subject: Subject) -> dict[str, Any]:
    """Everything the template draws, from the subject's record."""
    campaign, is_camp = _read(subject.path)
    runs = campaign.runs
    first = runs[0].meta if runs else {}
    ctx: dict[str, Any] = {"is_campaign": is_camp, "folder": str(subject.path)}
    if is_camp:
        cmeta = campaign.meta
        summary = cmeta.get("summary") or {}
        ctx["header"] = header_fields(first, cmeta)
        limits = cmeta.get("limits") or summary.get("limits") or first.get("limits") or {}
        te_camp = bool(runs) and all(is_te_record(r.meta) for r in runs)
        metas = [r.meta for r in runs]
        if te_camp:  # a transmission error campaign: each run's TE, the first one's curve
            sections = [_te_section(r) for r in runs]
            metas = [s.pop("meta") for s in sections]
            ctx["te"] = sections[0]
        run_outcomes = [_run_outcome(meta, limits) for meta in metas]
        rests_on = verdict_run(runs, [o for o, _ in run_outcomes])
        outcome = recorded_campaign_outcome(
            cmeta.get("outcome") or summary.get("outcome"), limits,
            [o for o, _ in run_outcomes], str(cmeta.get("status") or "completed"))
        if outcome not in OUTCOME_WORDS:  # another lab's word: judged from the runs
            outcome = recorded_campaign_outcome(None, limits, [o for o, _ in run_outcomes],
                                                str(cmeta.get("status") or "completed"))
        causes = list(summary.get("failures") or [c for _, cs in run_outcomes for c in cs])
        if cmeta.get("status") not in (None, "completed") and not summary.get("failures"):
            causes.append(f"campaign {cmeta.get('status')}: "
                          f"{summary.get('reason') or cmeta.get('reason') or 'no reason given'}")
        ctx["runs"] = [{
            "label": r.meta.get("label") or r.run_id, "run_id": r.run_id,
            "position": _fmt((r.meta.get("test") or {}).get("input_angle_deg"), "g"),
            "status": r.meta.get("status"), "metrics": {m["key"]: m for m in _metric_rows(
                meta, TE_CAMPAIGN_METRICS if te_camp else METRICS)},
            "outcome": OUTCOME_WORDS[o],
        } for r, meta, (o, _) in zip(runs, metas, run_outcomes, strict=True)]
        for r in ctx["runs"]:
            r["below_any"] = any(m["below"] for m in r["metrics"].values())
        below = any(r["below_any"] for r in ctx["runs"])
        title = f"campaign {cmeta.get('name') or campaign.name}"
        drawn: list[Any] = []
        if not te_camp:
            ctx["loop"], ctx["loop_notes"], drawn = _loop_figure(runs, title, rests_on)
        ctx["position"] = (_position_figure(campaign, runs, limits, _drawn_model(drawn))
                           if not te_camp else {"figure": None, "model": None, "band": None})
        n_runs = len(runs)
        ctx["campaign_line"] = f"campaign of {n_runs} run{'' if n_runs == 1 else 's'}" + (
            f", {cmeta['status']}" if cmeta.get("status") not in (None, "completed") else "")
        lm = summary.get("lost_motion_arcmin") or {}
        ctx["lm_summary"] = {k: below_zero_text("lost_motion_arcmin", lm.get(k), None, "", "")
                             or _fmt(lm.get(k), ".3f") for k in ("mean", "min", "max", "std")}
        ctx["lm_summary"]["n"] = lm.get("n")
        sig = summary.get("runout_signature") or None
        ctx["runout"] = None if not sig else (
            f"{sig['amplitude']:.3f} arcmin at {sig['phase_deg']:.0f} deg "
            f"(residual {sig['residual_rms']:.3f} arcmin)")
        ctx["diagnosis"] = _diagnosis_line(subject.path, cmeta.get("campaign_id"),
                                           subject.store)
        unit = cmeta.get("unit") or first.get("unit") or {}
    else:
        meta = first
        te = _te_section(runs[0]) if runs and is_te_record(meta) else None
        if te is not None:
            meta = te.pop("meta")
        ctx["te"] = te
        ctx["header"] = header_fields(meta)
        limits = meta.get("limits") or {}
        outcome, causes = _run_outcome(meta)
        ctx["metrics"] = _metric_rows(meta, TE_METRICS if te is not None else METRICS)
        below = any(m["below"] for m in ctx["metrics"])
        ctx["run"] = {"label": meta.get("label"), "status": meta.get("status"),
                      "reason": meta.get("reason"),
                      "position": _fmt((meta.get("test") or {}).get("input_angle_deg"), "g")}
        ctx["diagnosis"] = None
        unit = meta.get("unit") or {}
        ctx["design"] = _run_design(meta) if te is None else None
    ctx.setdefault("te", None)
    ctx.setdefault("design", None)
    ctx["metric_heads"] = [{"key": k, "label": label.strip(), "unit": u,
                            "limit": _limit_text(limits.get(LIMIT_OF_METRIC[k][0]),
                                                 LIMIT_OF_METRIC[k][1], u)
                            if k in LIMIT_OF_METRIC else None}
                           for k, label, u, _ in (
                               (TE_CAMPAIGN_METRICS if is_camp else TE_METRICS) if ctx["te"]
                               else METRICS)]
    ctx["limits"] = [h for h in ctx["metric_heads"] if h["limit"]]
    ctx["below_note"] = BELOW_NOTE if below else None
    ctx["outcome"] = outcome
    ctx["outcome_word"] = OUTCOME_WORDS[outcome]
    ctx["outcome_meaning"] = OUTCOME_MEANINGS[outcome]
    ctx["causes"] = causes
    ctx["unit"] = _pairs([(k, _value_text(v)) for k, v in unit.items()
                          if k not in IN_HEADER or ctx["header"].get(k) != _value_text(v)])
    ctx["sensors"] = [(k, _value_text(v)) for k, v in (first.get("sensors") or {}).items()]
    ctx["calibration"] = _calibration(first)
    ctx["test"] = _test_line(first)
    if ctx["te"]:
        ctx["loop"], ctx["loop_notes"] = ctx["te"]["figure"], ctx["te"]["notes"]
    elif not is_camp:
        ctx["loop"], ctx["loop_notes"], drawn = _loop_figure(runs, None)
        if ctx["design"] is not None and ctx["design"]["model"] is None:
            ctx["design"]["model"] = _fmt(_drawn_model(drawn), ".3f")
    ctx["not_recorded"] = NOT_RECORDED
    return ctx


SHORT_VALUE = 16
"""A unit value up to this many characters shares its table row with another."""


def _pairs(items: list[tuple[str, str]]) -> list[list[tuple[str, str]]]:
    """The unit table's rows: two short (key, value) items side by side, a long value (a list
    of measurements, notes) on a row of its own; in the record's order as far as that allows."""
    rows: list[list[tuple[str, str]]] = []
    pending: tuple[str, str] | None = None
    for item in items:
        if len(item[1]) > SHORT_VALUE:
            rows.append([item])
        elif pending is None:
            pending = item
        else:
            rows.append([pending, item])
            pending = None
    if pending is not None:
        rows.append([pending])
    return rows


def _test_line(meta: dict[str, Any]) -> str | None:
    test = meta.get("test") or {}
    parts = []
    if test.get("rated_torque_Nm") is not None:
        parts.append(f"rated torque {test['rated_torque_Nm']:g} N·m")
    if test.get("amplitude_pct") is not None:
        parts.append(f"amplitude {test['amplitude_pct']:g} % of rated")
    loading = test.get("loading") or {}
    if loading.get("mode"):
        parts.append(f"loading {loading['mode']}")
    if loading.get("sequence"):
        parts.append(str(loading["sequence"]))
    if test.get("temperature_C") is not None:
        parts.append(f"housing {test['temperature_C']:.1f} °C")
    return ", ".join(parts) or None


FIGURE_HEIGHTS_MM = (85, 75, 65, 55, 45)
"""Heights of the loop figure (mm) the PDF tries, largest first, until the page is one A4
page; the HTML certificate uses the first."""


def render_certificate(context: dict[str, Any], figure_mm: float = FIGURE_HEIGHTS_MM[0]) -> str:
    """The certificate page (self-contained HTML: figures inline, no external resources);
    ``figure_mm``: the height of the loop figure (and the largest of a campaign's figures)."""
    return template_env().get_template("certificate.html").render(
        **{**context, "figure_mm": figure_mm})


def html_to_pdf(html: str) -> bytes:
    """The page as PDF (WeasyPrint, A4)."""
    return _weasyprint().HTML(string=html).write_pdf()


def certificate_pdf(context: dict[str, Any]) -> bytes:
    """The certificate as a PDF of one A4 page: laid out with the loop figure at each height
    of :data:`FIGURE_HEIGHTS_MM` until the page holds everything (a campaign of many runs or
    a record with very many calibration entries may still need a second page)."""
    weasyprint = _weasyprint()
    document = None
    for height in FIGURE_HEIGHTS_MM:
        document = weasyprint.HTML(string=render_certificate(context, height)).render()
        if len(document.pages) == 1:
            break
    assert document is not None
    return document.write_pdf()


def _weasyprint() -> Any:
    try:
        import weasyprint
    except (ImportError, OSError) as exc:  # OSError: pango missing
        raise CertificateError(f"the PDF needs WeasyPrint and pango: {exc}") from exc
    return weasyprint


def write_certificate(subject: Subject, pdf: Path | None = None, html: Path | None = None
                      ) -> dict[str, Any]:
    """Write the certificate as PDF and/or HTML; return its context (outcome, header ...)."""
    context = certificate_context(subject)
    page = render_certificate(context)
    for path, data in ((html, page.encode("utf-8")), (pdf, certificate_pdf(context) if pdf
                                                       else b"")):
        if path is None:
            continue
        if not path.parent.is_dir():  # a mistyped folder is not made: said (rig certificate)
            raise CertificateError(f"{path}: no folder {path.parent} to write into")
        try:
            path.write_bytes(data)
        except OSError as exc:
            raise CertificateError(f"{path}: cannot write: {exc.strerror or exc}") from exc
    return context


def certificate_bytes(folder: str, store_root: str | None, samples: str | None, fmt: str
                      ) -> bytes:
    """The certificate of a run or campaign folder as ``fmt`` ("pdf" or "html") bytes; for a
    worker process (arguments are plain strings). ``store_root``: the store (folder or URL)."""
    store = None
    if store_root is not None:
        try:
            store = Store(store_root, create=False, recover=False, samples=samples)
        except StoreError as exc:
            log.warning("store %s not opened: %s", redact(store_root), redact(str(exc)))
    context = certificate_context(Subject(Path(folder), store))
    return certificate_pdf(context) if fmt == "pdf" else render_certificate(context).encode()
