"""Chunked reading of an SLCAN adapter's serial port for python-can's ``slcan`` bus.

python-can 4.6.1's ``slcanBus._read`` takes one byte per ``read(1)`` after asking
``in_waiting``; on pyserial each is a ``select`` and a ``recv`` (a ``socket://`` port's
``in_waiting`` is 0 or 1, never a count). At 500 frames a second of ~20 bytes that was 21 %
of the Python time of a session with the rig simulated in its process (py-spy ``--gil``),
time that a loaded PC then lacked. :class:`ChunkedPort` wraps the port: the first byte is
waited for as before (the port's own timeout), then everything already received is taken in
one call and handed out from memory; nothing is read ahead of what has arrived, so no frame
waits longer than it did.
"""

from __future__ import annotations

import socket
from typing import Any

__all__ = ["ChunkedPort", "read_in_chunks"]

CHUNK = 65536
"""Most bytes taken at once (a backlog of ~3,000 frames)."""


class ChunkedPort:
    """A pyserial port whose ``read`` hands out what has arrived from memory; every other
    attribute is the wrapped port's."""

    def __init__(self, port: Any) -> None:
        self._port = port
        self._buffer = bytearray()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._port, name)

    @property
    def in_waiting(self) -> int:
        """Bytes ready: those in memory, else the port's own answer."""
        return len(self._buffer) or self._port.in_waiting

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` bytes; with none in memory, wait for one (the port's timeout) and
        take with it every byte that has arrived."""
        if not self._buffer:
            first = self._port.read(1)
            if not first:
                return b""
            self._buffer += first
            self._buffer += self._arrived()
        out = bytes(self._buffer[:size])
        del self._buffer[:size]
        return out

    def reset_input_buffer(self) -> None:
        self._buffer.clear()
        self._port.reset_input_buffer()

    def _arrived(self) -> bytes:
        """The bytes already received, without waiting."""
        sock = getattr(self._port, "_socket", None)  # pyserial's socket:// handler
        if isinstance(sock, socket.socket):
            try:
                return sock.recv(CHUNK, socket.MSG_DONTWAIT)
            except (BlockingIOError, InterruptedError):
                return b""
        waiting = self._port.in_waiting  # a tty: the count the driver holds (TIOCINQ)
        return self._port.read(min(waiting, CHUNK)) if waiting else b""


def read_in_chunks(bus: Any) -> None:
    """Make python-can's slcan ``bus`` read its port in chunks (no-op for other buses)."""
    port = getattr(bus, "serialPortOrig", None)
    if port is not None and not isinstance(port, ChunkedPort):
        bus.serialPortOrig = ChunkedPort(port)
