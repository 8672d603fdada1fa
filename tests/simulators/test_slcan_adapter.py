"""The simulated SLCAN adapter: Lawicel parser, session state machine, TCP face; fuzzed."""

from __future__ import annotations

import socket
import time
import uuid

import can
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from simulators.slcan_adapter import (
    ERROR,
    OK,
    SlcanAdapter,
    SlcanSession,
    SlcanSyntaxError,
    format_frame,
    parse_line,
)

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)


def test_parse_frames() -> None:
    cmd = parse_line(b"t1854DEADBEEF")
    assert cmd.kind == "t" and cmd.frame is not None
    assert cmd.frame.arbitration_id == 0x185 and bytes(cmd.frame.data) == bytes.fromhex("DEADBEEF")
    ext = parse_line(b"T1ABCDEF82" + b"0011")
    assert ext.frame.is_extended_id and ext.frame.arbitration_id == 0x1ABCDEF8
    assert bytes(ext.frame.data) == b"\x00\x11"
    rtr = parse_line(b"r7053")
    assert rtr.frame.is_remote_frame and rtr.frame.dlc == 3
    assert parse_line(b"t0800").frame.dlc == 0


@pytest.mark.parametrize(
    ("line", "reason"),
    [
        (b"t18", "too short"),
        (b"t1859" + b"00" * 9, "DLC '9'"),
        (b"t18540102", "needs 8 hex digits, got 4"),
        (b"tXYZ0", "identifier"),
        (b"t1852ZZZZ", "data"),
        (b"T2000000000", "out of range"),
        (b"S9", "S0..S8"),
        (b"Ox", "no argument"),
        (b"q", "unknown command"),
        (b"r1852AA", "no data"),
        (b"t" + b"0" * 40, "longer than"),
    ],
)
def test_parse_errors_name_the_line(line: bytes, reason: str) -> None:
    with pytest.raises(SlcanSyntaxError, match=reason) as info:
        parse_line(line)
    assert repr(line[:8])[2:-1] in str(info.value)


def test_format_frame_round_trips() -> None:
    msg = can.Message(arbitration_id=0x185, is_extended_id=False, data=b"\x01\x02\x03\x04")
    assert format_frame(msg) == b"t185401020304\r"
    assert format_frame(msg, timestamp_ms=60001) == b"t1854010203040001\r"
    back = parse_line(format_frame(msg)[:-1]).frame
    assert back.arbitration_id == 0x185 and bytes(back.data) == bytes(msg.data)


def test_session_lawicel_rules() -> None:
    s = SlcanSession(serial_number="AB12")
    assert s.feed(b"t0800\r") == (ERROR, [])  # closed: no transmit
    assert s.feed(b"C\r")[0] == ERROR  # closing a closed channel
    assert s.feed(b"S6\r")[0] == OK and s.bitrate == 500_000
    assert s.feed(b"S4\r")[0] == OK and s.bitrate == 125_000
    assert s.feed(b"O\r")[0] == OK and s.is_open
    assert s.feed(b"S6\r")[0] == ERROR  # no bitrate change while open
    assert s.feed(b"O\r")[0] == ERROR
    assert s.feed(b"V\r")[0] == b"V1013\r"
    assert s.feed(b"N\r")[0] == b"NAB12\r"
    replies, frames = s.feed(b"t0800\rT000007051" + b"05\r")
    assert replies == b"z\rZ\r" and [f.arbitration_id for f in frames] == [0x80, 0x705]
    replies, frames = s.feed(b"t60")  # split anywhere
    assert (replies, frames) == (b"", [])
    replies, frames = s.feed(b"1440010600\r")
    assert replies == b"z\r" and bytes(frames[0].data) == bytes.fromhex("40010600")
    assert s.feed(b"C\r")[0] == OK and not s.is_open
    assert s.feed(b"L\r")[0] == OK and s.feed(b"t0800\r")[0] == ERROR  # listen only


