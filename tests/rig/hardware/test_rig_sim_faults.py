"""Backdoor faults of the in-process simulated rig show in ``rig devices``, per device.

The simulated rig runs in this process (for its backdoors); ``rig devices`` runs as its own
process over the real protocols (pty, SLCAN on TCP, Modbus TCP).
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from rig.hardware.config import load_rig_config
from rig.hardware.device_check import check_devices
from rig.hardware.simrig import SimulatedRig

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

RIG = [sys.executable, "-c", "from rig.cli import main; main()"]


@pytest.fixture
def sim():
    with SimulatedRig(seed=11, sync_period_s=0.005) as rig:
        yield rig


def _errors(dev: dict) -> str:
    return " | ".join(e["message"] for e in dev["errors"])


def test_faults_show_for_their_device_only(sim, tmp_path):
    backdoors = sim.backdoors
    backdoors["modbus"].exception(sim.modbus_server.sensor_id, 4)  # DEVICE FAILURE
    backdoors["input_encoder"].silence()  # no PDOs: the driver times out
    backdoors["transducer"].error_replies(7)  # ERR 7 internal fault to every command
    report = tmp_path / "devices.json"
    proc = subprocess.run([*RIG, "devices", "--rig", str(sim.rig_config_path), "--seconds",
                           "1.5", "--json", str(report)], capture_output=True, text=True,
                          timeout=90)
    assert proc.returncode == 1, (proc.stdout, proc.stderr)
    doc = json.loads(report.read_text(encoding="utf-8"))
    devices = doc["devices"]
    assert doc["healthy"] is False
    sensor = devices["torque_sensor"]
    assert "Modbus exception code 4" in _errors(sensor) and sensor["samples"] == 0
    assert "torque sensor (Modbus unit 1" in _errors(sensor)
    assert "input encoder (CANopen node 2" in _errors(devices["input_encoder"])
    assert "expected a position PDO" in _errors(devices["input_encoder"])
    assert "ERR 7 internal fault" in _errors(devices["transducer"])
    assert _errors(devices["transducer"]).startswith("did not open:")
    for name in ("encoder", "drive", "input_motor", "climate"):
        assert devices[name]["healthy"] and devices[name]["samples"] > 0, (name, devices[name])


def test_a_stuck_sensor_gives_samples_then_errors(sim):
    sim.backdoors["modbus"].stick_sensor()
    config = load_rig_config(sim.rig_config_path)
    reports = {r.name: r for r in check_devices(config, seconds=2.0)}
    sensor = reports["torque_sensor"]
    assert sensor.samples > 0  # until the counter has been still for stale_after_s (1 s)
    assert any("counter stuck" in message for message in sensor.errors)
    assert not sensor.healthy
    healthy = [name for name, rep in reports.items() if rep.healthy]
    assert sorted(healthy) == sorted(set(reports) - {"torque_sensor"})


def test_a_silent_drive_is_reported_not_raised(sim):
    config = load_rig_config(sim.rig_config_path)
    sim.backdoors["modbus"].silence(sim.modbus_server.drive_id)
    reports = {r.name: r for r in check_devices(config, seconds=1.0)}
    assert "drive" in reports and not reports["drive"].healthy
    assert any("loading drive" in m for m in reports["drive"].errors)
    assert reports["torque_sensor"].healthy and reports["encoder"].healthy
