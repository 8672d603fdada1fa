"""The Modbus torque sensor driver against the simulated sensor, over TCP, RTU on a TCP
socket and RTU on a real pty pair (socat), plus an outside client (mbpoll).

The plant is :class:`simulators.modbus.plant_backdoor.SineTestPlant`, whose torque is a closed
form, so the values that come over the wire are checked against numbers.
"""

from __future__ import annotations

import asyncio
import math
import re
import shutil
import subprocess
import time
from pathlib import Path

import pytest

from drivers.errors import (
    DeviceDisconnected,
    DeviceFault,
    DeviceOutOfRange,
    DeviceProtocolError,
    DeviceTimeout,
)
from drivers.loading_drive import LoadingDrive, LoadingDriveConfig
from drivers.modbus.link import ModbusLink
from drivers.modbus.map import SensorStatus
from drivers.modbus.torque_sensor import ModbusTorqueSensor, ModbusTorqueSensorConfig
from simulators.clock import ManualClock
from simulators.modbus.plant_backdoor import SineTestPlant
from simulators.modbus.server import ModbusRigServer

TIMEOUT_S = 1.0
BOUND_S = 10.0  # generous bound on "an error comes in bounded time" (loaded 2-core CI)


@pytest.fixture
def pty_pair(tmp_path: Path):
    """Two linked pty paths from socat (a null-modem cable in software)."""
    if shutil.which("socat") is None:
        pytest.fail("socat is required (apt-get install -y socat); CI installs it")
    a, b = tmp_path / "ptyA", tmp_path / "ptyB"
    proc = subprocess.Popen(["socat", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + BOUND_S
    while not (a.exists() and b.exists()):
        if time.monotonic() > deadline or proc.poll() is not None:
            proc.kill()
            pytest.fail(f"socat did not create the pty pair: {proc.stderr.read()!r}")
        time.sleep(0.01)
    yield str(a), str(b)
    proc.terminate()
    proc.wait(timeout=BOUND_S)


def serve(plant, transport: str, pty_pair=None, **kwargs) -> tuple[ModbusRigServer, dict]:
    """Start a server; return it and the driver config fields to reach it."""
    if transport == "rtu-serial":
        server = ModbusRigServer(plant, 20.0, transport="rtu-serial", serial_port=pty_pair[0],
                                 **kwargs)
        server.start()
        return server, {"transport": "rtu", "serial_url": pty_pair[1]}
    server = ModbusRigServer(plant, 20.0, transport=transport, **kwargs)
    address = server.start()
    if transport == "tcp":
        return server, {"transport": "tcp", "host": "127.0.0.1",
                        "port": int(address.rsplit(":", 1)[1])}
    return server, {"transport": "rtu", "serial_url": address}


@pytest.fixture(params=["tcp", "rtu-tcp", "rtu-serial"])
def transport(request):
    return request.param


@pytest.fixture
def tcp_rig():
    plant = SineTestPlant(amplitude_Nm=0.0, offset_Nm=3.25)
    server, where = serve(plant, "tcp")
    sensor = ModbusTorqueSensor(ModbusTorqueSensorConfig(**where, timeout_s=TIMEOUT_S,
                                                         stale_after_s=0.3))
    yield server, sensor, plant
    sensor.close()
    server.stop()


def test_reads_the_closed_form_torque(transport, request):
    pair = request.getfixturevalue("pty_pair") if transport == "rtu-serial" else None
    clock = ManualClock(0.125)
    plant = SineTestPlant(amplitude_Nm=2.0, frequency_Hz=1.0, offset_Nm=0.5, clock=clock)
    server, where = serve(plant, transport, pair)
    try:
        with ModbusTorqueSensor(ModbusTorqueSensorConfig(**where, timeout_s=TIMEOUT_S)) as s:
            first = s.read()
            # 0.5 + 2 sin(2 pi 0.125) = 0.5 + sqrt(2); float32 on the wire
            assert first.torque_Nm == pytest.approx(0.5 + math.sqrt(2.0), rel=1e-6)
            assert first.sample_counter == 125  # 1 kHz conversion counter at t = 0.125 s
            assert first.status == SensorStatus.VALID
            clock.advance(0.25)
            second = s.read()
            assert second.torque_Nm == pytest.approx(0.5 + 2 * math.sin(0.75 * math.pi),
                                                     rel=1e-6)
            assert second.sample_counter == 375
            assert second.t_s > first.t_s and second.latency_s > 0
            assert s.full_scale_Nm == 30.0  # 1.5 x the drive limit of 20 N*m
    finally:
        server.stop()


def test_tare_is_done_in_the_sensor(tcp_rig):
    server, sensor, _ = tcp_rig
    assert sensor.read().torque_Nm == 3.25
    assert sensor.tare() == 3.25
    reading = sensor.read()
    assert reading.torque_Nm == 0.0 and SensorStatus.TARED in reading.status
    assert server.sensor.tare_offset_Nm == 3.25
    sensor.clear_tare()
    assert sensor.read().torque_Nm == 3.25 and sensor.tare_offset_Nm() == 0.0


def test_mbpoll_reads_the_simulated_sensor(tcp_rig):
    """An outside Modbus master (libmodbus' mbpoll) agrees with the register map."""
    server, sensor, _ = tcp_rig
    if shutil.which("mbpoll") is None:
        pytest.fail("mbpoll is required (apt-get install -y mbpoll); CI installs it")
    port = server.address.rsplit(":", 1)[1]
    out = subprocess.run(
        ["mbpoll", "-m", "tcp", "-p", port, "-a", "1", "-r", "1", "-c", "1", "-t", "3:float",
         "-B", "-1", "-o", "5", "127.0.0.1"],
        capture_output=True, text=True, timeout=60, check=True).stdout
    values = re.findall(r"^\[1\]:\s+(\S+)$", out, flags=re.MULTILINE)
    assert [float(v) for v in values] == [3.25], out
    status = subprocess.run(
        ["mbpoll", "-m", "tcp", "-p", port, "-a", "1", "-r", "3", "-c", "1", "-t", "3",
         "-1", "-o", "5", "127.0.0.1"],
        capture_output=True, text=True, timeout=60, check=True).stdout
    assert re.search(r"^\[3\]:\s+1$", status, flags=re.MULTILINE), status  # VALID


def test_overload_is_out_of_range(tcp_rig):
    _, sensor, plant = tcp_rig
    plant.offset_Nm = 31.0  # beyond the 30 N*m full scale
    with pytest.raises(DeviceOutOfRange, match="full scale 30 N.m") as info:
        sensor.read()
    assert "torque sensor (Modbus unit 1 on tcp 127.0.0.1:" in info.value.device


def timed(fn):
    t0 = time.monotonic()
    try:
        fn()
    except Exception as exc:  # returned for the caller's pytest.raises-style checks
        return exc, time.monotonic() - t0
    return None, time.monotonic() - t0


def test_silence_gives_a_timeout_naming_device_and_address(tcp_rig):
    server, sensor, _ = tcp_rig
    server.backdoor.silence(1)
    exc, elapsed = timed(sensor.read)
    assert isinstance(exc, DeviceTimeout), exc
    assert elapsed < BOUND_S
    assert f"tcp {server.address}" in str(exc) and "unit 1" in str(exc)
    assert "no valid reply" in str(exc)
    server.backdoor.clear()
    assert sensor.read().torque_Nm == 3.25  # recovers after the fault


def test_delay_beyond_timeout_then_recovery_without_stale_replies(tcp_rig):
    server, sensor, plant = tcp_rig
    server.backdoor.delay(TIMEOUT_S * 1.5)
    exc, elapsed = timed(sensor.read)
    assert isinstance(exc, DeviceTimeout) and elapsed < BOUND_S
    server.backdoor.clear()
    plant.offset_Nm = -4.5
    time.sleep(TIMEOUT_S)  # the late reply to the timed-out request is now on its way
    assert [sensor.read().torque_Nm for _ in range(3)] == [-4.5] * 3


def test_short_delay_is_tolerated(tcp_rig):
    server, sensor, _ = tcp_rig
    server.backdoor.delay(0.1)
    reading = sensor.read()
    assert reading.torque_Nm == 3.25 and reading.latency_s >= 0.1


def test_exception_code_gives_device_fault(tcp_rig):
    server, sensor, _ = tcp_rig
    server.backdoor.exception(1, 4)
    with pytest.raises(DeviceFault, match=r"Modbus exception code 4 \(DEVICE_FAILURE\)"):
        sensor.read()
    server.backdoor.exception(1, None)
    assert sensor.read().torque_Nm == 3.25


def test_disconnect_gives_device_disconnected_then_reconnects(tcp_rig):
    server, sensor, _ = tcp_rig
    assert sensor.read().torque_Nm == 3.25
    server.backdoor.disconnect()
    exc, elapsed = timed(sensor.read)
    assert isinstance(exc, DeviceDisconnected), exc
    assert elapsed < BOUND_S and "connection lost" in str(exc)
    assert sensor.read().torque_Nm == 3.25  # the next request reconnects


def test_stopped_server_gives_connection_refused(tcp_rig):
    server, sensor, _ = tcp_rig
    server.stop()
    exc, elapsed = timed(sensor.read)
    assert isinstance(exc, DeviceDisconnected), exc
    assert elapsed < BOUND_S
    exc, _ = timed(sensor.read)
    assert isinstance(exc, DeviceDisconnected) and "refused" in str(exc)


def test_stuck_value_is_detected_from_the_sample_counter(tcp_rig):
    server, sensor, _ = tcp_rig
    sensor.read()
    server.backdoor.stick_sensor()
    t0 = time.monotonic()
    with pytest.raises(DeviceProtocolError, match="counter stuck at"):
        while time.monotonic() - t0 < BOUND_S:
            sensor.read()
            time.sleep(0.01)
    server.backdoor.clear()
    time.sleep(0.005)
    assert sensor.read().torque_Nm == 3.25


@pytest.mark.parametrize("transport", ["tcp", "rtu-tcp"])
def test_garbled_reply_gives_timeout_in_bounded_time(transport):
    server, where = serve(SineTestPlant(amplitude_Nm=0.0, offset_Nm=1.0), transport)
    sensor = ModbusTorqueSensor(ModbusTorqueSensorConfig(**where, timeout_s=TIMEOUT_S))
    try:
        assert sensor.read().torque_Nm == 1.0
        server.backdoor.garble(1)
        exc, elapsed = timed(sensor.read)
        assert isinstance(exc, DeviceTimeout), exc
        assert elapsed < BOUND_S and server.backdoor.replies_garbled >= 1
        server.backdoor.clear()
        assert sensor.read().torque_Nm == 1.0
    finally:
        sensor.close()
        server.stop()


def test_health_reports_without_raising(tcp_rig):
    server, sensor, _ = tcp_rig
    good = sensor.health()
    assert good.ok and "3.25 N*m" in good.detail and good.errors == 0
    server.backdoor.exception(None, 6)
    bad = sensor.health()
    assert not bad.ok and "exception code 6" in bad.detail and bad.errors == 1


def test_sensor_and_drive_share_one_rtu_line(pty_pair):
    """Two units on one serial line, one master: the RS-485 arrangement of the rig."""
    plant = SineTestPlant(amplitude_Nm=0.0, offset_Nm=0.0)
    server, where = serve(plant, "rtu-serial", pty_pair)
    link = ModbusLink(ModbusTorqueSensorConfig(**where, timeout_s=TIMEOUT_S))
    sensor = ModbusTorqueSensor(ModbusTorqueSensorConfig(**where), link=link)
    drive = LoadingDrive(LoadingDriveConfig(**where, torque_limit_Nm=10.0), link=link)
    try:
        drive.set_torque(2.5)
        drive.enable()
        assert sensor.read().torque_Nm == 2.5  # the ideal test plant transmits the command
        assert drive.status().actual_torque_Nm == 2.5
        drive.safe_state()
        assert sensor.read().torque_Nm == 0.0
    finally:
        drive.close()
        sensor.close()
        link.close()
        server.stop()


def test_serial_line_faults(pty_pair):
    """RTU on a pty: a "disconnect" is silence on a serial line; a vanished port is not."""
    server, where = serve(SineTestPlant(amplitude_Nm=0.0, offset_Nm=1.0), "rtu-serial",
                          pty_pair)
    sensor = ModbusTorqueSensor(ModbusTorqueSensorConfig(**where, timeout_s=TIMEOUT_S))
    try:
        assert sensor.read().torque_Nm == 1.0
        server.backdoor.garble(1)
        exc, elapsed = timed(sensor.read)
        assert isinstance(exc, DeviceTimeout) and elapsed < BOUND_S  # bad CRC: no valid reply
        server.backdoor.clear()
        server.backdoor.disconnect()
        exc, elapsed = timed(sensor.read)
        assert isinstance(exc, DeviceTimeout) and elapsed < BOUND_S
        server.backdoor.clear()
        assert sensor.read().torque_Nm == 1.0
    finally:
        sensor.close()
        server.stop()


def test_vanished_serial_port_is_disconnected(tmp_path):
    a, b = tmp_path / "ptyA", tmp_path / "ptyB"
    proc = subprocess.Popen(["socat", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + BOUND_S
    while not (a.exists() and b.exists()) and time.monotonic() < deadline:
        time.sleep(0.01)
    server, where = serve(SineTestPlant(amplitude_Nm=0.0, offset_Nm=1.0), "rtu-serial",
                          (str(a), str(b)))
    sensor = ModbusTorqueSensor(ModbusTorqueSensorConfig(**where, timeout_s=TIMEOUT_S))
    try:
        assert sensor.read().torque_Nm == 1.0
        proc.kill()  # the USB adapter is unplugged: both pty ends disappear
        proc.wait(timeout=BOUND_S)
        errors = [timed(sensor.read)[0] for _ in range(2)]
        assert all(isinstance(e, DeviceDisconnected) for e in errors), errors
        assert str(b) in str(errors[-1])
    finally:
        sensor.close()
        server.stop()


def test_server_runs_inside_an_asyncio_loop():
    """start_async/stop_async for a caller that owns the event loop (e.g. ``rig sim``)."""

    async def scenario() -> float:
        server = ModbusRigServer(SineTestPlant(amplitude_Nm=0.0, offset_Nm=2.0), 20.0)
        address = await server.start_async()
        host, port = address.rsplit(":", 1)
        sensor = ModbusTorqueSensor(ModbusTorqueSensorConfig(host=host, port=int(port),
                                                             timeout_s=TIMEOUT_S))
        try:
            reading = await asyncio.to_thread(sensor.read)  # sync driver off the loop
        finally:
            sensor.close()
            await server.stop_async()
            await server.stop_async()  # idempotent
        return reading.torque_Nm

    assert asyncio.run(scenario()) == 2.0
