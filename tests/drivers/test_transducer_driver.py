"""The serial transducer driver against its simulator, over a real pty and a real TCP socket."""

from __future__ import annotations

import math
import time
import tomllib
from collections.abc import Iterator

import pytest
import serial
from pydantic import ValidationError

from drivers.errors import DeviceDisconnected, DeviceFault, DeviceOutOfRange
from drivers.transducer.serial import (
    SerialTorqueTransducer,
    TransducerConfig,
    TransducerIdentity,
)
from simulators.clock import ManualClock
from simulators.transducer import SineTorqueSource, TransducerSimulator

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

AMPLITUDE_NM = 5.0
FREQUENCY_HZ = 0.5


@pytest.fixture(params=["pty", "tcp"])
def transport(request: pytest.FixtureRequest) -> str:
    return request.param


@pytest.fixture
def clock() -> ManualClock:
    return ManualClock(0.25)


@pytest.fixture
def plant(clock: ManualClock) -> SineTorqueSource:
    return SineTorqueSource(AMPLITUDE_NM, FREQUENCY_HZ, temperature_C=23.5, clock=clock)


@pytest.fixture
def sim(plant: SineTorqueSource, transport: str) -> Iterator[TransducerSimulator]:
    with TransducerSimulator(plant, transport) as simulator:  # type: ignore[arg-type]
        yield simulator


@pytest.fixture
def tt(sim: TransducerSimulator) -> Iterator[SerialTorqueTransducer]:
    assert sim.address is not None
    with SerialTorqueTransducer(TransducerConfig(url=sim.address, timeout_s=2.0)) as driver:
        yield driver


def test_identity_range_and_temperature(tt: SerialTorqueTransducer) -> None:
    assert tt.identity() == TransducerIdentity("RIGSIM", "TT-20", "SN000001", "FW1.0")
    assert tt.range_Nm() == 20.0
    assert tt.temperature_C() == 23.5
    health = tt.health()
    assert health.ok and health.temperature_C == 23.5 and health.overruns == 0


def test_a_query_reads_the_plant_torque(tt: SerialTorqueTransducer, clock: ManualClock) -> None:
    first = tt.read()
    # t = 0.25 s: 5 N*m * sin(2 pi 0.5 Hz 0.25 s) = 5 sin(pi/4) = 3.5355339 N*m
    assert first.torque_Nm == pytest.approx(5.0 * math.sin(math.pi / 4), abs=5e-6)
    assert first.device_t_s == 0.25
    clock.advance(0.75)  # t = 1.0 s: sin(pi) = 0
    second = tt.read()
    assert second.torque_Nm == pytest.approx(0.0, abs=5e-6)
    assert second.seq == first.seq + 1
    assert second.t_s > first.t_s


def test_tare_zeroes_the_reading(
    tt: SerialTorqueTransducer, plant: SineTorqueSource, clock: ManualClock
) -> None:
    plant.enable_drive(True)
    plant.command_torque(1.25)
    assert tt.tare() == pytest.approx(1.25)
    assert tt.read().torque_Nm == pytest.approx(0.0, abs=1e-9)
    plant.command_torque(3.0)
    assert tt.read().torque_Nm == pytest.approx(1.75, abs=1e-9)
    tt.clear_tare()
    assert tt.read().torque_Nm == pytest.approx(3.0, abs=1e-9)


def test_tare_beyond_ten_percent_of_the_range_is_refused(
    tt: SerialTorqueTransducer, plant: SineTorqueSource
) -> None:
    plant.enable_drive(True)
    plant.command_torque(2.5)  # 12.5 % of 20 N*m
    with pytest.raises(DeviceFault, match=r"ERR 6 tare out of range"):
        tt.tare()


def test_a_reading_beyond_the_range_raises(
    tt: SerialTorqueTransducer, plant: SineTorqueSource
) -> None:
    plant.enable_drive(True)
    plant.command_torque(-20.5)
    with pytest.raises(DeviceOutOfRange) as info:
        tt.read()
    assert "-20.50000 N*m, status OV" in info.value.got
    assert "|torque| <= 20 N*m" in info.value.expected
    assert not tt.health().ok


def test_stream_counts_samples_and_keeps_order(
    tt: SerialTorqueTransducer, sim: TransducerSimulator
) -> None:
    tt.start_stream(500)
    readings = list(tt.readings(300))
    stats = tt.stop_stream()
    seqs = [r.seq for r in readings]
    assert seqs[0] == 0
    assert all(b > a for a, b in zip(seqs, seqs[1:], strict=False))
    assert all(b.t_s >= a.t_s for a, b in zip(readings, readings[1:], strict=False))
    assert stats.received == 300
    # every gap in the counter is a sample the device could not send (its overruns)
    assert stats.lost == seqs[-1] + 1 - 300 == sim.device.overruns
    assert stats.bad_lines == 0
    assert not tt.streaming
    assert tt.read().torque_Nm == pytest.approx(5.0 * math.sin(math.pi / 4), abs=5e-6)


