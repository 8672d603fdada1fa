"""Device loss and a killed measuring process: the run is kept and marked aborted, and the
simulated drive ends disabled (by the engine, or by its own watchdog)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from rig.hardware.config import load_rig_config
from rig.hardware.devices import open_rig
from rig.hardware.simrig import SimulatedRig
from rig.measurement.service import (
    measure_plan,
    open_session,
    plant_config_for,
    run_meta,
    write_plant_toml,
)
from rig.plans import LoopParams, hysteresis_plan
from rig.plans.campaign_file import SimulationSection
from rig.runformat import read_run
from rig.store import RECOVERED_REASON, Store
from simulators.plant.config import load_plant_config

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

DRAG = {"effects": {"friction": {"enabled": True, "model": "lugre",
                                 "viscous_Nms_per_arcmin": 0.002}}}
UNIT = dict(load_plant_config().unit, serial="fault-unit")
PLANT = plant_config_for(UNIT, SimulationSection(plant=DRAG))
LONG = LoopParams(rated_torque_Nm=10.0, steps_per_quarter=2, dwell_s=0.0, pre_cycles=0,
                  cycles=20, rate_Nm_per_s=25.0)


def test_losing_every_device_mid_run_aborts_and_keeps_the_samples(tmp_path) -> None:
    store = Store(tmp_path / "store")
    with open_session(simulated=True, plant=PLANT) as session:
        started = threading.Event()
        box: dict = {}

        def target():
            box["engine"], box["outcomes"] = measure_plan(
                session, store, hysteresis_plan(LONG), run_meta(UNIT, session),
                progress=lambda e: e.kind == "run_started" and started.set())

        thread = threading.Thread(target=target, daemon=True)
        thread.start()
        assert started.wait(30)
        time.sleep(1.0)
        os.kill(session.simulated.process.pid, signal.SIGKILL)  # the whole rig vanishes
        thread.join(60)
        assert not thread.is_alive() and box["engine"].state == "aborted"
        (outcome,) = box["outcomes"]
        assert outcome.status == "aborted"
        # the reason names the device that noticed first, what was expected and what came
        assert any(name in outcome.reason for name in
                   ("encoder", "torque transducer", "drive", "torque sensor", "acquisition"))
        assert "expected" in outcome.reason
        run = read_run(outcome.path)
        assert run.n_samples > 100 and run.meta["status"] == "aborted"


def test_sigkill_of_rig_measure_keeps_the_run_and_the_drive_falls_safe(tmp_path) -> None:
    plant_toml = write_plant_toml(PLANT, tmp_path / "plant.toml")
    store_dir = tmp_path / "store"
    with SimulatedRig(plant_toml, in_process=False, rig_config_path=tmp_path / "rig.toml",
                      sync_period_s=0.004, stream_rate_Hz=250.0) as sim:
        cmd = [sys.executable, "-c", "from rig.cli import main; main()", "measure",
               "--rig", str(sim.rig_config_path), "--store", str(store_dir),
               "--cycles", "20", "--pre-cycles", "0", "--steps", "2"]
        log = (tmp_path / "measure.log").open("w")
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
        try:
            deadline = time.monotonic() + 60
            samples = []
            while time.monotonic() < deadline and proc.poll() is None:
                samples = list((store_dir / "runs").glob("*/samples.csv"))
                if samples and samples[0].stat().st_size > 20_000:
                    break
                time.sleep(0.2)
            assert samples, (tmp_path / "measure.log").read_text()
            proc.send_signal(signal.SIGKILL)
            proc.wait(10)
        finally:
            if proc.poll() is None:
                proc.kill()
            log.close()
        store = Store(store_dir)  # the next opening finds the run and marks it aborted
        (info,) = store.list_runs()
        assert info.status == "aborted" and info.reason == RECOVERED_REASON
        assert read_run(info.path, allow_truncated_tail=True).n_samples > 100
        # nobody feeds the drive's watchdog any more: it has disabled the drive by itself
        time.sleep(1.0)
        with open_rig(load_rig_config(sim.rig_config_path)) as devices:
            status = devices.drive.status()
        assert not status.enabled and status.watchdog_tripped
