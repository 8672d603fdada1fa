"""End to end in a real headless Chromium (Debian's package, driven by Playwright through
``executable_path``; no browser download): ``rig serve --simulated`` is started as a process,
the page measures a run on the simulated rig (the loop drawn live, the lost motion shown),
then a second run is aborted and the page shows the safe state. Screenshots are kept in
``artifacts/e2e/`` (gitignored)."""

from __future__ import annotations

from pathlib import Path

import pytest
from playwright.sync_api import expect, sync_playwright

from tests.support.browser import (
    ARTIFACTS,
    NEEDS_CHROMIUM,
    confirm_lock,
    fill_identity,
    launch_browser,
    open_page,
    start_run,
)
from tests.support.serve import get_json, rig_serve

# alone (tests/conftest.py): the run's verdict is asserted, and beside the other worker's
# CPU-bound tests the torque channel came 12-16 ms late against the twist (the lag check's
# 10 ms: INCOMPLETE, honestly) in both tries of the fresh-clone CI run of 2026-11-29 (and
# under load on 2026-11-28); alone it passes
pytestmark = [pytest.mark.realtime, pytest.mark.alone, NEEDS_CHROMIUM, pytest.mark.timeout(240)]


def test_operator_measures_a_run_and_aborts_another(tmp_path: Path):
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    with rig_serve(tmp_path / "store") as (url, link), sync_playwright() as pw:
        browser = launch_browser(pw)
        page, errors = open_page(browser, link, 1400, 1500)
        expect(page.locator("#role")).to_have_text("operator")
        expect(page.locator("#estop")).to_be_visible()
        expect(page.locator("#state")).to_have_text("idle", timeout=90_000)

        # first run: confirm the input lock, start, watch the loop drawn and the metrics
        # (the shortest loop: 2 steps a quarter, no pre-cycle; the abort below runs the
        # default plan, long enough to be stopped in the middle)
        page.fill("#setup input[name=steps_per_quarter]", "2")
        page.fill("#setup input[name=pre_cycles]", "0")
        start_run(page)
        page.wait_for_function("() => window.rigStats.points > 500", timeout=60_000)
        expect(page.locator("#state")).to_have_text("completed", timeout=90_000)
        expect(page.locator("#m-lost")).not_to_have_text("–", timeout=10_000)
        shown = float(page.locator("#m-lost").inner_text())
        page.screenshot(path=str(ARTIFACTS / "control-page-run.png"), full_page=True)

        runs = get_json(url + "api/runs")
        assert runs[0]["status"] == "completed"
        stored = runs[0]["metrics"]["lost_motion_arcmin"]
        assert shown == pytest.approx(stored, abs=0.0005)  # shown with 3 decimals
        assert 0.5 < stored < 10.0  # a seed 000 pair: a few arcmin
        # no limits set: neither OK nor NOT OK (issue 21 item 13)
        assert page.locator("#m-verdict").inner_text() == "NO LIMITS"
        drawn = page.evaluate("window.rigStats")
        assert drawn["batches"] > 10 and len(drawn["latency_s"]) > 10

        # second run: abort it while it runs; the page shows the safe state
        page.fill("#setup input[name=steps_per_quarter]", "4")
        page.fill("#setup input[name=pre_cycles]", "1")
        fill_identity(page)  # the serial was cleared by the first Start: this is another unit
        confirm_lock(page)
        first_run = runs[0]["run_id"]
        page.click("#start")
        page.wait_for_function(  # a function, not a string to eval: the page's CSP
            f"() => window.rigPage.live.runId && window.rigPage.live.runId !== '{first_run}' "
            "&& window.rigStats.points > 200", timeout=60_000)
        expect(page.locator("#abort")).to_be_enabled()
        page.click("#abort")
        expect(page.locator("#state")).to_have_text("aborted", timeout=30_000)
        expect(page.locator("#fault-title")).to_contain_text("Stopped by the operator")
        expect(page.locator("#v-safe")).to_have_text("yes", timeout=10_000)
        expect(page.locator("#v-drive")).to_have_text("disabled")
        page.screenshot(path=str(ARTIFACTS / "control-page-aborted.png"), full_page=True)

        runs = get_json(url + "api/runs")
        assert runs[0]["status"] == "aborted"
        assert runs[0]["reason"] == "aborted by the operator"
        status = get_json(url + "api/status")
        assert status["safe"] is True and status["live"]["setpoint_Nm"] == 0.0
        assert not errors, errors
        browser.close()
