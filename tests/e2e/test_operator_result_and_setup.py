"""Issue 21 items 12, 15, 16 and 17 in Debian chromium, at 1440x900 and at 390x844, on one
``rig serve --simulated`` for the module (its store seeded with closed-form campaigns: one OK,
one NOT OK over two positions, one whose lost motion comes out below zero).

- 12: every History link is clickable at both widths (nothing covers it: the pinned loop
  panel stays above History), and the downloads, the Certificate and the diagnosis open;
- 15: the result panel shows only the numbers of the run or campaign it is titled with: no
  previous verdict while the next run measures or is paused, partial figures marked and the
  open loop's area not shown, the campaign's worst run at its end, a failing campaign's own
  verdict when clicked, a lost motion below zero never shown as a measurement;
- 16: after Start the progress and loop come into view; after an E-STOP while scrolled down
  the fault box and Reset faults do, and the header's state badge can be tapped to get there;
- 17: a campaign of the rig (by name) or an uploaded campaign file fills the set-up (its
  hostile text shown as text, a broken file named with line and column); with --simulated
  the "Expired calibration" box is hidden; the Devices panel keeps all its rows during a run;
  the "Quality (SPC)" link has a contrast of at least 4.5:1 in light mode.
"""

from __future__ import annotations

import re

import pytest
from playwright.sync_api import expect, sync_playwright

from rig.store import Store
from rig.store.synthetic_runs import write_campaign
from tests.support.browser import (
    ARTIFACTS,
    DESKTOP,
    NEEDS_CHROMIUM,
    PHONE,
    confirm_lock,
    fill_identity,
    launch_browser,
    start_run,
)
from tests.support.serve import get_json, rig_serve

# alone (tests/conftest.py): the run's verdict is asserted, and beside the other worker's
# CPU-bound tests the torque channel came 12-16 ms late against the twist (the lag check's
# 10 ms: INCOMPLETE, honestly) in both tries of the fresh-clone CI run of 2026-11-29 (and
# under load on 2026-11-28); alone it passes
pytestmark = [pytest.mark.realtime, pytest.mark.alone, NEEDS_CHROMIUM, pytest.mark.timeout(240)]

HOSTILE = "<img src=x onerror=alert(1)>"
UPLOAD = f"""name = "upload-2pos"
description = "{HOSTILE} two positions"
[unit]
file = "../../rig/examples/units/seed000-pair1.json"
serial = "UP-1"
[plan]
rated_torque_Nm = 10.0
steps_per_quarter = 2
pre_cycles = 0
extra_levels_pct = [3.0]
zero_band_Nm = 0.3
zero_rate_Nm_per_s = 1.0
rate_Nm_per_s = 25.0
dwell_s = 0.05
[axes]
positions_deg = [0.0, 180.0]
[limits]
lost_motion_arcmin_max = 30.0
"""


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory):
    """One simulated rig and page for the module: (url, operator link, seeded ids, browser)."""
    tmp = tmp_path_factory.mktemp("page21")
    st = Store(tmp / "store")
    try:
        seeded = {
            "ok": write_campaign(st, "E2E-OK", play_arcmin=2.0, positions_deg=(0.0,),
                                 limits={"lost_motion_arcmin_max": 5.0}, n_quarter=100),
            "nok": write_campaign(st, "E2E-NOK", play_arcmin=[2.5, 3.0],
                                  positions_deg=(0.0, 180.0),
                                  limits={"lost_motion_arcmin_max": 2.0}, n_quarter=100),
            "neg": write_campaign(st, "E2E-NEG", play_arcmin=-0.5, positions_deg=(0.0,),
                                  n_quarter=200),
        }
    finally:
        st.close()
    (tmp / "upload-2pos.toml").write_text(UPLOAD, encoding="utf-8")
    (tmp / "broken.toml").write_text('name = "b"\n[plan\nrated_torque_Nm = 1\n',
                                     encoding="utf-8")
    expect.set_options(timeout=30_000)  # a loaded machine: a stored loop takes seconds
    with rig_serve(tmp / "store") as (url, link), sync_playwright() as pw:
        browser = launch_browser(pw)
        runs = {key: get_json(url + f"api/campaigns/{cid}")["runs"]
                for key, cid in seeded.items()}
        yield {"url": url, "link": link, "ids": seeded, "runs": runs, "tmp": tmp,
               "browser": browser}
        browser.close()
    expect.set_options(timeout=5_000)


