"""The drivers against the Modbus simulator running in a separate process.

``python -m simulators.modbus.server`` prints its address as JSON on its first stdout line
and serves until killed; this is how ``rig sim`` and a technician start it.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest

from drivers.errors import DeviceDisconnected, DeviceError
from drivers.loading_drive import LoadingDrive, LoadingDriveConfig
from drivers.modbus.torque_sensor import ModbusTorqueSensor, ModbusTorqueSensorConfig

TIMEOUT_S = 2.0


def start_simulator(*args: str) -> tuple[subprocess.Popen, dict]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "simulators.modbus.server", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline()  # blocks until the server listens (or the process dies)
    if not line:
        proc.kill()
        pytest.fail(f"the simulator printed no address: {proc.stderr.read()}")
    return proc, json.loads(line)


def stop_simulator(proc: subprocess.Popen) -> None:
    proc.terminate()
    try:
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout=20)


@pytest.mark.parametrize("transport", ["tcp", "rtu-tcp"])
def test_drivers_against_a_simulator_process(transport):
    proc, info = start_simulator("--transport", transport, "--torque-limit", "15")
    try:
        if transport == "tcp":
            host, port = info["modbus_tcp"].rsplit(":", 1)
            assert host == "127.0.0.1"
            where = {"transport": "tcp", "host": host, "port": int(port)}
        else:
            assert info["modbus_rtu"].startswith("socket://127.0.0.1:")
            where = {"transport": "rtu", "serial_url": info["modbus_rtu"]}
        assert (info["sensor_id"], info["drive_id"]) == (1, 2)
        sensor = ModbusTorqueSensor(ModbusTorqueSensorConfig(**where, timeout_s=TIMEOUT_S))
        drive = LoadingDrive(LoadingDriveConfig(**where, torque_limit_Nm=10.0,
                                                timeout_s=TIMEOUT_S, watchdog_s=5.0),
                             link=sensor.link)
        try:
            idle = sensor.read()  # the sine test plant: |T| <= 1 N*m while the drive is off
            assert abs(idle.torque_Nm) <= 1.0 and sensor.full_scale_Nm == 22.5
            assert drive.drive_limit_Nm == 15.0 and drive.torque_limit_Nm == 10.0
            drive.set_torque(4.0)
            drive.enable()
            assert sensor.read().torque_Nm == 4.0
            drive.safe_state()
            assert drive.status().actual_torque_Nm == 0.0
        finally:
            drive.close()
            sensor.close()
    finally:
        stop_simulator(proc)
    assert proc.returncode == 0, proc.stderr.read()


def test_killed_simulator_gives_a_device_error_in_bounded_time():
    proc, info = start_simulator("--transport", "tcp")
    host, port = info["modbus_tcp"].rsplit(":", 1)
    sensor = ModbusTorqueSensor(ModbusTorqueSensorConfig(host=host, port=int(port),
                                                         timeout_s=TIMEOUT_S))
    try:
        sensor.read()
        proc.kill()
        proc.wait(timeout=20)
        t0 = time.monotonic()
        with pytest.raises(DeviceError) as info_exc:
            sensor.read()
        assert time.monotonic() - t0 < 5 * TIMEOUT_S
        assert isinstance(info_exc.value, DeviceDisconnected)
        assert f"tcp {host}:{port}" in str(info_exc.value)
    finally:
        sensor.close()
        if proc.poll() is None:
            proc.kill()
