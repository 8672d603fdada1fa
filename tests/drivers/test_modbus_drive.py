"""The loading drive driver against the simulated drive over Modbus TCP (and RTU).

Safety is checked on both sides: the driver refuses setpoints beyond its limit before
sending, and the simulated drive refuses them from any master (here a raw pymodbus client
standing in for a faulty one) with an exception and a latched fault code.
"""

from __future__ import annotations

import time

import pytest
from pydantic import ValidationError
from pymodbus.client import ModbusTcpClient

from drivers.errors import DeviceDisconnected, DeviceFault, DeviceOutOfRange, DeviceTimeout
from drivers.loading_drive import LoadingDrive, LoadingDriveConfig
from drivers.modbus.map import LOADING_DRIVE_MAP, DriveFaultCode, encode_float32
from simulators.modbus.plant_backdoor import SineTestPlant
from simulators.modbus.server import ModbusRigServer

TIMEOUT_S = 1.0
BOUND_S = 10.0
DRIVE_LIMIT_NM = 20.0


@pytest.fixture
def rig():
    plant = SineTestPlant(amplitude_Nm=0.0)
    server = ModbusRigServer(plant, DRIVE_LIMIT_NM, watchdog_s=5.0)
    host, port = server.start().rsplit(":", 1)
    config = LoadingDriveConfig(host=host, port=int(port), timeout_s=TIMEOUT_S,
                                torque_limit_Nm=12.0, watchdog_s=5.0)
    drive = LoadingDrive(config)
    yield server, drive, plant
    drive.close()
    server.stop()


@pytest.fixture
def raw_master(rig):
    """A Modbus master that is not our driver (no driver-side limits)."""
    server = rig[0]
    host, port = server.address.rsplit(":", 1)
    client = ModbusTcpClient(host, port=int(port), timeout=TIMEOUT_S, retries=0)
    assert client.connect()
    yield client
    client.close()


def test_setpoint_reaches_the_plant_when_enabled(rig):
    server, drive, plant = rig
    drive.set_torque(7.5)
    assert plant.snapshot().true_torque_Nm == 0.0  # still disabled
    drive.enable()
    status = drive.status()
    assert status.enabled and not status.faulted
    assert status.setpoint_Nm == 7.5 and status.actual_torque_Nm == 7.5
    drive.set_torque(-3.0)
    assert plant.snapshot().true_torque_Nm == -3.0
    assert plant.commands[-1][1] == -3.0


def test_effective_limit_is_the_smaller_of_config_and_drive(rig):
    server, drive, _ = rig
    assert drive.drive_limit_Nm == DRIVE_LIMIT_NM and drive.torque_limit_Nm == 12.0
    host, port = server.address.rsplit(":", 1)
    loose = LoadingDrive(LoadingDriveConfig(host=host, port=int(port), torque_limit_Nm=50.0,
                                            watchdog_s=5.0, timeout_s=TIMEOUT_S))
    try:
        assert loose.torque_limit_Nm == DRIVE_LIMIT_NM
        with pytest.raises(DeviceOutOfRange):
            loose.set_torque(20.5)
    finally:
        loose.close()


def test_limits_cannot_be_raised_after_load(rig):
    """Fault-matrix row 13: a script assigning a higher limit to the driver or to its
    configuration is refused; the setpoint is checked against the loaded limit still."""
    server, drive, plant = rig
    with pytest.raises(AttributeError):
        drive.torque_limit_Nm = 1000.0
    with pytest.raises(ValidationError, match="frozen"):
        drive.config.torque_limit_Nm = 1000.0
    drive.set_torque(1.0)
    drive.enable()
    with pytest.raises(DeviceOutOfRange):
        drive.set_torque(15.0)
    assert server.drive.setpoint_Nm == 1.0 and plant.snapshot().true_torque_Nm == 1.0