def open_page(served, viewport):
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    page = served["browser"].new_page(viewport=viewport, accept_downloads=True)
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.on("dialog", lambda d: (errors.append("dialog " + d.message), d.dismiss()))
    page.goto(served["link"])
    expect(page.locator("#role")).to_have_text("operator")
    expect(page.locator("#state")).to_have_text(re.compile("idle|completed|aborted|fault"),
                                                timeout=90_000)
    if page.locator("#state").inner_text() == "fault":  # left by the other width's test
        page.click("#reset-faults")
    expect(page.locator("#runs tbody tr")).not_to_have_count(0, timeout=30_000)
    return page, errors


def below_header(page, selector: str) -> bool:
    """The element's top is on screen below the sticky header, its bottom on screen too (or
    it fills the screen from there)."""
    return page.evaluate("""(sel) => {
        const h = document.querySelector('header').getBoundingClientRect().bottom;
        const r = document.querySelector(sel).getBoundingClientRect();
        return r.width > 0 && r.top >= h - 1 && r.top < innerHeight
               && (r.bottom <= innerHeight || r.top <= h + 60); }""", selector)


COVERED = """() => [...document.querySelectorAll('#history-panel a')].map((a) => {
  a.scrollIntoView({block: 'center', inline: 'center'});
  const r = a.getClientRects()[0];  // its first line box (a long id wraps)
  const hit = document.elementFromPoint(r.left + r.width / 2, r.top + r.height / 2);
  return hit === a || a.contains(hit) ? null
    : a.textContent + ' of ' + a.closest('tr').cells[0].textContent + ' under ' +
      (hit ? hit.tagName + '.' + hit.className + ' in #' + (hit.closest('[id]') || {}).id : '-');
}).filter(Boolean)"""


def check_history_links(page, served, *, all_clicks: bool) -> None:
    """Item 12: no History link is covered, and they work when clicked (downloads, the
    Certificate, the diagnosis page)."""
    page.click("#refresh")
    expect(page.locator("#runs tbody tr")).not_to_have_count(0)
    assert page.evaluate(COVERED) == [], "History links covered"
    # the links of the OK campaign and its run (every row's were checked above)
    ok = served["ids"]["ok"]
    camp = page.locator("#campaigns tbody tr", has=page.locator(f"a[data-campaign='{ok}']"))
    run_id = served["runs"]["ok"][0]["run_id"]
    run = page.locator("#runs tbody tr", has=page.locator(f"a[data-run='{run_id}']"))
    # History's own run link and lost-motion column: clicked, that run's loop is drawn
    run.locator(f"a[data-run='{run_id}']").click()
    expect(page.locator("#loop-title")).to_contain_text(run_id)
    # each link clicked for real (nothing intercepts the pointer): the request goes out; the
    # downloads served by the page itself arrive (a certificate or diagnosis is drawn in the
    # analysis worker, which a loaded machine may keep busy for minutes: its request is
    # what this checks)
    worker = [(run, "Certificate", "/certificate.pdf"), (camp, "Certificate", "/certificate.pdf")]
    if all_clicks:
        for text in ("zip", "csv", "png"):
            with page.expect_download(timeout=60_000) as got:
                run.get_by_role("link", name=text, exact=True).click()
            assert got.value.failure() is None, (text, got.value.failure())
        # the closed-form campaign's runs carry no unit data: its diagnosis is refused, said
        # in the notice (never a silent download), and History then says why instead of
        # offering it (issue 33 item 13; tests/e2e/test_history_and_live_panel.py)
        camp.get_by_role("link", name="json", exact=True).click()
        expect(page.locator("#notice")).to_contain_text("cannot be diagnosed", timeout=120_000)
        expect(camp.locator(".no-diagnosis")).to_contain_text("no diagnosis: ")
        assert camp.locator("a[data-diagnosis]").count() == 0
    for row, text, path in worker:
        with page.expect_request(lambda r, path=path: r.url.endswith(path), timeout=10_000):
            row.get_by_role("link", name=text, exact=True).click()
        page.evaluate("window.stop()")  # the page stays: the next link is clicked on it


