"""Issue 21 item 1: every HTML the product writes shows hostile strings as text.

A store is written with markup in every field a user or a file controls (unit serial,
design, name and notes, operator, rig name, run label, abort reason, campaign name, sensor
names and values, calibration sensor, override reason). Each page is rendered from it: the
``rig spc`` page, the run and campaign certificates, the diagnosis page (and its plain
fallback), and the same pages served by the control page, which also carry a
Content-Security-Policy that forbids inline script. No markup of the store reaches a page
raw; each field's text is on the page (escaped), and ``{{7*7}}`` stays literal."""

from __future__ import annotations

import html
import json
import shutil
from html.parser import HTMLParser

import pytest

from tests.support.hostile import assert_shown_as_text, hostile, write_hostile_store


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    st, campaign_id, run_id = write_hostile_store(tmp_path_factory.mktemp("xss") / "store")
    yield st, campaign_id, run_id
    st.close()


SPC_FIELDS = ["design", "serial 9"]
RUN_CERT_FIELDS = ["serial 9", "design", "unit name", "notes", "operator", "rig name",
                   "sensor name", "sensor value", "calibration sensor", "override reason",
                   "abort reason"]
CAMPAIGN_CERT_FIELDS = ["serial 9", "design", "unit name", "notes", "operator", "rig name",
                        "label 1", "label 2", "sensor name", "sensor value",
                        "calibration sensor", "override reason"]
DIAGNOSIS_FIELDS = ["serial 9", "design", "operator", "rig name", "campaign name"]


def test_spc_page_escapes_design_and_serial(store):
    from rig.reports.spc import spc_report
    from rig.reports.spc.html import render_html

    st, _, _ = store
    doc = spc_report(st, design=hostile("design"))
    assert doc["designs"][0]["metrics"]["lost_motion_arcmin"]["chart"]["violations"]
    page = render_html(doc)
    assert_shown_as_text(page, SPC_FIELDS)
    assert "<title>Production quality: design&lt;script&gt;" in page


def test_certificates_escape_every_field(store, tmp_path):
    from rig.reports.certificate import Subject, certificate_context, render_certificate

    st, campaign_id, _ = store
    folder = st.get_campaign(campaign_id).path
    page = render_certificate(certificate_context(Subject(folder, st)))
    assert_shown_as_text(page, CAMPAIGN_CERT_FIELDS)
    run_folder = tmp_path / "run"
    shutil.copytree(sorted(p.parent for p in folder.glob("*/run.json"))[0], run_folder)
    meta = json.loads((run_folder / "run.json").read_text())
    meta.update(status="aborted", reason=hostile("abort reason"), outcome="incomplete")
    (run_folder / "run.json").write_text(json.dumps(meta))
    page = render_certificate(certificate_context(Subject(run_folder, None)))
    assert_shown_as_text(page, RUN_CERT_FIELDS)


def test_diagnosis_pages_escape_every_field(store):
    from rig.web.report import diagnose_campaign_folder, plain_report_html

    st, campaign_id, _ = store
    report, page = diagnose_campaign_folder(st.get_campaign(campaign_id).path)
    assert report["campaign"] == hostile("campaign name")
    assert_shown_as_text(page, DIAGNOSIS_FIELDS)
    plain = plain_report_html({**report, "verdict": hostile("verdict"),
                               "candidates": [hostile("candidate")],
                               "ranking": [{"effect": hostile("effect"), "shrink": 0.5}]})
    assert_shown_as_text(plain, ["campaign name", "verdict", "effect"])


class _Scripts(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.inline: list[str] = []
        self.handlers: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        names = dict(attrs)
        if tag == "script" and not names.get("src"):
            self.inline.append(tag)
        self.handlers += [k for k in names if k.startswith("on")]
        self.handlers += [k for k, v in names.items() if (v or "").startswith("javascript:")]


def test_the_control_page_serves_them_escaped_under_a_csp(store):
    """The control page, /spc, the certificates and the diagnosis page as served: escaped,
    and with a Content-Security-Policy that forbids inline script; the control page and the
    /spc page carry no inline script to forbid."""
    from fastapi.testclient import TestClient

    from rig.web.app import create_app
    from rig.web.settings import resolve_settings

    st, campaign_id, run_id = store
    app = create_app(resolve_settings(store_root=st.root, token="xss-test-token"), store=st)
    pages = {"/": [], "/spc": SPC_FIELDS,
             f"/spc?design={html.escape(hostile('design'))}": SPC_FIELDS,
             f"/api/runs/{run_id}/certificate.html": RUN_CERT_FIELDS[:-1],
             f"/api/campaigns/{campaign_id}/certificate.html": CAMPAIGN_CERT_FIELDS,
             f"/api/campaigns/{campaign_id}/diagnosis.html": DIAGNOSIS_FIELDS}
    with TestClient(app) as client:
        for path, fields in pages.items():
            if "?design=" in path:
                r = client.get("/spc", params={"design": hostile("design")})
            else:
                r = client.get(path)
            assert r.status_code == 200, (path, r.text[:300])
            csp = r.headers["content-security-policy"]
            directives = dict(d.strip().split(" ", 1) for d in csp.split(";"))
            assert directives["script-src"] == "'self'", csp
            assert directives["script-src-attr"] == "'none'", csp
            assert directives["object-src"] == "'none'" and "frame-ancestors" in directives
            assert r.headers["x-content-type-options"] == "nosniff"
            assert_shown_as_text(r.text, fields)
            scripts = _Scripts()
            scripts.feed(r.text)
            assert scripts.inline == [] and scripts.handlers == [], (path, scripts.__dict__)
        for path in ("/static/app.js", "/api/status", "/api/spc"):
            assert "script-src 'self'" in client.get(path).headers["content-security-policy"]

