"""Issue 21 item 6: a start that moved the drive leaves an aborted run with its reason, even
when it stops before its recording begins (the torque zero, the preload, the pre-cycles).

Over the simulated rig and the real protocols: an encoder heartbeat lost during the
pre-cycle (the simulated rig in this process, for its backdoor), an E-stop during the
pre-cycle through the web API (FastAPI's TestClient, the simulated rig its own process),
and SIGTERM to a ``rig serve --simulated`` process during the first ramp. Each run is in
the store's index (``rig runs``, ``/api/runs``) and its audit trail with its reason.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

import pytest

from rig.hardware.simrig import SimulatedRig
from rig.measurement.service import measure_plan, open_session, plant_config_for, run_meta
from rig.plans import LoopParams, hysteresis_plan
from rig.plans.campaign_file import SimulationSection
from rig.runformat import read_run
from rig.store import Store
from rig.web.simulated import example_unit
from simulators.plant.config import load_plant_config
from tests.support.serve import page_lines, started
from tests.support.simulated_page import identified, page_on, wait_for

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(240)]

RIG = [sys.executable, "-c", "from rig.cli import main; main()"]
TOKEN = "rig-test-operator"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
PRE_CYCLE_PLAN = {"rated_torque_Nm": 10.0, "mode": "constant_rate", "pre_cycles": 3,
                  "rate_Nm_per_s": 5.0}
"""Three slow pre-cycles (6 s a ramp): the stop comes long before the recording begins."""


def assert_aborted_record(store: Store, reason_part: str) -> dict[str, Any]:
    """The store's one run: aborted with ``reason_part`` in its reason, in the index, in
    its run.json and in the audit trail (started, then aborted with the reason)."""
    (info,) = store.list_runs()
    assert info.status == "aborted", info
    assert reason_part in (info.reason or ""), info.reason
    run = read_run(info.path)
    assert run.meta["status"] == "aborted" and run.meta["reason"] == info.reason
    assert run.meta["outcome"] == "incomplete"
    notes = (run.meta.get("result") or {}).get("engine_notes") or []
    assert any("before its recording began" in n for n in notes), notes
    actions = [(a["action"], (a.get("detail") or {}).get("reason"))
               for a in store.audit(info.run_id)]
    assert actions[0][0] == "run started" and actions[-1] == ("run aborted", info.reason)
    return {"info": info, "run": run}


def test_heartbeat_lost_in_the_pre_cycle_leaves_an_aborted_run(tmp_path: Path):
    unit = dict(load_plant_config().unit, serial="pre-cycle-heartbeat")
    plant = plant_config_for(unit, SimulationSection(seed=3))
    plan = hysteresis_plan(LoopParams(rated_torque_Nm=10.0, steps_per_quarter=2,
                                      dwell_s=0.1, pre_cycles=2, cycles=1,
                                      rate_Nm_per_s=10.0))
    store = Store(tmp_path / "store")
    with SimulatedRig(plant, seed=3, sync_period_s=0.004, stream_rate_Hz=250.0) as sim:
        injected = threading.Event()

        def progress(event: Any) -> None:
            # the second ramp of the preload is a pre-cycle's (-10 -> +10 N*m)
            if (not injected.is_set() and event.kind == "step"
                    and event.message.startswith("torque to +10")):
                sim.backdoors["encoder"].lose_heartbeat()
                injected.set()

        with open_session(rig=sim.rig_config_path) as session:
            engine, outcomes = measure_plan(session, store, plan, run_meta(unit, session),
                                            progress=progress)
        drive = sim.modbus_server.drive
        assert not drive.enabled and drive.setpoint_Nm == 0.0
    assert injected.is_set() and engine.state == "aborted"
    (outcome,) = outcomes
    assert outcome.status == "aborted" and "heartbeat" in outcome.reason, outcome.reason
    got = assert_aborted_record(store, "heartbeat")
    run = got["run"]
    assert run.n_samples > 100  # the preload and the pre-cycle so far, at 250 Hz
    assert run.torque_Nm.min() < -8.0  # the preload reached -10 N*m: it is in the record
    assert got["info"].run_id == outcome.run_id


@pytest.fixture
def page(simulated_rig, tmp_path: Path):
    with page_on(simulated_rig, tmp_path / "store", TOKEN) as (client, store, _):
        yield client, store


def test_sigterm_to_rig_serve_in_the_first_ramp_leaves_an_aborted_run(tmp_path: Path):
    store_dir = tmp_path / "store"
    cmd = [*RIG, "serve", "--simulated", "--port", "0", "--store", str(store_dir),
           "--token", TOKEN]
    with started(cmd, tmp_path) as (proc, stderr):
        url = page_lines(proc, stderr)["control page"]

        def call(path: str, body: dict | None = None) -> Any:
            req = urllib.request.Request(
                url + path.lstrip("/"), method="GET" if body is None else "POST",
                data=None if body is None else json.dumps(body).encode(),
                headers={**AUTH, "Content-Type": "application/json"})
            with urllib.request.urlopen(req, timeout=30) as answer:
                return json.loads(answer.read())

        deadline = time.monotonic() + 90
        while call("/api/status")["state"] != "idle":
            assert time.monotonic() < deadline, "the simulated rig did not open"
            time.sleep(0.3)
        call("/api/devices/input-lock", {"angle_deg": 0.0})
        call("/api/control/start", identified({"unit": example_unit("seed000-pair1"),
                                               "plan": PRE_CYCLE_PLAN}))
        deadline = time.monotonic() + 60
        seen = []
        while True:  # the first ramp (0 -> -10 N*m at 5 N*m/s), before the recording
            status = call("/api/status")
            progress = status.get("progress") or {}
            seen.append((status["state"], progress.get("description")))
            if (progress.get("description") or "").startswith("torque to -10"):
                assert progress.get("run_id") is None, status
                break
            assert status["state"] == "running" and time.monotonic() < deadline, seen
            time.sleep(0.02)
        time.sleep(1.0)  # about -5 N*m
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=60)
    listing = subprocess.run([*RIG, "runs", "--store", str(store_dir), "--json", "-"],
                             capture_output=True, text=True, timeout=60)
    assert listing.returncode == 0, listing.stderr
    (row,) = json.loads(listing.stdout)["runs"]
    assert row["status"] == "aborted" and "shut down" in row["reason"], row
    got = assert_aborted_record(Store(store_dir), "shut down")
    assert got["run"].torque_Nm.min() < -2.0


def test_estop_in_the_pre_cycle_through_the_web_api_leaves_an_aborted_run(page):
    client, store = page
    unit = example_unit("seed000-pair1")
    lock = client.post("/api/devices/input-lock", json={"angle_deg": 0.0}, headers=AUTH)
    assert lock.status_code == 200, lock.text
    r = client.post("/api/control/start", json=identified({"unit": unit, "plan": PRE_CYCLE_PLAN}),
                    headers=AUTH)
    assert r.status_code == 200, r.text
    # in the first pre-cycle, on its way up from the preload's -10 N*m: torque applied
    status = wait_for(client, lambda s: (s.get("progress") or {}).get("description", "")
                      .startswith("torque to +10"), 90.0)
    assert status["progress"]["run_id"] is None  # the recording has not begun
    time.sleep(0.5)
    stop = client.post("/api/control/estop")
    assert stop.status_code == 200, stop.text
    wait_for(client, lambda s: s["state"] == "fault", 60.0)
    got = assert_aborted_record(store, "E-stop")
    assert got["run"].n_samples > 100
    assert got["run"].torque_Nm.min() < -8.0
    listed = client.get("/api/runs").json()
    assert [(r["run_id"], r["status"]) for r in listed] == [(got["info"].run_id, "aborted")]
    assert "E-stop" in listed[0]["reason"]