def test_commands_during_a_stream_keep_the_samples(
    tt: SerialTorqueTransducer, sim: TransducerSimulator
) -> None:
    tt.start_stream(200)
    before = tt.next_reading()
    assert tt.temperature_C() == 23.5  # samples that came meanwhile are kept
    with pytest.raises(DeviceFault, match="ERR 4 not allowed while streaming"):
        tt.tare()
    after = [tt.next_reading() for _ in range(20)]
    if sim.device.overruns == 0:  # the simulator's thread kept up (a loaded machine may not)
        assert [r.seq for r in after] == list(range(before.seq + 1, before.seq + 21))
    assert tt.stop_stream().lost == sim.device.overruns


def test_stream_rate_beyond_the_serial_line_is_refused_before_sending(
    tt: SerialTorqueTransducer,
) -> None:
    with pytest.raises(DeviceOutOfRange, match=r"\[1, 1047\] Hz at 460800 Bd"):
        tt.start_stream(1500)
    assert not tt.streaming
    assert tt.read().seq == 0  # the device never saw the command


def test_open_refuses_a_transducer_of_another_range(sim: TransducerSimulator) -> None:
    assert sim.address is not None
    driver = SerialTorqueTransducer(TransducerConfig(url=sim.address, full_scale_Nm=50.0))
    with pytest.raises(DeviceOutOfRange, match="a range of 50 N.m"):
        driver.open()
    driver.close()


def test_reopen_stops_a_stream_left_running(sim: TransducerSimulator) -> None:
    assert sim.address is not None
    config = TransducerConfig(url=sim.address, timeout_s=2.0)
    other_program = serial.serial_for_url(sim.address, timeout=2.0)
    other_program.write(b"STREAM 500\r\n")  # it starts a stream and exits without STOP
    assert other_program.readline() == b"OK*04\r\n"
    assert other_program.readline().startswith(b"ST 000000 ")
    other_program.close()
    assert sim.device.streaming
    with SerialTorqueTransducer(config) as second:
        assert not sim.device.streaming
        assert second.read().seq >= 0


def test_a_closed_driver_says_so() -> None:
    driver = SerialTorqueTransducer(TransducerConfig(url="socket://127.0.0.1:9"))
    with pytest.raises(DeviceDisconnected, match="call open"):
        driver.read()
    with pytest.raises(DeviceDisconnected, match="a serial port that opens"):
        driver.open()


def test_carriage_return_terminator(plant: SineTorqueSource) -> None:
    with TransducerSimulator(plant, "tcp", terminator="\r") as sim:
        assert sim.address is not None
        config = TransducerConfig(url=sim.address, terminator="CR")
        with SerialTorqueTransducer(config) as driver:
            assert driver.range_Nm() == 20.0
            driver.start_stream(100)
            assert len(list(driver.readings(10))) == 10


def test_config_from_a_toml_table() -> None:
    table = tomllib.loads(
        """
        [transducer]
        url = "/dev/ttyUSB0"
        baudrate = 115200
        terminator = "CRLF"
        stream_rate_Hz = 250
        full_scale_Nm = 20.0
        """
    )["transducer"]
    config = TransducerConfig.model_validate(table)
    assert config.terminator == "\r\n" and config.max_rate_Hz == 261.0
    with pytest.raises(ValidationError, match="exceeds 261 Hz"):
        TransducerConfig.model_validate({**table, "stream_rate_Hz": 500})
    with pytest.raises(ValidationError, match="timeout_s"):
        TransducerConfig.model_validate({**table, "timeout_s": 0})
    with pytest.raises(ValidationError, match="speed"):
        TransducerConfig.model_validate({**table, "speed": 1})


def test_samples_sent_before_stop_stay_readable(
    tt: SerialTorqueTransducer, sim: TransducerSimulator
) -> None:
    tt.start_stream(1000)
    first = tt.next_reading()
    time.sleep(0.2)  # the device sends on while the host is busy elsewhere
    tt.stop_stream()
    rest = []
    with pytest.raises(RuntimeError, match="no stream running"):
        while True:
            rest.append(tt.next_reading())
    assert rest and [r.seq for r in rest][0] > first.seq
    assert tt.stats.received == 1 + len(rest)
    assert tt.stats.lost == sim.device.overruns


def test_simulator_restarts(plant: SineTorqueSource, transport: str) -> None:
    sim = TransducerSimulator(plant, transport)  # type: ignore[arg-type]
    for _ in range(2):
        address = sim.start()
        with SerialTorqueTransducer(TransducerConfig(url=address, timeout_s=2.0)) as driver:
            assert driver.range_Nm() == 20.0
        sim.stop()
