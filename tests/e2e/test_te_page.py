"""End to end in a real headless Chromium: the transmission error test from the control page.
The simulated rig runs as its own process with a seed 000 pair carrying the eq. (4)
eccentricities and pitch errors (``rig sim``'s plant), ``rig serve --rig`` connects to it;
the operator chooses the test, sets speed, brake and the TE limit, starts, watches the TE
drawn live against the output angle, and reads the result with its limit and verdict, the
figure the run stored. About 10 s of rotation at 240 rpm (the 45/40 pair, ratio -8)."""

from __future__ import annotations

import contextlib
from pathlib import Path

import pytest
from playwright.sync_api import expect, sync_playwright

from rig.hardware.simrig import SimulatedRig
from rig.measurement.service import plant_config_for, write_plant_toml
from rig.plans.campaign_file import SimulationSection
from simulators.plant.config import load_plant_config
from tests.support.browser import (
    ARTIFACTS,
    NEEDS_CHROMIUM,
    launch_browser,
    open_page,
    start_run,
)
from tests.support.serve import TOKEN, get_json, served

pytestmark = [pytest.mark.realtime, NEEDS_CHROMIUM, pytest.mark.timeout(300)]

EFFECTS = {"kinematic_error": {"enabled": True, "beta_deg": 30.0},
           "tooth_spacing_error": {"enabled": True, "transition_fraction": 0.5}}


@contextlib.contextmanager
def serve_rig(rig_toml: Path, store: Path):
    """``rig serve --rig RIG.toml`` on a free port; yields (url, operator link)."""
    with served(store, TOKEN, "--rig", str(rig_toml)) as lines:
        yield lines["control page"], lines["operator link"]


def test_operator_measures_the_transmission_error(tmp_path: Path):
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    unit = dict(load_plant_config().unit, serial="te-page")
    plant = write_plant_toml(plant_config_for(unit, SimulationSection(
        seed=2, plant={"effects": EFFECTS})), tmp_path / "plant.toml")
    with SimulatedRig(plant, in_process=False, rig_config_path=tmp_path / "rig.toml",
                      sync_period_s=0.004, stream_rate_Hz=250.0) as sim, \
            serve_rig(sim.rig_config_path, tmp_path / "store") as (url, link), \
            sync_playwright() as pw:
        browser = launch_browser(pw)
        page, errors = open_page(browser, link, 1400, 1800)
        expect(page.locator("#role")).to_have_text("operator", timeout=60_000)
        expect(page.locator("#state")).to_have_text("idle", timeout=90_000)
        expect(page.locator("#te-panel")).to_be_hidden()

        # choose the test: its fields appear; set speed, brake, revolutions and the limit
        page.select_option("select[name=test]", "transmission_error")
        expect(page.locator("input[name=te_speed_rpm]")).to_be_visible()
        page.fill("input[name=te_speed_rpm]", "240")
        page.fill("input[name=te_brake_fraction]", "0.3")
        page.fill("input[name=te_revolutions]", "1")
        page.fill("input[name=te_pp_max_arcsec]", "2000")
        page.click("#preview")
        expect(page.locator("#preview-out")).to_contain_text("turn input forward at 240 rpm",
                                                        timeout=30_000)

        start_run(page)
        # the TE drawn live against the output angle, both directions
        page.wait_for_function("() => (window.rigStats.te_points || 0) > 300", timeout=90_000)
        expect(page.locator("#state")).to_have_text("completed", timeout=120_000)
        expect(page.locator("#te-pp")).not_to_have_text("–", timeout=20_000)
        expect(page.locator("#te-verdict")).to_have_text("OK", timeout=20_000)
        expect(page.locator("#te-limit")).to_contain_text("2000.0 arcsec")
        page.screenshot(path=str(ARTIFACTS / "te-page.png"), full_page=True)

        shown = float(page.locator("#te-pp").inner_text())
        runs = get_json(url + "api/runs")
        assert runs[0]["status"] == "completed"
        run_id = runs[0]["run_id"]
        detail = get_json(url + f"api/runs/{run_id}")
        result = detail["meta"]["result"]
        assert detail["meta"]["test"]["kind"] == "transmission_error"
        stored = result.get("te_pp_arcsec") or result["te_raw"]["pp_arcsec"]
        assert shown == pytest.approx(stored, abs=0.06)  # shown with 1 decimal
        assert stored > 100.0  # the injected eccentricities: a few arcmin of TE
        status = get_json(url + "api/status")
        assert status["safe"] is True
        assert not errors, errors
        browser.close()
