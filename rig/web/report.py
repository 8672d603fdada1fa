"""The diagnosis report of a campaign as an HTML page.

The project's report writer (:mod:`rig.reports.diagnosis_html`) draws it;
:func:`plain_report_html` is
the fallback for a report that page cannot draw (plain tables of the rig-diagnosis/1 keys).
"""

from __future__ import annotations

import html
import json
import logging
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)


def diagnose_campaign_folder(campaign_path: Path) -> tuple[dict[str, Any], str]:
    """Diagnose the campaign folder: its rig-diagnosis/1 report (JSON-safe) and the HTML page
    of :func:`rig.reports.diagnosis_html.render_html` (figures inline); the plain tables of
    :func:`plain_report_html` if that page cannot be drawn for this report."""
    from rig.core.json_files import json_safe
    from rig.reports.certificate.header import header_for_campaign
    from rig.reports.diagnosis_html import render_html
    from rig.results.diagnose import diagnose_path, report_dict

    campaign, diagnosis = diagnose_path(campaign_path)
    report = json_safe(report_dict(campaign, diagnosis))
    try:
        page = render_html(report, diagnosis, header_for_campaign(campaign))
    except (KeyError, TypeError, ValueError) as exc:
        log.warning("diagnosis page of %s drawn as plain tables: %s", campaign_path, exc)
        page = plain_report_html(report)
    return report, page


def _cell(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, dict | list):
        return html.escape(json.dumps(value))
    return html.escape(str(value))


def plain_report_html(report: dict[str, Any]) -> str:
    """The report's keys as HTML tables (no scripts, no external resources)."""
    esc = html.escape
    rows = []
    for key in ("campaign", "verdict", "model_effects", "gap_before", "localization",
                "candidates", "next_experiment"):
        if key in report:
            rows.append(f"<tr><th>{esc(key)}</th><td>{_cell(report[key])}</td></tr>")
    ranking = "".join(
        f"<tr><td>{_cell(r.get('effect'))}</td><td>{_cell(r.get('shrink'))}</td>"
        f"<td>{_cell(r.get('gap_after'))}</td><td>{_cell(r.get('params'))}</td></tr>"
        for r in report.get("ranking", []) if isinstance(r, dict))
    return (
        "<!doctype html><html><head><meta charset='utf-8'><title>Diagnosis "
        f"{esc(str(report.get('campaign', '')))}</title><style>body{{font-family:sans-serif;"
        "margin:2em}}table{border-collapse:collapse}td,th{border:1px solid #bbb;"
        "padding:4px 8px;text-align:left}</style></head><body>"
        f"<h1>Diagnosis: {esc(str(report.get('campaign', '')))}</h1>"
        f"<table>{''.join(rows)}</table><h2>Effects ranked</h2><table><tr><th>effect</th>"
        f"<th>shrink</th><th>gap after</th><th>parameters</th></tr>{ranking}</table>"
        "</body></html>")