@pytest.mark.parametrize("value", [12.001, -12.5, float("nan"), float("inf"), 1e9])
def test_driver_refuses_setpoints_beyond_its_limit_without_sending(rig, value):
    server, drive, plant = rig
    drive.set_torque(1.0)
    drive.enable()
    requests = drive.link.requests
    with pytest.raises(DeviceOutOfRange, match=r"within \+-12 N\*m") as info:
        drive.set_torque(value)
    assert "loading drive (Modbus unit 2 on tcp 127.0.0.1:" in info.value.device
    assert drive.link.requests == requests  # nothing went on the wire
    assert server.drive.setpoint_Nm == 1.0 and plant.snapshot().true_torque_Nm == 1.0


def test_drive_refuses_over_limit_from_any_master_and_latches_fault(rig, raw_master):
    server, drive, plant = rig
    drive.set_torque(5.0)
    drive.enable()
    reply = raw_master.write_registers(LOADING_DRIVE_MAP["setpoint"].address,
                                       encode_float32(25.0), device_id=2)
    assert reply.isError() and reply.exception_code == 3  # ILLEGAL DATA VALUE
    status = drive.status()
    assert status.fault_code == DriveFaultCode.SETPOINT_OVER_LIMIT and status.limit_hit
    assert not status.enabled and status.actual_torque_Nm == 0.0
    assert plant.snapshot().true_torque_Nm == 0.0 and max(c for _, c in plant.commands) == 5.0
    # while the fault is latched: no enable, no torque, but the safe state is accepted
    with pytest.raises(DeviceFault, match="exception code 4.*fault code 1 SETPOINT_OVER_LIMIT"):
        drive.enable()
    with pytest.raises(DeviceFault, match="fault code 1"):
        drive.set_torque(1.0)
    drive.safe_state()
    drive.reset_fault()
    drive.set_torque(2.0)
    drive.enable()
    assert drive.status().actual_torque_Nm == 2.0 and drive.health().ok


def test_drive_refuses_nan_setpoint(rig, raw_master):
    server, drive, _ = rig
    reply = raw_master.write_registers(LOADING_DRIVE_MAP["setpoint"].address,
                                       [0x7FC0, 0x0000], device_id=2)
    assert reply.isError() and reply.exception_code == 3
    assert drive.status().fault_code == DriveFaultCode.SETPOINT_NOT_FINITE
    assert not drive.health().ok


def test_safe_state_is_idempotent_and_one_request(rig):
    server, drive, plant = rig
    drive.set_torque(9.0)
    drive.enable()
    for _ in range(25):
        before = drive.link.requests
        drive.safe_state()
        assert drive.link.requests == before + 1
        status = drive.status()
        assert not status.enabled and status.setpoint_Nm == 0.0
        assert status.actual_torque_Nm == 0.0 and not status.faulted
    assert plant.snapshot().true_torque_Nm == 0.0 and server.drive.setpoint_Nm == 0.0


def test_watchdog_time_is_written_on_open(rig):
    server, drive, _ = rig
    assert server.drive.watchdog_ms == 5000


def test_watchdog_zeroes_torque_when_the_master_goes_silent():
    plant = SineTestPlant(amplitude_Nm=0.0)
    server = ModbusRigServer(plant, DRIVE_LIMIT_NM)
    host, port = server.start().rsplit(":", 1)
    drive = LoadingDrive(LoadingDriveConfig(host=host, port=int(port), torque_limit_Nm=10.0,
                                            watchdog_s=0.5, timeout_s=TIMEOUT_S))
    try:
        drive.set_torque(6.0)
        drive.enable()
        t_end = time.monotonic() + 1.2  # fed every 50 ms for 2.4 watchdog times: stays on
        while time.monotonic() < t_end:
            drive.keepalive()
            last_feed = time.monotonic()
            time.sleep(0.05)
        assert drive.status().enabled and plant.snapshot().true_torque_Nm == 6.0
        status = drive.status()  # reads do not feed the watchdog
        while status.enabled and time.monotonic() - last_feed < BOUND_S:
            time.sleep(0.05)
            status = drive.status()
        assert time.monotonic() - last_feed >= 0.5
        assert status.fault_code == DriveFaultCode.WATCHDOG_TIMEOUT and status.watchdog_tripped
        assert not status.enabled and status.actual_torque_Nm == 0.0
        assert plant.snapshot().true_torque_Nm == 0.0 and plant.commands[-1][1] == 0.0
        with pytest.raises(DeviceFault, match="WATCHDOG_TIMEOUT"):
            drive.set_torque(1.0)
    finally:
        drive.close()
        server.stop()


