"""Backdoor faults of the simulated transducer: each gives a clear driver error in bounded time."""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivers.errors import (
    DeviceDisconnected,
    DeviceError,
    DeviceFault,
    DeviceProtocolError,
    DeviceTimeout,
)
from drivers.transducer.serial import SerialTorqueTransducer, TorqueReading, TransducerConfig
from simulators.transducer import SineTorqueSource, TransducerSimulator

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

TIMEOUT_S = 0.4
BOUND_S = TIMEOUT_S + 5.0  # generous: the machine may be loaded; a hang is what we exclude


@pytest.fixture(params=["pty", "tcp"])
def sim(request: pytest.FixtureRequest) -> Iterator[TransducerSimulator]:
    with TransducerSimulator(SineTorqueSource(), request.param, seed=7) as simulator:
        yield simulator


@pytest.fixture
def tt(sim: TransducerSimulator) -> Iterator[SerialTorqueTransducer]:
    assert sim.address is not None
    with SerialTorqueTransducer(TransducerConfig(url=sim.address, timeout_s=TIMEOUT_S)) as driver:
        yield driver


def _raises_within(error: type[DeviceError], call, bound_s: float = BOUND_S) -> DeviceError:
    start = time.monotonic()
    with pytest.raises(error) as info:
        call()
    assert time.monotonic() - start < bound_s
    assert info.value.device == f"torque transducer at {info.value.device.split(' at ')[1]}"
    return info.value


def test_silence_times_out_naming_what_was_awaited(
    tt: SerialTorqueTransducer, sim: TransducerSimulator
) -> None:
    sim.backdoor.silence()
    err = _raises_within(DeviceTimeout, tt.read)
    assert err.expected == "a reply to 'TQ?' within 0.4 s" and err.got == "nothing"
    health = tt.health()
    assert not health.ok and "within 0.4 s" in health.detail
    sim.backdoor.silence(False)
    assert abs(tt.read().torque_Nm) <= 5.0  # the 5 N*m sine source answers again


def test_silence_during_a_stream_times_out(
    tt: SerialTorqueTransducer, sim: TransducerSimulator
) -> None:
    tt.start_stream(500)
    tt.next_reading()
    sim.backdoor.silence()
    start = time.monotonic()
    with pytest.raises(DeviceTimeout, match="a stream sample at 500 Hz within 0.4 s"):
        for _ in range(10_000):  # what was sent before the silence, then the timeout
            tt.next_reading()
    assert time.monotonic() - start < BOUND_S
    sim.backdoor.silence(False)
    reading = tt.next_reading()
    assert tt.stats.lost > 0  # samples taken while the device was mute are counted
    assert isinstance(reading, TorqueReading)


def test_a_delay_longer_than_the_timeout_times_out(
    tt: SerialTorqueTransducer, sim: TransducerSimulator
) -> None:
    sim.backdoor.delay(0.1)
    assert tt.range_Nm() == 20.0  # a short delay is fine
    sim.backdoor.delay(1.0)
    _raises_within(DeviceTimeout, tt.read)
    sim.backdoor.delay(0.0)
    time.sleep(1.2)  # let the late reply arrive; the next command discards it
    assert tt.range_Nm() == 20.0


def test_garbled_reply_quotes_the_bytes(
    tt: SerialTorqueTransducer, sim: TransducerSimulator
) -> None:
    sim.backdoor.garble(1.0)
    err = _raises_within(DeviceProtocolError, tt.read)
    assert err.got.startswith("b'") and "\\r\\n'" in err.got
    sim.backdoor.garble(0.0)
    assert tt.range_Nm() == 20.0


def test_garbled_stream_lines_are_errors_and_lost_samples(
    tt: SerialTorqueTransducer, sim: TransducerSimulator
) -> None:
    tt.start_stream(500)
    sim.backdoor.garble(0.2)
    good, bad = 0, 0
    while good < 300:
        try:
            tt.next_reading()
            good += 1
        except DeviceProtocolError:
            bad += 1
    sim.backdoor.garble(0.0)
    good = 0
    while good < 300:  # lines garbled before the switch may still be on their way
        try:
            tt.next_reading()
            good += 1
        except DeviceProtocolError:
            bad += 1
            good = 0
    stats = tt.stop_stream()
    assert bad > 10 and stats.bad_lines == bad
    assert stats.lost == bad + sim.device.overruns


def test_dropped_lines_are_counted_as_lost(
    tt: SerialTorqueTransducer, sim: TransducerSimulator
) -> None:
    tt.start_stream(500)
    list(tt.readings(10))
    sim.backdoor.drop_next(7)
    list(tt.readings(50))
    stats = tt.stop_stream()
    assert stats.lost == 7 + sim.device.overruns
    assert stats.received == 60


