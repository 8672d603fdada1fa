"""The driver over ``rfc2217://``: pyserial's own RFC 2217 port server in front of the device.

This is the path of ports that cannot be select()ed (the driver polls them), and the way a
transducer on a remote serial server (a Moxa NPort, ser2net) is reached.
"""

from __future__ import annotations

import socket
import threading
from collections.abc import Iterator

import pytest
import serial
import serial.rfc2217

from drivers.transducer.serial import SerialTorqueTransducer, TransducerConfig
from simulators.transducer import SineTorqueSource, TransducerSimulator

# pyserial 3.5's own rfc2217 client thread uses setDaemon()/setName()
pytestmark = [pytest.mark.realtime,
              pytest.mark.filterwarnings(r"ignore:set(Daemon|Name)\(\) is deprecated")]


class _SocketWriter:
    """What PortManager writes its telnet replies to."""

    def __init__(self, conn: socket.socket) -> None:
        self.conn = conn

    def write(self, data: bytes) -> None:
        self.conn.sendall(data)


def _serve_rfc2217(device_url: str, listener: socket.socket, stop: threading.Event) -> None:
    """Accept one client and bridge it to the device through serial.rfc2217.PortManager.

    The device side is the simulator's TCP face: PortManager polls modem lines (CTS, DSR),
    which a pty does not have.
    """
    conn, _ = listener.accept()
    port = serial.serial_for_url(device_url, timeout=0.05)
    manager = serial.rfc2217.PortManager(port, _SocketWriter(conn))

    def pty_to_client() -> None:
        while not stop.is_set():
            data = port.read(port.in_waiting or 1)
            if data:
                conn.sendall(b"".join(manager.escape(data)))

    pump = threading.Thread(target=pty_to_client, daemon=True)
    pump.start()
    try:
        conn.settimeout(0.1)
        while not stop.is_set():
            try:
                data = conn.recv(4096)
            except TimeoutError:
                continue
            if not data:
                break
            port.write(b"".join(manager.filter(data)))
    finally:
        stop.set()
        pump.join(5)
        port.close()
        conn.close()


@pytest.fixture
def rfc2217_url() -> Iterator[str]:
    with TransducerSimulator(SineTorqueSource(amplitude_Nm=3.0), "tcp") as sim:
        assert sim.address is not None
        listener = socket.create_server(("127.0.0.1", 0))
        stop = threading.Event()
        bridge = threading.Thread(
            target=_serve_rfc2217, args=(sim.address, listener, stop), daemon=True
        )
        bridge.start()
        yield f"rfc2217://127.0.0.1:{listener.getsockname()[1]}"
        stop.set()
        listener.close()
        bridge.join(10)


def test_driver_over_rfc2217(rfc2217_url: str) -> None:
    with SerialTorqueTransducer(TransducerConfig(url=rfc2217_url, timeout_s=3.0)) as tt:
        assert tt.identity().manufacturer == "RIGSIM"
        assert abs(tt.read().torque_Nm) <= 3.0
        tt.start_stream(200)
        readings = list(tt.readings(100))
        stats = tt.stop_stream()
    assert stats.received == 100 and stats.bad_lines == 0
    assert [r.seq for r in readings] == list(range(readings[0].seq, readings[0].seq + 100))