def test_close_leaves_the_drive_safe(rig):
    server, drive, plant = rig
    drive.set_torque(4.0)
    drive.enable()
    drive.close()
    assert not server.drive.enabled and plant.snapshot().true_torque_Nm == 0.0


def test_opening_an_absent_drive_is_disconnected(rig):
    server, drive, _ = rig
    host, port = server.address.rsplit(":", 1)
    server.stop()
    t0 = time.monotonic()
    with pytest.raises(DeviceDisconnected, match="refused"):
        LoadingDrive(LoadingDriveConfig(host=host, port=int(port), torque_limit_Nm=1.0,
                                        timeout_s=TIMEOUT_S))
    assert time.monotonic() - t0 < BOUND_S


def test_silent_drive_on_open_is_a_timeout(rig):
    server, _, _ = rig
    server.backdoor.silence(2)
    host, port = server.address.rsplit(":", 1)
    with pytest.raises(DeviceTimeout) as info:
        LoadingDrive(LoadingDriveConfig(host=host, port=int(port), torque_limit_Nm=1.0,
                                        timeout_s=0.3))
    assert f"tcp {server.address}" in str(info.value) and "unit 2" in str(info.value)


def test_rtu_config_needs_a_serial_url():
    with pytest.raises(ValueError, match="serial_url"):
        LoadingDriveConfig(transport="rtu", torque_limit_Nm=1.0)
    with pytest.raises(ValueError, match="greater than 0"):
        LoadingDriveConfig(torque_limit_Nm=0.0)
    config = LoadingDriveConfig.model_validate(
        {"transport": "rtu", "serial_url": "socket://127.0.0.1:15021", "torque_limit_Nm": 5})
    assert config.device_id == 2 and config.watchdog_s == 0.5


class _Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _enabled_drive(clock: _Clock):
    from simulators.modbus.devices import LoadingDriveModel

    drive = LoadingDriveModel(SineTestPlant(amplitude_Nm=0.0), 12.0, watchdog_s=0.5, now=clock)
    control = LOADING_DRIVE_MAP["control"].address
    assert drive.write_holding(control, [1]) is None and drive.enabled
    return drive, control


def test_the_simulators_own_stall_is_not_the_masters_silence():
    """The drive's watchdog counts the master's silence: a real drive has its own CPU. When
    the simulator process is starved for 1 s (its periodic check does not run) while the
    master keeps writing, the writes wait in the socket; processed late, they must not trip
    it (seen in a loaded CI run: WATCHDOG_TIMEOUT at a run's start). A master that really
    goes silent while the simulator runs still trips it within the watchdog time."""
    clock = _Clock()
    drive, control = _enabled_drive(clock)
    for _ in range(2):
        clock.t += 0.005
        drive.note_poll(0.005)
    clock.t += 1.0  # the simulator starved: no poll, the master's keepalive queued
    assert drive.write_holding(control, [1]) is None  # processed late: no trip
    assert drive.enabled and not drive.watchdog_tripped
    clock.t += 0.003
    drive.note_poll(0.005)  # the check resumes; the stall before the write is not silence
    assert drive.enabled and drive.master_silence_s() < 0.01
    while clock.t < 1.6:  # now the master is silent and the simulator runs
        clock.t += 0.005
        drive.note_poll(0.005)
    assert drive.watchdog_tripped and not drive.enabled
    assert drive.fault == DriveFaultCode.WATCHDOG_TIMEOUT
    assert 0.5 < drive.max_write_gap_s < 0.52