def test_error_replies_are_device_faults(
    tt: SerialTorqueTransducer, sim: TransducerSimulator
) -> None:
    sim.backdoor.error_replies(7)
    err = _raises_within(DeviceFault, tt.read)
    assert err.expected == "a reply to 'TQ?'" and err.got == "'ERR 7 internal fault'"
    assert "ERR 7 internal fault" in tt.health().detail
    sim.backdoor.error_replies(None)
    assert tt.health().ok


def test_a_stuck_measurement_is_a_fault(
    tt: SerialTorqueTransducer, sim: TransducerSimulator
) -> None:
    first = tt.read()
    sim.backdoor.stuck()
    err = _raises_within(DeviceFault, tt.read)
    assert f"seq {first.seq:06d} again" in err.got and "stuck" in err.got
    sim.backdoor.stuck(False)
    assert tt.read().seq > first.seq  # the device counted on while its output was stale


def test_a_stuck_stream_is_a_fault(tt: SerialTorqueTransducer, sim: TransducerSimulator) -> None:
    tt.start_stream(500)
    list(tt.readings(5))
    sim.backdoor.stuck()
    start = time.monotonic()
    with pytest.raises(DeviceFault, match="stale data: the measurement is stuck"):
        for _ in range(10_000):
            tt.next_reading()
    assert time.monotonic() - start < BOUND_S


def test_disconnect_during_a_query(tt: SerialTorqueTransducer, sim: TransducerSimulator) -> None:
    tt.read()
    sim.disconnect()
    start = time.monotonic()
    with pytest.raises(DeviceDisconnected) as info:
        for _ in range(100):  # the first command may still go out before the link drops
            tt.read()
            time.sleep(0.05)
    assert time.monotonic() - start < BOUND_S
    assert info.value.got


def test_disconnect_during_a_stream(tt: SerialTorqueTransducer, sim: TransducerSimulator) -> None:
    tt.start_stream(500)
    list(tt.readings(5))
    sim.disconnect()
    start = time.monotonic()
    with pytest.raises(DeviceDisconnected):
        for _ in range(100_000):
            tt.next_reading()
    assert time.monotonic() - start < BOUND_S
    tt.close()  # closing a dead link is fine


def test_tcp_device_can_be_reconnected_after_a_disconnect() -> None:
    with TransducerSimulator(SineTorqueSource(), "tcp") as sim:
        assert sim.address is not None
        config = TransducerConfig(url=sim.address, timeout_s=2.0)
        with SerialTorqueTransducer(config) as first:
            first.read()
            sim.disconnect()
            with pytest.raises(DeviceDisconnected):
                for _ in range(100):
                    first.read()
                    time.sleep(0.05)
        with SerialTorqueTransducer(config) as second:
            assert second.range_Nm() == 20.0


@pytest.fixture(scope="module")
def noisy_link() -> Iterator[tuple[TransducerSimulator, SerialTorqueTransducer]]:
    with TransducerSimulator(SineTorqueSource(), "pty") as sim:
        assert sim.address is not None
        config = TransducerConfig(url=sim.address, timeout_s=1.0)
        with SerialTorqueTransducer(config) as driver:
            yield sim, driver


@given(noise=st.binary(min_size=1, max_size=300))
@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
def test_line_noise_gives_a_reading_or_our_error(
    noisy_link: tuple[TransducerSimulator, SerialTorqueTransducer], noise: bytes
) -> None:
    sim, driver = noisy_link
    sim.backdoor.inject(noise)  # raw bytes on the wire just before the reply to TQ?
    start = time.monotonic()
    try:
        reading = driver.read()
        assert isinstance(reading, TorqueReading)
    except (DeviceProtocolError, DeviceTimeout, DeviceFault):
        pass
    assert time.monotonic() - start < 1.0 + 5.0
    assert driver.range_Nm() == 20.0  # and the link is usable again at once


def test_a_late_reply_coming_after_the_next_command_is_skipped(
    sim: TransducerSimulator,
) -> None:
    """A reply that comes after its command timed out, and after the next command was sent
    (a busy PC, a slow line), is that earlier command's: skipped, not taken for the next
    one's (under load: "expected a 'RANGE ...' reply to 'RANGE?', got TQ ...")."""
    assert sim.address is not None
    with SerialTorqueTransducer(TransducerConfig(url=sim.address, timeout_s=1.0)) as tt:
        sim.backdoor.delay(1.5)
        _raises_within(DeviceTimeout, tt.read, bound_s=1.4)  # its reply leaves at 1.5 s
        sim.backdoor.delay(0.0)
        assert tt.range_Nm() == 20.0  # sent at 1.0 s: its reply follows the late one
        assert tt.late_replies == 1
        reading = tt.read()  # and the line is in step afterwards
        assert isinstance(reading, TorqueReading)
