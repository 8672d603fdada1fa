"""Issue 32 item 6 on the operator page, in Debian chromium: a planetary unit set up and its
transmission error measured from the page. ``rig serve --simulated --plant
simulators/planetary_plant.toml``: the simulated rig runs seed 003's paper train drawn inside
its tolerances (the planetary plant, so the TE holds seed 003's lines).

At 1440x900 the operator chooses the planetary kind: its example unit fills its own fields
(ratio, planets, the three stages' backlash, face width), the other kinds' are hidden; a wrong
backlash is named at the field. The TE test (3000 rpm, one output revolution = 320 input turns
each way, the shortest the form allows: about 13 s of turning) runs from the page and its
result, peak-to-peak and verdict, is shown in the TE panel; the stored run is the planetary
unit's, its TE the plant's truth over the revolution analysed, beside seed 003's model. At
390x844 (a second page on the same server) the kind's fields are shown without a sideways
scroll, and the finished run's TE result is read in the TE panel."""

from __future__ import annotations

import pytest
from playwright.sync_api import expect, sync_playwright

from rig.results.te import analyse_te_run
from rig.store import Store
from simulators.clock import ManualClock
from simulators.plant import GearPlant
from simulators.plant.config import load_plant_config
from tests.support.browser import (
    ARTIFACTS,
    NEEDS_CHROMIUM,
    desktop_and_phone,
    launch_browser,
    no_sideways_scroll,
    start_run,
)
from tests.support.paths import REPO
from tests.support.serve import get_json, rig_serve

pytestmark = [pytest.mark.realtime, pytest.mark.alone, NEEDS_CHROMIUM, pytest.mark.timeout(300)]

PLANETARY_PLANT = REPO / "simulators" / "planetary_plant.toml"
OTHER_KINDS_FIELDS = ("z_internal", "z_external", "z_pinion", "module_mm", "height_coeff",
                      "cone_angle_deg", "m_value_internal_mm", "runout_internal_mm")


def choose_planetary(page) -> None:
    """Choose the planetary kind: its example unit in its own fields, the others hidden."""
    form = page.locator("#setup")
    expect(page.locator("#unit-example option[value=planetary-seed003]")).to_have_count(1)
    form.locator("select[name=unit_kind]").select_option("planetary")
    expect(page.locator("#unit-example")).to_have_value("planetary-seed003")
    for name, value in (("ratio", "320"), ("planets", "3"), ("backlash_um", "20, 20, 20"),
                        ("face_width_mm", "10")):
        expect(form.locator(f"input[name={name}]")).to_be_visible()
        expect(form.locator(f"input[name={name}]")).to_have_value(value)
    for hidden in OTHER_KINDS_FIELDS:
        expect(form.locator(f"input[name={hidden}]")).to_be_hidden()


def test_operator_measures_the_te_of_a_planetary_unit(tmp_path):
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    with rig_serve(tmp_path / "store", "--plant", str(PLANETARY_PLANT)) as (url, link), \
            sync_playwright() as pw:
        browser = launch_browser(pw)
        page, errors, phone, phone_errors = desktop_and_phone(browser, link)
        for p in (page, phone):
            choose_planetary(p)
        no_sideways_scroll(phone)
        phone.screenshot(path=str(ARTIFACTS / "planetary-setup-phone.png"), full_page=True)

        # a wrong field is named at the field, at both widths
        for p in (page, phone):
            field = p.locator("#setup input[name=backlash_um]")
            field.fill("20, 20")
            expect(p.locator(".field-error[data-for=backlash_um]")).to_have_text(
                "backlash of the stages must be 3 values, one per stage (2 given)")
            field.fill("20, 20, 20")
            expect(p.locator(".field-error[data-for=backlash_um]")).to_have_text("")

        # the TE test: the shortest plan, one output revolution each way at 3000 rpm, the
        # ratio the unit's (320)
        form = page.locator("#setup")
        page.select_option("select[name=test]", "transmission_error")
        form.locator("input[name=te_speed_rpm]").fill("3000")
        form.locator("input[name=te_brake_fraction]").fill("0.2")
        form.locator("input[name=te_revolutions]").fill("1")
        form.locator("input[name=te_pp_max_arcsec]").fill("600")
        page.click("#preview")
        expect(page.locator("#preview-out")).to_contain_text("turn input forward at 3000 rpm",
                                                            timeout=30_000)
        start_run(page, serial="PL-1")
        expect(page.locator("#state")).to_have_text("completed", timeout=120_000)
        for p in (page, phone):
            expect(p.locator("#te-panel")).to_be_visible(timeout=30_000)
            expect(p.locator("#loop-panel")).to_be_hidden()
            expect(p.locator("#te-pp")).not_to_have_text("–", timeout=20_000)
            expect(p.locator("#te-verdict")).to_have_text("OK", timeout=20_000)
            expect(p.locator("#te-limit")).to_contain_text("600.0 arcsec")
        no_sideways_scroll(phone)
        page.screenshot(path=str(ARTIFACTS / "planetary-te-page.png"), full_page=True)
        phone.screenshot(path=str(ARTIFACTS / "planetary-te-page-phone.png"), full_page=True)
        shown = float(page.locator("#te-pp").inner_text())
        assert phone.locator("#te-pp").inner_text() == page.locator("#te-pp").inner_text()
        fwd, rev = (float(x) for x in page.locator("#te-pp-dirs").inner_text().split(" / "))

        # the stored run: the planetary unit, its ratio, measured on the planetary plant
        runs = get_json(url + "api/runs")
        assert runs[0]["status"] == "completed" and runs[0]["unit_serial"] == "PL-1"
        run_id = runs[0]["run_id"]
        meta = get_json(url + f"api/runs/{run_id}")["meta"]
        assert meta["unit"]["kind"] == "planetary" and meta["unit"]["backlash_um"] == [20.0] * 3
        assert meta["test"]["kind"] == "transmission_error" and meta["test"]["ratio"] == 320.0
        assert meta["simulation"]["plant_kind"] == "planetary"
        result = meta["result"]
        assert not result.get("plant_mismatch"), result.get("plant_mismatch")
        assert shown == pytest.approx(result["te_pp_arcsec"], abs=0.06)  # shown with 1 decimal
        assert fwd == pytest.approx(result["te_pp_forward_arcsec"], abs=0.06)
        assert rev == pytest.approx(result["te_pp_reverse_arcsec"], abs=0.06)
        assert result["model"]["name"].startswith("seed 003")  # the planetary TE model

        # the planetary TE measured: each direction's peak-to-peak is the plant's truth over
        # the output revolution analysed (5 %, as tests/rig/measurement/test_te_planetary_e2e)
        run = Store(tmp_path / "store").load_run(run_id)
        item = analyse_te_run(run, with_model=False)
        plant = GearPlant(load_plant_config(PLANETARY_PLANT), ManualClock())
        for code, name, got in ((1, "forward", fwd), (-1, "reverse", rev)):
            truth = plant.true_transmission_error(
                meta["test"]["brake_torque_Nm"],
                output_window_deg=item.result.curves[code].span_deg)[name]["pp_arcsec"]
            print(f"planetary on the page, {name}: shown {got} arcsec, plant truth {truth:.1f}")
            assert got == pytest.approx(truth, rel=0.05), (name, got, truth)
        assert not errors, errors
        assert not phone_errors, phone_errors
        browser.close()