def check_stored_numbers(page, served) -> None:
    """Item 15 on History: a failing campaign clicked after a green OK run shows its own
    verdict and worst run; a lost motion below zero is never shown as a measurement."""
    ok_run = served["runs"]["ok"][0]["run_id"]
    page.locator(f"a[data-run='{ok_run}']").click()
    expect(page.locator("#m-verdict")).to_have_text("OK")
    expect(page.locator("#metrics-title")).to_contain_text(ok_run)
    nok = served["ids"]["nok"]
    page.locator(f"a[data-campaign='{nok}']").click()
    expect(page.locator("#m-verdict")).to_have_text("NOT OK")
    expect(page.locator("#metrics-title")).to_contain_text(nok)
    worst = max(served["runs"]["nok"], key=lambda r: r["metrics"]["lost_motion_arcmin"])
    expect(page.locator("#metrics-title")).to_contain_text(f"worst run {worst['run_id']}")
    expect(page.locator("#loop-title")).to_contain_text(worst["run_id"])
    assert float(page.locator("#m-lost").inner_text()) == pytest.approx(
        worst["metrics"]["lost_motion_arcmin"], abs=0.0005)
    expect(page.locator("#result")).to_contain_text("NOT OK")
    assert ">OK<" not in page.locator("#loop-panel").inner_html()
    # the run whose lost motion came out below zero (-0.48 arcmin): no figure shown
    neg = served["runs"]["neg"][0]
    assert neg["metrics"]["lost_motion_arcmin"] < 0
    row = page.locator("#runs tbody tr", has=page.locator(f"a[data-run='{neg['run_id']}']"))
    expect(row.locator("td.lost-motion")).to_contain_text("below zero")
    assert not re.search(r"-\d", row.locator("td.lost-motion").inner_text())
    row.locator(f"a[data-run='{neg['run_id']}']").click()
    expect(page.locator("#metrics-title")).to_contain_text(neg["run_id"])
    expect(page.locator("#m-lost")).to_have_text("–")
    expect(page.locator("#m-lost-u")).to_contain_text("below zero")
    assert not re.search(r"-\d", page.locator("#m-lost").inner_text()
                         + page.locator("#m-hysteresis").inner_text())


def check_setup_items(page, served) -> None:
    """Item 17 without a run: the simulated rig's page hides the override box; SPC link
    contrast; an example campaign and an uploaded file fill the set-up."""
    expect(page.locator("#calibration-state")).to_have_text("none in the rig configuration")
    expect(page.locator("#override-box")).to_be_hidden()
    page.emulate_media(color_scheme="light")
    fg, bg = page.evaluate("""() => {
        const a = document.querySelector('#spc-link');
        let el = a, bg = 'rgba(0, 0, 0, 0)';
        while (el && /rgba\\(.*, 0\\)$|transparent/.test(bg)) {
            bg = getComputedStyle(el).backgroundColor; el = el.parentElement; }
        return [getComputedStyle(a).color, bg]; }""")
    assert contrast(fg, bg) >= 4.5, (fg, bg, contrast(fg, bg))
    f = "#setup [name={}]".format
    page.select_option("#campaign-example", "seed000-pair1")
    expect(page.locator(f("positions_deg"))).to_have_value("0, 90, 180, 270")
    expect(page.locator(f("kind"))).to_have_value("campaign")
    expect(page.locator(f("name"))).to_have_value("seed000-pair1")
    expect(page.locator(f("lost_motion_arcmin_max"))).to_have_value("3")
    expect(page.locator(f("steps_per_quarter"))).to_have_value("4")
    expect(page.locator(f("z_internal"))).to_have_value("45")
    expect(page.locator("#campaign-file-note")).to_contain_text("seed000-pair1.toml")
    # a broken file: one line naming the file, line and column
    page.set_input_files("#campaign-upload", str(served["tmp"] / "broken.toml"))
    expect(page.locator("#notice")).to_contain_text("broken.toml:2:")
    expect(page.locator("#notice")).to_contain_text("TOML syntax error")
    # the file that is run next: two positions, two steps per quarter, no pre-cycle
    page.set_input_files("#campaign-upload", str(served["tmp"] / "upload-2pos.toml"))
    expect(page.locator(f("positions_deg"))).to_have_value("0, 180")
    expect(page.locator(f("steps_per_quarter"))).to_have_value("2")
    expect(page.locator(f("pre_cycles"))).to_have_value("0")
    expect(page.locator(f("serial"))).to_have_value("UP-1")
    expect(page.locator(f("lost_motion_arcmin_max"))).to_have_value("30")
    expect(page.locator("#campaign-file-note")).to_contain_text(HOSTILE)  # as text
    assert page.locator("#setup-panel img").count() == 0
    expect(page.locator("#preview-out")).to_contain_text("2 run(s)")