def test_session_survives_overlong_garbage() -> None:
    s = SlcanSession()
    replies, _ = s.feed(b"x" * 5000 + b"\r" + b"V\r")
    assert replies == ERROR + b"V1013\r"
    assert s.errors == 1


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=200))
def test_fuzz_parse_line_only_raises_our_error(data: bytes) -> None:
    line = data.replace(b"\r", b"")
    try:
        cmd = parse_line(line)
    except SlcanSyntaxError as exc:
        assert exc.line[:10] == line[:10]
    else:
        assert cmd.kind in "OLCVNFSsZtTrR" or cmd.kind == ""


@settings(max_examples=300, deadline=None)
@given(st.lists(st.binary(max_size=64), max_size=20))
def test_fuzz_session_never_raises(chunks: list[bytes]) -> None:
    s = SlcanSession()
    for chunk in chunks:
        replies, frames = s.feed(chunk)
        assert set(replies) <= set(b"\r\azZVNF0123456789ABCDEFSIM")
        assert all(isinstance(f, can.Message) for f in frames)
    # a fresh command still works after any garbage once a line end flushes it
    replies, _ = s.feed(b"\rV\r")
    assert replies.endswith(b"V1013\r")


def _recv_until(sock: socket.socket, end: bytes, timeout_s: float = 5.0) -> bytes:
    sock.settimeout(timeout_s)
    buf = b""
    while not buf.endswith(end):
        chunk = sock.recv(4096)
        if not chunk:
            break
        buf += chunk
    return buf


@pytest.fixture
def adapter():
    with SlcanAdapter(channel=f"slcan-{uuid.uuid4().hex[:8]}") as a:
        yield a


def test_python_can_slcan_talks_to_it(adapter: SlcanAdapter) -> None:
    peer = can.Bus(interface="virtual", channel=adapter.channel)
    bus = can.Bus(interface="slcan", channel=adapter.address, sleep_after_open=0, bitrate=500000)
    try:
        assert bus.get_version(2.0) == (10, 13)
        assert bus.get_serial_number(2.0) == "SIM1"
        bus.send(can.Message(arbitration_id=0x601, is_extended_id=False, data=b"\x40\x18\x10\x01"))
        got = peer.recv(5.0)
        assert got is not None and got.arbitration_id == 0x601
        assert bytes(got.data) == b"\x40\x18\x10\x01"
        peer.send(can.Message(arbitration_id=0x1ABCDEF, is_extended_id=True, data=b"\xff"))
        deadline = time.monotonic() + 5
        back = None
        while back is None and time.monotonic() < deadline:
            back = bus.recv(0.1)
        assert back is not None and back.is_extended_id and back.arbitration_id == 0x1ABCDEF
        assert bytes(back.data) == b"\xff"
    finally:
        bus.shutdown()
        peer.shutdown()


def test_one_client_at_a_time_and_reconnect(adapter: SlcanAdapter) -> None:
    host, port = adapter.address.removeprefix("socket://").split(":")
    first = socket.create_connection((host, int(port)), timeout=5)
    first.sendall(b"V\r")
    assert _recv_until(first, b"\r") == b"V1013\r"
    second = socket.create_connection((host, int(port)), timeout=5)
    second.settimeout(5)
    assert second.recv(10) == b""  # busy, like an open tty: refused
    second.close()
    adapter.backdoor.disconnect()
    first.settimeout(5)
    assert first.recv(10) == b""
    first.close()
    third = socket.create_connection((host, int(port)), timeout=5)
    third.sendall(b"N\r")
    assert _recv_until(third, b"\r") == b"NSIM1\r"
    third.close()


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(garbage=st.binary(min_size=1, max_size=300))
def test_fuzz_over_tcp_server_keeps_serving(adapter: SlcanAdapter, garbage: bytes) -> None:
    host, port = adapter.address.removeprefix("socket://").split(":")
    with socket.create_connection((host, int(port)), timeout=5) as sock:
        sock.sendall(garbage + b"\rV\r")
        assert _recv_until(sock, b"V1013\r").endswith(b"V1013\r")
    deadline = time.monotonic() + 5
    while adapter._client is not None and time.monotonic() < deadline:  # let it see the close
        time.sleep(0.005)
