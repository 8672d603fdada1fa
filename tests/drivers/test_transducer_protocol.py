"""The transducer line protocol: formatting, parsing, checksums, rate budget, fuzzing."""

from __future__ import annotations

import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.errors import DeviceProtocolError
from drivers.transducer.protocol import (
    ErrorReply,
    Measurement,
    Reply,
    checksum,
    format_measurement,
    frame_line,
    max_stream_rate_Hz,
    parse_line,
    parse_quantity,
    stream_line_bytes,
)
from simulators.clock import ManualClock
from simulators.transducer import SineTorqueSource, TransducerBackdoor, TransducerDevice


def test_checksum_is_the_xor_of_the_body_bytes() -> None:
    # 'O' = 0x4F, 'K' = 0x4B: 0x4F ^ 0x4B = 0x04
    assert checksum(b"OK") == 0x04
    assert frame_line("OK") == b"OK*04\r\n"
    assert frame_line("OK", "\r") == b"OK*04\r"


def test_measurement_line_round_trips() -> None:
    body = format_measurement("ST", 123, 12.345678, 12.3456, "Nm", "OK")
    assert body == "ST 000123 12.345678 +12.34560 Nm OK"
    line = parse_line(frame_line(body))
    assert line == Measurement("ST", 123, 12.345678, 12.3456, "Nm", "OK")


def test_counters_wrap_in_the_line() -> None:
    body = format_measurement("TQ", 1_000_003, 100_002.5, -0.5, "Nm", "OK")
    assert body == "TQ 000003 2.500000 -0.50000 Nm OK"


def test_replies_and_errors_parse() -> None:
    assert parse_line(frame_line("OK")) == Reply("OK", "")
    assert parse_line(frame_line("RANGE 20.000 Nm")) == Reply("RANGE", "20.000 Nm")
    assert parse_line(frame_line("ERR 3 unknown command")) == ErrorReply(3, "unknown command")
    assert parse_quantity(Reply("TEMP", "+23.45 C"), "C") == 23.45


@pytest.mark.parametrize(
    "raw",
    [
        b"OK\r\n",  # no checksum
        b"OK*05\r\n",  # wrong checksum
        b"OK*04*04\r\n",
        b"ok*64\r\n",  # lower-case keyword (checksum right)
        b"ST 000123 12.345678 +12.34560 Nm OK*14\r\n".replace(b"OK*14", b"XX*14"),
        b"\x00\xffOK*04\r\n",
        b"x" * 200,
    ],
)
def test_bad_lines_raise_protocol_errors_quoting_the_bytes(raw: bytes) -> None:
    with pytest.raises(DeviceProtocolError) as info:
        parse_line(raw, "tt at /dev/pts/9")
    assert info.value.device == "tt at /dev/pts/9"
    assert info.value.got == repr(raw)
    assert str(info.value).startswith("tt at /dev/pts/9: expected ")


def test_lower_case_checksum_digits_are_refused() -> None:
    # XOR 0x20 turns 'A' into 'a': one garbled byte must never pass as a good line
    assert frame_line("TEMP +22.00 C") == b"TEMP +22.00 C*4A\r\n"
    assert parse_line(b"TEMP +22.00 C*4A\r\n") == Reply("TEMP", "+22.00 C")
    with pytest.raises(DeviceProtocolError):
        parse_line(b"TEMP +22.00 C*4a\r\n")


def test_stream_rate_budget_follows_the_baud_rate() -> None:
    # longest line of a 20 N*m transducer: "ST 999999 99999.999999 -200.00000 Nm OV*HH\r\n"
    assert stream_line_bytes(20.0) == 44
    assert max_stream_rate_Hz(460800, 20.0) == 1047.0  # 46080 B/s / 44 B
    assert max_stream_rate_Hz(115200, 20.0) == 261.0
    assert max_stream_rate_Hz(2_000_000, 20.0) == 2000.0  # the device's own cap


@given(st.binary(max_size=300))
@settings(max_examples=400, deadline=None)
def test_arbitrary_bytes_give_a_line_or_our_error(raw: bytes) -> None:
    try:
        line = parse_line(raw)
    except DeviceProtocolError as exc:
        assert exc.got == repr(raw)
    else:
        assert isinstance(line, Measurement | Reply | ErrorReply)


@given(
    st.sampled_from(["TQ", "ST"]),
    st.integers(0, 999_999),
    st.floats(0.0, 99_999.0),
    st.floats(-1000.0, 1000.0),
    st.sampled_from(["OK", "OV"]),
)
def test_every_measurement_round_trips(
    tag: str, seq: int, t_s: float, torque_Nm: float, status: str
) -> None:
    line = parse_line(frame_line(format_measurement(tag, seq, t_s, torque_Nm, "Nm", status)))
    assert isinstance(line, Measurement)
    assert (line.tag, line.seq, line.status) == (tag, seq, status)
    assert line.torque_Nm == pytest.approx(torque_Nm, abs=5e-6)
    assert line.device_t_s == pytest.approx(t_s % 100_000.0, abs=5e-7)


@given(st.text(max_size=120))
@settings(max_examples=300, deadline=None)
def test_the_device_answers_any_command_text_with_good_lines(text: str) -> None:
    device = TransducerDevice(SineTorqueSource(clock=ManualClock(0.3)), TransducerBackdoor())
    for body in device.handle(text, now_s=0.0):
        assert isinstance(parse_line(frame_line(body)), Measurement | Reply | ErrorReply)


def test_the_device_refuses_what_it_cannot_do() -> None:
    device = TransducerDevice(SineTorqueSource(clock=ManualClock(0.0)), TransducerBackdoor())
    assert device.handle("FOO?", 0.0) == ["ERR 3 unknown command"]
    assert device.handle("TQ? 3", 0.0) == ["ERR 2 bad argument"]
    assert device.handle("STREAM 5000", 0.0) == ["ERR 5 rate out of range"]
    assert device.handle("STREAM abc", 0.0) == ["ERR 2 bad argument"]
    assert device.handle("STREAM nan", 0.0) == ["ERR 5 rate out of range"]
    assert device.handle("X" * 80, 0.0) == ["ERR 1 line too long"]
    assert device.handle("   ", 0.0) == []
    assert device.handle("stream 200", 0.0) == ["OK"]  # commands are case-insensitive
    assert device.handle("TARE", 0.0) == ["ERR 4 not allowed while streaming"]
    assert device.handle("STREAM 100", 0.0) == ["ERR 4 not allowed while streaming"]
    assert device.handle("RATE?", 0.0) == ["RATE 200"]
    assert device.handle("STOP", 0.0) == ["OK"]


def test_every_device_line_in_the_documentation_parses(repo_root) -> None:
    text = (repo_root / "docs" / "transducer-protocol.md").read_text(encoding="utf-8")
    lines = re.findall(r"^([A-Z][ -~]*?\*[0-9A-F]{2})\b", text, flags=re.MULTILINE)
    assert len(lines) >= 20
    for line in lines:
        parse_line(line.encode("ascii") + b"\r\n")
