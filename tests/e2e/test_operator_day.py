"""The operator's day in Debian chromium (issue 11): a latched drive fault is acknowledged and
reset from the page, start and preview are refused while it is latched, the badge never says
idle while a device is faulted, an E-stop needs the same acknowledgement, and the numbers
beside a stored loop drawn from the history are that run's, whatever the status poll brings.

The drive fault is made from outside, as a second Modbus master on the line would: a setpoint
over the drive's limit written with pymodbus to the simulated drive, which refuses it and
latches SETPOINT_OVER_LIMIT (docs/modbus.md).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from playwright.sync_api import expect, sync_playwright
from pymodbus.client import ModbusTcpClient

from drivers.modbus.map import LOADING_DRIVE_MAP, encode_float32
from rig.hardware.config import load_rig_config
from rig.store import Store
from tests.support.browser import ARTIFACTS, launch_browser, open_page, start_run
from tests.support.serve import get_json, post, rig_serve
from tests.support.simulated_page import identified

# measures on simulated devices in real time; alone: beside the other worker's test the live
# panel's last event of the second run could land after the history click (the suite's CI on
# 2026-11-28 failed it twice in a row, the test alone passed; the race itself is issue 33
# item 16)
pytestmark = [pytest.mark.realtime, pytest.mark.alone]


def latch_drive_fault_from_outside(url: str) -> None:
    """A second Modbus master writes a setpoint over the drive's limit: the drive refuses it
    (exception 3) and latches its fault."""
    rig_text = get_json(url + "api/status")["rig"]
    path = re.search(r"\(([^)]*rig\.toml)\)", rig_text).group(1)
    drive = load_rig_config(path).drive
    client = ModbusTcpClient(drive.host, port=drive.port, timeout=2)
    assert client.connect()
    try:
        reply = client.write_registers(LOADING_DRIVE_MAP["setpoint"].address,
                                       encode_float32(10 * drive.torque_limit_Nm),
                                       device_id=drive.device_id)
        assert reply.isError()  # refused: the fault is latched, nothing moved
    finally:
        client.close()


def seed_a_failed_campaign(root: Path) -> str:
    """A NOT OK campaign in the store before the page starts (closed-form runs recorded with
    their limits and outcomes as a measured campaign records them): History must call it
    NOT OK, as the certificate and the CLI do."""
    from rig.store.synthetic_runs import write_campaign

    st = Store(root)
    try:
        return write_campaign(st, "E2E-NOK", play_arcmin=2.5, positions_deg=(0.0,),
                              limits={"lost_motion_arcmin_max": 2.0}, n_quarter=100)
    finally:
        st.close()


def history_row(page, table: str, ident: str):
    return page.locator(f"#{table} tbody tr", has=page.locator(
        f"a[data-{table[:-1]}='{ident}']"))


def test_fault_reset_estop_ack_and_history_numbers(tmp_path: Path):
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    failed_campaign = seed_a_failed_campaign(tmp_path / "store")
    with rig_serve(tmp_path / "store") as (url, link), sync_playwright() as pw:
        browser = launch_browser(pw)
        page, errors = open_page(browser, link, 1440, 900)
        expect(page.locator("#state")).to_have_text("idle", timeout=90_000)
        page.fill("#setup input[name=operator]", "A. Operator")
        # the shortest loop for both runs (2 steps a quarter, no pre-cycle, the play crossed
        # at 1 N*m/s): what is checked here is the page around the runs, not the loop
        page.fill("#setup input[name=steps_per_quarter]", "2")
        page.fill("#setup input[name=pre_cycles]", "0")
        page.fill("#setup input[name=zero_rate_Nm_per_s]", "1")

        # one completed run for the history, with a limit it fails (a seed 000 pair: 4')
        page.fill("#setup input[name=lost_motion_arcmin_max]", "1")
        start_run(page)
        expect(page.locator("#state")).to_have_text("completed", timeout=120_000)
        first = get_json(url + "api/runs")[0]

        # 1. a latched drive fault: badge "fault", start and preview refused, reset clears
        latch_drive_fault_from_outside(url)
        expect(page.locator("#state")).to_have_text("fault", timeout=10_000)
        expect(page.locator("#fault")).to_be_visible()
        expect(page.locator("#fault-action")).to_contain_text("loading drive")
        expect(page.locator("#reset-faults")).to_be_visible()
        expect(page.locator("#start")).to_be_disabled()
        page.screenshot(path=str(ARTIFACTS / "operator-fault-latched.png"))
        body = identified({"unit": get_json(url + "api/units")[0]["unit"],
                           "plan": {"rated_torque_Nm": 10.0, "steps_per_quarter": 2}})
        code, answer = post(url + "api/control/start", body)
        assert code == 409 and "fault is latched" in answer["detail"], answer
        assert "loading drive" in answer["detail"]
        code, answer = post(url + "api/plan/preview", body)
        assert code == 409 and "fault is latched" in answer["detail"], answer
        page.click("#reset-faults")
        expect(page.locator("#state")).to_have_text("idle", timeout=10_000)
        expect(page.locator("#fault")).to_be_hidden()
        expect(page.locator("#notice")).to_contain_text("faults reset")

        # the reset is in the store's audit trail with who and when
        audit = [a for a in Store(tmp_path / "store").audit() if a["action"] == "fault reset"]
        assert audit and "A. Operator" in json.dumps(audit[-1]["detail"])
        assert "SETPOINT_OVER_LIMIT" in json.dumps(audit[-1]["detail"])

        # 2. an E-stop while idle: never "idle" until acknowledged
        page.click("#estop")
        expect(page.locator("#state")).to_have_text("fault", timeout=10_000)
        expect(page.locator("#fault-action")).to_contain_text("E-stop")
        page.click("#reset-faults")
        expect(page.locator("#state")).to_have_text("idle", timeout=10_000)

        # 3. history: the numbers beside a stored loop are that run's, after the poll too
        # (the second run at 180 deg: the runout gives it another lost motion; no limit)
        page.fill("#setup input[name=lost_motion_arcmin_max]", "")
        page.fill("#lock-angle", "180")
        start_run(page)
        expect(page.locator("#state")).to_have_text("completed", timeout=120_000)
        latest = get_json(url + "api/runs")[0]
        assert latest["run_id"] != first["run_id"]
        labels = {r["run_id"]: Store(tmp_path / "store").load_run(r["run_id"]).meta["label"]
                  for r in (first, latest)}
        assert labels[latest["run_id"]].startswith("pos180-"), labels
        assert labels[first["run_id"]].startswith("pos000-"), labels
        page.click(f"a[data-run='{first['run_id']}']")
        expect(page.locator("#loop-title")).to_contain_text(first["run_id"])
        page.wait_for_timeout(2500)  # two status polls later
        shown = float(page.locator("#m-lost").inner_text())
        assert shown == pytest.approx(first["metrics"]["lost_motion_arcmin"], abs=0.0005)
        assert shown != pytest.approx(latest["metrics"]["lost_motion_arcmin"], abs=0.0005)
        expect(page.locator("#m-verdict")).to_have_text("NOT OK")  # over its 1' limit

        # 4. issue 21 item 14: every history row says its verdict in the one vocabulary, with
        # its lost motion; a failed campaign is NOT OK (never FAIL), at 1440 and at 390 px
        page.click("#refresh")
        runs = {r["run_id"]: r for r in get_json(url + "api/runs")}
        for run_id, word in ((first["run_id"], "NOT OK"), (latest["run_id"], "NO LIMITS")):
            row = history_row(page, "runs", run_id)
            expect(row.locator("td.verdict")).to_have_text(word)
            lm = runs[run_id]["metrics"]["lost_motion_arcmin"]
            u = runs[run_id]["metrics"]["uncertainty"]["lost_motion_arcmin"]
            expect(row.locator("td.lost-motion")).to_have_text(f"{lm:.3f} ± {u:.3f}")
        camp = history_row(page, "campaigns", failed_campaign)
        expect(camp.locator("td.verdict")).to_contain_text("NOT OK")
        expect(camp.locator("td.verdict")).to_contain_text("is above the limit 2")
        for width, height in ((1440, 900), (390, 844)):
            page.set_viewport_size({"width": width, "height": height})
            history = page.locator("#history-panel")
            history.scroll_into_view_if_needed()
            expect(history_row(page, "runs", first["run_id"]).locator("td.verdict")
                   ).to_be_visible()
            assert "FAIL" not in history.inner_text() and "PASS" not in history.inner_text()
            assert page.locator("#runs td.verdict").count() == len(runs)
        page.set_viewport_size({"width": 1440, "height": 900})
        page.screenshot(path=str(ARTIFACTS / "operator-history.png"))
        assert not errors, errors
        browser.close()