def check_fault_comes_into_view(page) -> None:
    """Item 16: an E-STOP while scrolled down brings the fault box and Reset faults into
    view; scrolled away again, a tap on the header's state badge brings them back."""
    page.evaluate("window.scrollTo(0, document.body.scrollHeight)")
    page.click("#estop")
    expect(page.locator("#state")).to_have_text("fault", timeout=15_000)
    expect(page.locator("#reset-faults")).to_be_visible()
    page.wait_for_function("() => !document.querySelector('#fault').hidden")
    page.wait_for_timeout(300)
    assert below_header(page, "#fault") and below_header(page, "#reset-faults")
    page.evaluate("window.scrollTo(0, document.body.scrollHeight)")
    assert not below_header(page, "#reset-faults")
    page.click("#state")  # a real tap: nothing covers the badge
    assert below_header(page, "#fault") and below_header(page, "#reset-faults")
    page.click("#reset-faults")
    expect(page.locator("#state")).not_to_have_text("fault", timeout=15_000)


def device_names(page) -> list[str]:
    page.wait_for_function("() => document.querySelectorAll('#devices tbody tr').length >= 5",
                           timeout=30_000)
    return page.locator("#devices tbody tr td:nth-child(2)").all_inner_texts()


def test_desktop_result_panel_links_and_setup(served):
    page, errors = open_page(served, DESKTOP)
    idle_devices = device_names(page)
    assert len(idle_devices) >= 5, idle_devices
    check_setup_items(page, served)
    check_stored_numbers(page, served)
    # a green OK drawn from History, then the uploaded two-position campaign started
    ok_run = served["runs"]["ok"][0]["run_id"]
    page.locator(f"a[data-run='{ok_run}']").click()
    expect(page.locator("#m-verdict")).to_have_text("OK")
    start_run(page)
    expect(page.locator("#state")).to_have_text("running", timeout=15_000)
    # 15: no earlier verdict beside the run measured now
    expect(page.locator("#m-verdict")).to_have_text("–", timeout=10_000)
    # 17: the Devices panel keeps every row during the run
    page.wait_for_function("() => window.rigStats.points > 20", timeout=30_000)
    page.wait_for_timeout(1200)
    assert device_names(page) == idle_devices
    # 15: partial figures are marked so, the open loop's area is not shown
    page.wait_for_function("() => (window.rigStats.partial || 0) > 0", timeout=60_000)
    expect(page.locator("#metrics-title")).to_contain_text("partial")
    expect(page.locator("#m-hysteresis")).to_have_text("–")
    expect(page.locator("#m-lost")).to_have_class(re.compile("partial"))
    # 15: the second run measures, paused: not the first run's verdict or figures
    now = page.locator("#campaign-now")
    try:
        expect(now).to_contain_text("Now measuring run 2 of 2", timeout=60_000)
    except AssertionError:
        status = get_json(served["url"] + "api/status")
        raise AssertionError(f"no second run: {status['state']}: {status['message']}") from None
    expect(page.locator("#m-verdict")).to_have_text("–")
    first = now.locator("li").first.inner_text()
    second_run = get_json(served["url"] + "api/status")["current"]["run_id"]
    page.wait_for_function("(run) => window.rigPage.live.runId === run && "
                           "window.rigStats.points > 50", arg=second_run, timeout=30_000)
    page.click("#pause")
    expect(page.locator("#state")).to_have_text("paused", timeout=30_000)
    expect(page.locator("#metrics-title")).to_contain_text(second_run)
    expect(page.locator("#m-verdict")).to_have_text("–")
    assert "lost motion" in first
    page.click("#resume")
    page.wait_for_function("() => !['running', 'paused', 'stopping'].includes("
                           "document.querySelector('#state').textContent)", timeout=90_000)
    status = get_json(served["url"] + "api/status")
    assert status["state"] == "completed", (status["message"], status["fault"])
    # 15: at the end, the campaign's worst run, named
    result = get_json(served["url"] + "api/status")["last_result"]
    worst = max(result["runs"], key=lambda r: r["lost_motion_arcmin"])
    expect(page.locator("#metrics-title")).to_contain_text(f"worst run {worst['label']}")
    assert float(page.locator("#m-lost").inner_text()) == pytest.approx(
        worst["lost_motion_arcmin"], abs=0.0005)
    expect(page.locator("#m-verdict")).to_have_text("OK")
    page.screenshot(path=str(ARTIFACTS / "result-panel-1440.png"))
    # 12: after the campaign, then after clicking a campaign in History
    assert page.evaluate(COVERED) == [], "History links covered"
    page.locator(f"a[data-campaign='{served['ids']['nok']}']").click()
    expect(page.locator("#m-verdict")).to_have_text("NOT OK")
    assert page.evaluate(COVERED) == [], "History links covered"
    # 16 at this width too: the fault comes into view
    check_fault_comes_into_view(page)
    check_history_links(page, served, all_clicks=True)  # last: the page may navigate
    assert not errors, errors
    page.close()


