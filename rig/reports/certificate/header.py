"""The header of a test certificate and of the diagnosis page: who, what, when, where, with what.

One partial (rig/templates/certificate_header.html) draws it for both. The fields come from
what the record says: run.json and campaign.json (``unit``, ``operator``, ``started_at``,
``rig_id``/``rig_name``, ``software_version``); a field the record lacks reads "not recorded".
"""

from __future__ import annotations

import re
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING, Any

from markupsafe import Markup, escape

from rig import __version__

if TYPE_CHECKING:
    from jinja2 import Environment

    from rig.runformat import Campaign

TEMPLATES = Path(__file__).resolve().parents[2] / "templates"
NOT_RECORDED = "not recorded"
LONGEST_UNBROKEN_WORD = 40
"""Words (runs of non-space characters) up to this many characters are never broken across
lines on a certificate; a longer one may be, so that it cannot run off the page."""
_SPACES = re.compile(r"(\s+)")
_NO_BREAK_INSIDE = re.compile(r"[\w.,:;'\"()\[\]]*")
"""A word of only these characters offers the line breaker no place to break (UAX #14)."""


def whole_words(value: Any) -> Markup:
    """``value`` as escaped HTML that wraps at spaces only. A word of up to
    :data:`LONGEST_UNBROKEN_WORD` characters that holds a hyphen, a slash or another place
    the line breaker would break at goes in a ``<span class="w">`` (``white-space:
    nowrap``): "SN-CERT-1", "D-K-15070" or "2026-01-15" never break at their hyphens (a break
    there also makes ``pdftotext`` drop the hyphen). A longer word goes in a ``<span
    class="long">`` (``overflow-wrap: anywhere``) so that it stays on the page."""
    out = []
    for part in _SPACES.split(str(value)):
        if not part:
            continue
        if part.isspace():
            out.append(Markup(" "))
        elif len(part) > LONGEST_UNBROKEN_WORD:
            out.append(Markup('<span class="long">%s</span>') % part)
        elif _NO_BREAK_INSIDE.fullmatch(part):
            out.append(escape(part))
        else:
            out.append(Markup('<span class="w">%s</span>') % part)
    return Markup("").join(out) if out else escape("")


def software_version() -> str:
    """The installed backlash-rig version (importlib.metadata), else the package's own."""
    try:
        return metadata.version("backlash-rig")
    except metadata.PackageNotFoundError:
        return __version__


def template_env() -> Environment:
    """The jinja2 environment of rig/templates: every value HTML-escaped, whatever the
    template's file name (not ``select_autoescape()``, which skips ``.j2``); the filter
    ``words`` (:func:`whole_words`) keeps words whole on the page."""
    from jinja2 import Environment, FileSystemLoader, StrictUndefined

    env = Environment(loader=FileSystemLoader(TEMPLATES), autoescape=True,
                      undefined=StrictUndefined)
    env.filters["words"] = whole_words
    return env


def _text(value: Any) -> str | None:
    if value is None or (isinstance(value, str) and not value.strip()):
        return None
    return str(value)


def _first(*values: Any) -> str:
    return next((t for t in map(_text, values) if t is not None), NOT_RECORDED)


def utc_text(stamp: Any) -> str:
    """``2026-11-25T08:26:49Z`` as ``2026-11-25 08:26:49 UTC``."""
    text = _text(stamp)
    if text is None:
        return NOT_RECORDED
    return text.replace("T", " ").removesuffix("Z") + (" UTC" if text.endswith("Z") else "")


def header_fields(run_meta: dict[str, Any], campaign_meta: dict[str, Any] | None = None,
                  ) -> dict[str, str]:
    """The header of one run (``run_meta``: its run.json) or of a campaign (``campaign_meta``:
    campaign.json, ``run_meta`` one of its runs, or {} when it has none)."""
    camp = campaign_meta or {}
    unit = camp.get("unit") if isinstance(camp.get("unit"), dict) else None
    if unit is None:
        unit = run_meta.get("unit") if isinstance(run_meta.get("unit"), dict) else {}
    if campaign_meta is not None:
        subject = f"campaign {_first(camp.get('campaign_id'), camp.get('name'))}"
        started = camp.get("started_at") or run_meta.get("started_at")
        finished = camp.get("finished_at") or run_meta.get("finished_at")
    else:
        subject = f"run {_first(run_meta.get('run_id'))}"
        started, finished = run_meta.get("started_at"), run_meta.get("finished_at")
    measured_with = _text(run_meta.get("software_version"))
    return {
        "subject": subject,
        "serial": _first(unit.get("serial")),
        "kind": _first(unit.get("kind")),
        "design": _first(unit.get("design"), unit.get("model"), unit.get("name")),
        "operator": _first(run_meta.get("operator"), camp.get("operator")),
        "date": utc_text(started),
        "finished": utc_text(finished),
        "rig": _first(run_meta.get("rig_name"), run_meta.get("rig_id"), camp.get("rig_name"),
                      camp.get("rig_id")),
        "software": software_version(),
        "measured_with": measured_with or NOT_RECORDED,
    }


def header_for_campaign(campaign: Campaign) -> dict[str, str]:
    """The header of a campaign (or of one run read as a one-run campaign)."""
    first = campaign.runs[0].meta if campaign.runs else {}
    if len(campaign.runs) == 1 and campaign.meta.get("campaign_id") is None \
            and "unit" not in campaign.meta:
        return header_fields(first)
    return header_fields(first, campaign.meta)


def render_header(header: dict[str, str]) -> str:
    """The header partial alone, as an HTML fragment (its own small style sheet inside)."""
    return template_env().get_template("certificate_header.html").render(header=header)
