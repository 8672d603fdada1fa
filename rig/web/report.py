"""The diagnosis report of a campaign as an HTML page.

Uses the project's report writer (:mod:`rig.report_html`) when it is installed; otherwise
renders the rig-diagnosis/1 keys as plain tables (verdict, gaps, ranking, localisation).
"""

from __future__ import annotations

import html
import json
from pathlib import Path
from typing import Any


def diagnosis_html(campaign_path: Path, report: dict[str, Any]) -> str:
    """An HTML page for ``report`` (rig-diagnosis/1) of the campaign at ``campaign_path``."""
    try:
        from rig import report_html
    except ImportError:
        report_html = None
    render = getattr(report_html, "report_html", None) if report_html else None
    if callable(render):
        try:
            return str(render(campaign_path, report))
        except TypeError:
            pass
    return plain_report_html(report)


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