def test_phone_start_fault_links_and_setup(served):
    page, errors = open_page(served, PHONE)
    check_setup_items(page, served)
    check_stored_numbers(page, served)
    # 16: Start from the set-up, far below the loop: the progress and the loop come into view
    f = "#setup [name={}]".format
    page.select_option(f("kind"), "run")
    fill_identity(page)
    confirm_lock(page)
    page.locator("#start").scroll_into_view_if_needed()
    assert not below_header(page, "#progress")
    idle_devices = device_names(page)
    page.click("#start")
    expect(page.locator("#state")).to_have_text("running", timeout=15_000)
    page.wait_for_timeout(300)
    assert below_header(page, "#progress"), "the progress is not in view after Start"
    assert below_header(page, "#loop-panel")
    page.wait_for_function("() => window.rigStats.points > 20", timeout=30_000)
    page.wait_for_timeout(1200)
    assert device_names(page) == idle_devices  # 17 at this width
    # 16: an E-STOP during the run while scrolled down
    check_fault_comes_into_view(page)
    page.screenshot(path=str(ARTIFACTS / "phone-after-reset.png"))
    check_history_links(page, served, all_clicks=False)
    assert not errors, errors
    page.close()


def contrast(fg: str, bg: str) -> float:
    """WCAG 2 contrast ratio of two CSS rgb()/rgba() colours."""
    def luminance(css: str) -> float:
        r, g, b = (int(x) for x in re.findall(r"[\d.]+", css)[:3])
        lin = [c / 255 / 12.92 if c / 255 <= 0.03928 else ((c / 255 + 0.055) / 1.055) ** 2.4
               for c in (r, g, b)]
        return 0.2126 * lin[0] + 0.7152 * lin[1] + 0.0722 * lin[2]
    a, b = sorted((luminance(fg), luminance(bg)), reverse=True)
    return (a + 0.05) / (b + 0.05)
