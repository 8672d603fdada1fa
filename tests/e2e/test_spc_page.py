"""Issue 21 items 16 and 18 in a real headless Chromium: the quality page ``/spc`` at a
desktop's 1440x900 and a phone's 390x844. It fits the screen (no horizontal scroll: the
document is no wider than the viewport, the tables scroll inside their own box), and
hovering a point of a chart names its unit: test order and serial (a hostile serial shown
as text), in a tooltip that stays on the screen.

The page is served by the control page's app (rig/web/app.py) under uvicorn on a free port,
in this process: the quality view needs the store, not a rig, so no simulated rig is started.
"""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from pathlib import Path

import pytest
from playwright.sync_api import expect, sync_playwright

from tests.support.browser import NEEDS_CHROMIUM, launch_browser
from tests.support.hostile import UNIT, hostile

pytestmark = [pytest.mark.realtime, NEEDS_CHROMIUM, pytest.mark.timeout(300)]
WIDTHS = ((1440, 900), (390, 844))
N_UNITS = 6


def write_store(root: Path):
    """Six units of one design, one run each, with hostile serials
    (tests/rig/reports/test_html_escaping)."""
    from rig.store import Store
    from rig.store.synthetic_runs import write_campaign

    st = Store(root)
    for k, play in enumerate([1.0, 1.2, 1.1, 1.6, 1.3, 1.2][:N_UNITS]):
        write_campaign(st, hostile(f"serial {k}"), play_arcmin=play, positions_deg=(0.0,),
                       design="RV-40E", unit_data=UNIT, n_quarter=20,
                       limits={"lost_motion_arcmin_max": 3.0})
    return st


@contextlib.contextmanager
def serve_store(store):
    """The control page's app for ``store`` under uvicorn on 127.0.0.1 (a free port)."""
    import uvicorn

    from rig.web.app import create_app
    from rig.web.settings import resolve_settings

    app = create_app(resolve_settings(store_root=store.root, token="spc-e2e-token"),
                     store=store)
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning", lifespan="on"))
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    try:
        deadline = time.monotonic() + 60
        while not server.started:
            assert thread.is_alive() and time.monotonic() < deadline, "uvicorn did not start"
            time.sleep(0.05)
        yield f"http://127.0.0.1:{sock.getsockname()[1]}/"
    finally:
        server.should_exit = True
        thread.join(timeout=30)
        sock.close()


def test_spc_fits_desktop_and_phone_and_names_the_serial_on_hover(tmp_path: Path):
    store = write_store(tmp_path / "store")
    try:
        with serve_store(store) as url, sync_playwright() as pw:
            browser = launch_browser(pw)
            page = browser.new_page(viewport={"width": 1440, "height": 900})
            page.goto(url + "spc", timeout=120_000)  # laid out again at each width below
            expect(page.locator("h2").first).to_contain_text("Design RV-40E: 6 unit tests")
            scroll = "document.documentElement.scrollWidth"
            for width, height in WIDTHS:  # no horizontal scroll at either width
                page.set_viewport_size({"width": width, "height": height})
                assert page.evaluate(scroll) <= width, (width, page.evaluate(scroll))
            for width, height in WIDTHS:
                page.set_viewport_size({"width": width, "height": height})
                chart = page.locator('.chart[data-metric="lost_motion_arcmin"]')
                image = chart.locator("img").bounding_box()
                assert image["x"] >= 0 and image["x"] + image["width"] <= width
                # the units in test order; the 4th is hovered, its serial shown as text
                targets = chart.locator(".pt")
                expect(targets).to_have_count(N_UNITS)
                point = targets.nth(3)
                point.scroll_into_view_if_needed()
                box = point.bounding_box()
                centre = (box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
                # nothing covers the point: it is what the pointer reaches there
                assert page.evaluate("([x, y]) => document.elementFromPoint(x, y)"
                                     ".dataset.order", list(centre)) == "4"
                tip = point.locator(".tip")
                expect(tip).to_be_hidden()
                page.mouse.move(*centre)
                expect(tip).to_be_visible()
                expect(tip).to_contain_text("unit test 4: " + hostile("serial 3"))
                assert hostile("serial 3") in point.get_attribute("title")
                shown = tip.bounding_box()
                assert shown["x"] >= 0 and shown["x"] + shown["width"] <= width, shown
                assert page.evaluate(scroll) <= width, (width, page.evaluate(scroll))
                # the last unit, at the chart's right edge: its tooltip opens leftwards
                last = targets.nth(N_UNITS - 1)
                last.scroll_into_view_if_needed()
                last.hover()
                shown = last.locator(".tip").bounding_box()
                assert shown["x"] >= 0 and shown["x"] + shown["width"] <= width, shown
                assert page.evaluate(scroll) <= width, (width, page.evaluate(scroll))
                assert page.title() == "Production quality"  # no script of the store ran
            browser.close()
    finally:
        store.close()
