"""Hostile text for the escaping tests (issue 21 item 1): a field's text that would run as
markup if a page put it raw, a store full of it, and a page's text as a reader sees it."""

from __future__ import annotations

import json
from html.parser import HTMLParser
from pathlib import Path

from tests.support.paths import REPO

UNIT = json.loads((REPO / "rig/examples/units/seed000-pair1.json").read_text())
RAW_MARKUP = ("<script>document", "<img src=x", "<svg onload", "'><svg", '"><img')
"""Markup that runs only when it reaches a page raw (as escaped text it is harmless)."""


def hostile(field: str) -> str:
    """One field's hostile text: a script that steals the token, an attribute breakout,
    a template expression and quotes."""
    return (f'{field}<script>document.title="XSS-"+sessionStorage.getItem("rigToken")'
            f"</script>\"><img src=x onerror=alert('{field}')>'><svg onload=alert(1)>"
            "{{7*7}} O'Brien \"q\" & co")


PLAYS = [1.0, 1.1] * 4 + [1.0, 3.0]
"""Worst lost motion per unit: the jump of the last unit is a rule signal (WE1) on the SPC
chart, so that its serial is listed in the signals table (tests/rig/reports/test_spc.py,
same shape)."""


def write_hostile_store(root: Path):
    """A folder store of 10 units of one hostile design; the last unit's campaign and runs
    carry hostile operator, labels, sensors, calibration and override reason. Returns
    (store, campaign id of the last unit, its first run id)."""
    from rig.store import Store
    from rig.store.synthetic_runs import write_campaign

    st = Store(root)
    unit = {**UNIT, "name": hostile("unit name"), "notes": hostile("notes")}
    campaign_id = ""
    for k, play in enumerate(PLAYS):
        campaign_id = write_campaign(
            st, hostile(f"serial {k}"), play_arcmin=play, positions_deg=(0.0, 180.0),
            design=hostile("design"), unit_data=unit, n_quarter=60,
            limits={"lost_motion_arcmin_max": 3.0})
    folder = st.get_campaign(campaign_id).path
    cmeta = json.loads((folder / "campaign.json").read_text())
    cmeta.update(name=hostile("campaign name"), operator=hostile("operator"))
    (folder / "campaign.json").write_text(json.dumps(cmeta))
    run_ids = []
    for i, run_json in enumerate(sorted(folder.glob("*/run.json")), start=1):
        meta = json.loads(run_json.read_text())
        meta.update(
            operator=hostile("operator"), rig_name=hostile("rig name"),
            label=hostile(f"label {i}"),
            sensors={hostile("sensor name"): hostile("sensor value")},
            calibration=[{"sensor": hostile("calibration sensor"), "id": "TT-1",
                          "due": "2099-01-01"}],
            calibration_override=hostile("override reason"))
        run_json.write_text(json.dumps(meta))
        run_ids.append(meta["run_id"])
    return st, campaign_id, run_ids[0]


class _Text(HTMLParser):
    """A page's text as a reader sees it: the tags gone (a certificate wraps each word in a
    span that keeps it whole), character references decoded."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.parts: list[str] = []

    def handle_data(self, data: str) -> None:
        self.parts.append(data)


def page_text(page: str) -> str:
    parser = _Text()
    parser.feed(page)
    parser.close()
    return "".join(parser.parts)


def assert_shown_as_text(page: str, fields: list[str]) -> None:
    """No hostile markup reached the page raw; every field's text is on it, escaped."""
    for raw in RAW_MARKUP:
        assert raw not in page, f"{raw!r} raw in the page"
    text = page_text(page)
    for field in fields:
        assert hostile(field) not in page, f"{field}: unescaped"
        assert hostile(field) in text, f"{field}: not on the page"
    assert not fields or ("{{7*7}}" in text and ">49<" not in page)
