"""Issue 33 item 19 in a real headless Chromium at a phone's 390x844: the campaign certificate
(HTML) and the diagnosis page fit the screen (the document no wider than the viewport; a wide
table scrolls inside its own box), the certificate's Unit and Sensors tables do not overlap,
and the diagnosis page's gap-map panels are shown whole at their own size (labels legible).

The campaign is the reference dead-zone loop written through the store
(:mod:`rig.store.synthetic_runs`, seed 000 pair 1 as the unit, the sensors a measured run
records): no simulated rig; the pages are files opened by the browser.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from playwright.sync_api import sync_playwright

from tests.support.browser import NEEDS_CHROMIUM, PHONE, launch_browser
from tests.support.paths import REPO

pytestmark = [pytest.mark.realtime, NEEDS_CHROMIUM, pytest.mark.timeout(300)]
UNIT = json.loads((REPO / "rig/examples/units/seed000-pair1.json").read_text())
SENSORS = {"encoder_counts_per_rev": 8388608, "torque_full_scale_Nm": 20.0,
           "output_encoder": "RESOLUTE-RA26BTA absolute, 26 bit"}


@pytest.fixture(scope="module")
def pages(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The certificate and the diagnosis page of a NOT OK campaign at three positions."""
    from rig.reports.certificate import Subject, certificate_context, render_certificate
    from rig.store import Store
    from rig.store.synthetic_runs import write_campaign

    tmp = tmp_path_factory.mktemp("phone")
    st = Store(tmp / "store")
    try:
        cid = write_campaign(st, "SN-PHONE-0001", play_arcmin=[2.0, 6.0, 3.0],
                             positions_deg=(0.0, 120.0, 240.0), unit_data=UNIT,
                             limits={"lost_motion_arcmin_max": 4.0}, n_quarter=200)
        folder = st.get_campaign(cid).path
    finally:
        st.close()
    for path in folder.glob("*/run.json"):  # labelled and with sensors, as a measured run
        meta = json.loads(path.read_text())
        meta["label"] = f"pos{meta['test']['input_angle_deg']:03.0f}"
        meta["sensors"] = SENSORS
        path.write_text(json.dumps(meta))
    certificate = tmp / "certificate.html"
    certificate.write_text(render_certificate(certificate_context(Subject(folder))),
                           encoding="utf-8")
    diagnosis = tmp / "diagnosis.html"
    res = subprocess.run([sys.executable, "-c", "from rig.cli import main; main()", "diagnose",
                          str(folder), "--html", str(diagnosis)], capture_output=True,
                         text=True, timeout=240, cwd=tmp)
    assert res.returncode == 0, res.stderr
    return {"certificate": certificate, "diagnosis": diagnosis}


@pytest.fixture(scope="module")
def browser():
    with sync_playwright() as pw:
        chromium = launch_browser(pw)
        try:
            yield chromium
        finally:
            chromium.close()


def _open(browser, path: Path):
    """``path`` in a new page of a phone's size; its screenshot beside it."""
    page = browser.new_page(viewport=PHONE)
    page.goto(path.as_uri())
    page.screenshot(path=str(path.with_suffix(".png")), full_page=True)
    return page


def _box(page, selector: str) -> dict[str, float]:
    box = page.locator(selector).bounding_box()
    assert box is not None, selector
    return box


def _overlap(a: dict[str, float], b: dict[str, float]) -> bool:
    return (a["x"] < b["x"] + b["width"] and b["x"] < a["x"] + a["width"]
            and a["y"] < b["y"] + b["height"] and b["y"] < a["y"] + a["height"])


def test_the_certificate_is_no_wider_than_a_phone(pages: dict[str, Path], browser):
    page = _open(browser, pages["certificate"])
    width = page.evaluate("document.documentElement.scrollWidth")
    assert width <= PHONE["width"], f"the certificate is {width} px wide at 390"


def test_the_certificates_unit_and_sensors_tables_do_not_overlap(pages: dict[str, Path],
                                                                 browser):
    page = _open(browser, pages["certificate"])
    unit = _box(page, "h2:text-is('Unit') + table")
    sensors = _box(page, "h2:text-is('Sensors') + table")
    assert not _overlap(unit, sensors), f"Unit {unit} and Sensors {sensors} overlap"
    for box in (unit, sensors):
        assert box["x"] >= 0 and box["x"] + box["width"] <= PHONE["width"], box


def test_the_diagnosis_page_fits_a_phone_with_its_gap_map_whole(pages: dict[str, Path],
                                                                browser):
    page = _open(browser, pages["diagnosis"])
    width = page.evaluate("document.documentElement.scrollWidth")
    panels = page.evaluate("""() => [...document.querySelectorAll('img')]
        .filter(img => img.alt.startsWith('gap map'))
        .map(img => ({natural: img.naturalWidth, shown: img.clientWidth,
                      right: img.getBoundingClientRect().right}))""")
    assert width <= PHONE["width"], f"the diagnosis page is {width} px wide at 390"
    assert panels, "no gap-map panel on the diagnosis page"
    for panel in panels:  # whole, at its own size: labels neither cut off nor shrunk
        assert panel["right"] <= PHONE["width"], panel
        assert panel["shown"] == panel["natural"], panel
