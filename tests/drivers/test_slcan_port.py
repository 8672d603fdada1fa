"""drivers.canbus.slcan_port: the SLCAN serial port read in chunks hands out the same bytes,
in order, as byte-by-byte reading, waits no longer for the first byte, and takes a burst in
one receive; python-can's slcan bus reads frames through it."""

from __future__ import annotations

import socket
import time

import can
import serial

from drivers.canbus.slcan_port import ChunkedPort, read_in_chunks
from simulators.slcan_adapter import SlcanAdapter


def _pair() -> tuple[socket.socket, serial.SerialBase]:
    server = socket.create_server(("127.0.0.1", 0))
    port = serial.serial_for_url(f"socket://127.0.0.1:{server.getsockname()[1]}", timeout=0.05)
    conn, _ = server.accept()
    server.close()
    return conn, port


def test_bytes_come_out_in_order_and_a_burst_in_one_receive() -> None:
    conn, raw = _pair()
    port = ChunkedPort(raw)
    try:
        t0 = time.monotonic()
        assert port.read(1) == b"" and time.monotonic() - t0 < 0.5  # the port's timeout
        burst = b"".join(f"t18140{i:08X}\r".encode() for i in range(200))
        conn.sendall(burst)
        time.sleep(0.1)
        got = bytearray(port.read(1))
        assert port.in_waiting == len(burst) - 1  # the rest is in memory: one receive
        while len(got) < len(burst):
            got += port.read(1)
        assert bytes(got) == burst and port.read(1) == b""
        conn.sendall(b"abc")
        assert port.read(5) == b"abc"  # never more than has arrived
    finally:
        conn.close()
        raw.close()


def test_python_can_slcan_reads_frames_through_it() -> None:
    with SlcanAdapter(channel="chunked-port-test") as adapter:
        bus = can.Bus(interface="slcan", channel=adapter.address, sleep_after_open=0)
        peer = can.Bus(interface="virtual", channel="chunked-port-test")
        try:
            read_in_chunks(bus)
            read_in_chunks(bus)  # once only
            assert isinstance(bus.serialPortOrig, ChunkedPort)
            assert not isinstance(bus.serialPortOrig._port, ChunkedPort)
            # the adapter forwards frames once it has executed the bus's "O" (open), which
            # python-can sends without waiting (sleep_after_open=0): probe until one arrives
            deadline = time.monotonic() + 10.0
            while bus.recv(0.0) is None and time.monotonic() < deadline:
                peer.send(can.Message(arbitration_id=0x700, is_extended_id=False, data=b""))
                if bus.recv(0.2) is not None:
                    break
            while bus.recv(0.3) is not None:  # a late probe
                pass
            for i in range(50):
                peer.send(can.Message(arbitration_id=0x181, is_extended_id=False,
                                      data=i.to_bytes(4, "little")))
            got = [bus.recv(5.0) for _ in range(50)]  # returns at each frame; load may delay one
            assert [int.from_bytes(m.data, "little") for m in got] == list(range(50))
            bus.send(can.Message(arbitration_id=0x80, is_extended_id=False, data=b""))
            echo = peer.recv(1.0)
            assert echo is not None and echo.arbitration_id == 0x80  # writes pass through
        finally:
            bus.shutdown()
            peer.shutdown()
