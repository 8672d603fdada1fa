"""``rig sim`` as its own process, driven over the real protocols from this process.

The contract (issue 3): the first output line is one JSON object with every device's address
and "rig_config"; that file connects ``rig devices`` and ``open_rig`` to every device; one
GearPlant drives them all; SIGTERM stops it cleanly with exit 0.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from rig.hardware.config import load_rig_config
from rig.hardware.devices import open_rig
from rig.hardware.simrig import SimulatedRig
from simulators.plant import GearPlant
from simulators.plant.config import load_plant_config
from tests.support.devices import first_line, mean_angle, wait_alive

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

RIG = [sys.executable, "-c", "from rig.cli import main; main()"]
TORQUE_NM = 10.0


@pytest.fixture(scope="module")
def sim():
    proc = subprocess.Popen([*RIG, "sim", "--seed", "3"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    line = first_line(proc)
    if not line:
        proc.kill()
        pytest.fail(f"rig sim printed nothing: {proc.stderr.read()}")
    yield proc, json.loads(line)
    if proc.poll() is None:
        proc.kill()
        proc.wait(timeout=20)


def test_first_line_names_every_device_and_the_rig_config(sim):
    _, info = sim
    assert info["modbus_tcp"].startswith("127.0.0.1:")
    assert info["encoder_slcan"].startswith("socket://127.0.0.1:")
    assert info["transducer"].startswith("/dev/pts/")
    assert info["encoder_nodes"] == {"encoder": 1, "input_encoder": 2}
    config = load_rig_config(info["rig_config"])
    assert config.can.channel == info["encoder_slcan"]
    assert config.transducer.url == info["transducer"]
    assert f"{config.drive.host}:{config.drive.port}" == info["modbus_tcp"]


def test_rig_devices_reports_every_device_healthy(sim, tmp_path):
    _, info = sim
    report = tmp_path / "devices.json"
    proc = subprocess.run([*RIG, "devices", "--rig", info["rig_config"], "--seconds", "2",
                           "--json", str(report)], capture_output=True, text=True, timeout=90,
                          env={**os.environ, "COLUMNS": "200"})  # the table whole
    doc = json.loads(report.read_text(encoding="utf-8"))
    assert proc.returncode == 0, (proc.stdout, proc.stderr)
    assert doc["healthy"] is True
    assert set(doc["devices"]) == {"encoder", "input_encoder", "transducer", "torque_sensor",
                                   "drive", "input_motor", "climate"}
    for name, dev in doc["devices"].items():
        assert dev["samples"] > 0, name
        assert dev["errors"] == [], name
        assert dev["rate_Hz"] > 0, name
    assert doc["devices"]["transducer"]["info"]["temperature_C"] == pytest.approx(20.0)
    assert doc["devices"]["climate"]["last"] == pytest.approx(20.0)
    assert "torque_sensor" in proc.stdout  # the rich table


def test_drive_torque_reaches_every_sensor_as_the_plant_says(sim):
    _, info = sim
    config = load_rig_config(info["rig_config"])
    truth = GearPlant(load_plant_config())  # the same default plant, for its closed forms
    twist = truth.true_twist_arcmin(np.linspace(0.0, TORQUE_NM, 201))
    expected_arcmin = twist[-1] - twist[0]
    with open_rig(config) as rig:
        before = mean_angle(rig.encoder)
        rig.drive.set_torque(TORQUE_NM)
        rig.drive.enable()
        wait_alive(rig, 0.6)  # drive lag 10 ms; the output settles well within this
        after = mean_angle(rig.encoder)
        transducer = np.mean([rig.transducer.read().torque_Nm for _ in range(10)])
        sensor = np.mean([rig.torque_sensor.read().torque_Nm for _ in range(10)])
        status = rig.drive.status()
        assert rig.safe_state()
        wait_alive(rig, 0.3)
        relaxed = rig.torque_sensor.read().torque_Nm
    assert status.enabled and status.actual_torque_Nm == pytest.approx(TORQUE_NM)
    # noise 0.005 N*m rms per reading (docs/plant.md), averaged over 10
    assert transducer == pytest.approx(TORQUE_NM, abs=0.01)
    assert sensor == pytest.approx(TORQUE_NM, abs=0.01)
    # play (4.28 arcmin) + T/K: 0.3 arcsec noise and 0.15 arcsec quantisation, averaged
    assert (after - before) * 60.0 == pytest.approx(expected_arcmin, abs=0.01)
    assert abs(relaxed) < 0.05


def test_input_motor_turns_both_encoders_by_the_gear_ratio(sim):
    _, info = sim
    config = load_rig_config(info["rig_config"])
    ratio = GearPlant(load_plant_config()).true_parameters()["ratio"]
    with open_rig(config) as rig:
        # a small preload holds the output on one flank (inside the play it would be free),
        # so the twist is the same before and after the move: the play does not depend on
        # the input angle with the default plant's effects off
        rig.drive.set_torque(2.0)
        rig.drive.enable()
        wait_alive(rig, 0.5)
        out0, in0 = mean_angle(rig.encoder), mean_angle(rig.input_encoder)
        state = rig.input_motor.lock_at(in0 + 45.0, timeout_s=10.0)
        assert state.locked and not state.moving
        wait_alive(rig, 0.3)
        out1, in1 = mean_angle(rig.encoder), mean_angle(rig.input_encoder)
        rig.input_motor.lock_at(in0, timeout_s=10.0)
    assert in1 - in0 == pytest.approx(45.0, abs=1e-4)
    assert out1 - out0 == pytest.approx(-45.0 / ratio, abs=2e-4)  # 0.7 arcsec


def test_sigterm_stops_rig_sim_cleanly(sim):
    proc, info = sim
    rig_config = Path(info["rig_config"])
    assert rig_config.exists()
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=30) == 0, proc.stderr.read()
    assert not rig_config.exists()  # its temporary folder is gone


def test_simulated_rig_out_of_process_with_rtu_and_tcp_transducer(tmp_path):
    sim = SimulatedRig(in_process=False, transducer="tcp", modbus="rtu-tcp", seed=5,
                       input_encoder=False, rig_config_path=tmp_path / "rig.toml")
    with sim:
        assert sim.addresses["modbus_rtu"].startswith("socket://127.0.0.1:")
        assert sim.addresses["transducer"].startswith("socket://127.0.0.1:")
        config = load_rig_config(sim.rig_config_path)
        assert config.input_encoder is None and config.drive.transport == "rtu"
        with open_rig(config) as rig:
            rig.drive.set_torque(-5.0)
            rig.drive.enable()
            wait_alive(rig, 0.3)
            assert rig.transducer.read().torque_Nm == pytest.approx(-5.0, abs=0.03)
            assert rig.torque_sensor.read().torque_Nm == pytest.approx(-5.0, abs=0.03)
        assert sim.process is not None and sim.process.poll() is None
    assert sim.process is None and sim.exit_code == 0
    assert "Traceback" not in sim.stderr_final


def test_rig_sim_refuses_a_bad_plant_file(tmp_path):
    plant = tmp_path / "plant.toml"
    plant.write_text("[unit]\nkind = 'internal_involute'\n[rig]\nstep_s = -1\n",
                     encoding="utf-8")
    proc = subprocess.run([*RIG, "sim", "--config", str(plant)], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 2 and proc.stdout == ""
    assert f"rig: error: {plant}: key rig.step_s" in proc.stderr


def test_a_simulator_started_by_a_killed_program_stops_too():
    """A measuring program that starts `rig sim` out of process and is killed with -9 leaves
    no simulator behind: orphans kept the CI box loaded for the rest of the suite."""
    import os

    parent = subprocess.Popen(
        [sys.executable, "-c", "import time\nfrom rig.hardware.simrig import SimulatedRig\n"
         "s = SimulatedRig(None, in_process=False)\ns.start()\n"
         "print(s.process.pid, flush=True)\ntime.sleep(600)"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = first_line(parent)
        assert line.strip(), parent.stderr.read() if parent.poll() is not None else "no pid"
        child = int(line)
        os.kill(parent.pid, signal.SIGKILL)
        parent.wait(10)
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline:
            try:
                os.kill(child, 0)
            except ProcessLookupError:
                break
            time.sleep(0.1)
        else:
            os.kill(child, signal.SIGKILL)
            pytest.fail("the simulator outlived the program that started it")
    finally:
        if parent.poll() is None:
            parent.kill()
