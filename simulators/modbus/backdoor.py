"""Fault injection for the simulated Modbus devices (the lewis-style backdoor).

Tests and ``rig sim`` set faults here; the protocol face (``simulators/modbus/server.py``)
consults it on every request and reply. All setters are safe to call from any thread.

Faults, per Modbus unit id (``None`` = every unit on the server):

- ``silence(unit)``: requests are processed but no reply is sent (the master times out);
- ``delay(seconds)``: every reply is held back that long;
- ``exception(unit, code)``: every request to ``unit`` is answered with that exception code;
- ``garble(unit)``: reply frames are corrupted on the wire (RTU: bad CRC; TCP: bad header);
- ``stick_sensor()``: the torque sensor's input registers freeze (value and counter);
- ``disconnect()``: every open connection is dropped (the master sees a closed socket); on
  a serial line (``rtu-serial``) there is no connection, so it silences the line instead,
  as a pulled RS-485 cable would, until ``clear()``.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from pymodbus.constants import ExcCodes

ALL_UNITS = -1


class ModbusBackdoor:
    """Fault switches of one :class:`simulators.modbus.server.ModbusRigServer`."""

    def __init__(self, rtu: bool) -> None:
        self.rtu = rtu
        self._lock = threading.Lock()
        self._silent: set[int] = set()
        self._garbled: set[int] = set()
        self._exceptions: dict[int, ExcCodes] = {}
        self.delay_s = 0.0
        self.sensor_stuck = False
        self.replies_dropped = 0
        self.replies_garbled = 0
        self._disconnect: Callable[[], None] | None = None

    # -- setters (tests, rig sim) -------------------------------------------------------
    def silence(self, unit: int | None = None, on: bool = True) -> None:
        """Stop (or resume) answering ``unit`` (None = all units)."""
        key = ALL_UNITS if unit is None else unit
        with self._lock:
            (self._silent.add if on else self._silent.discard)(key)

    def garble(self, unit: int | None = None, on: bool = True) -> None:
        """Corrupt (or stop corrupting) reply frames of ``unit`` (None = all units)."""
        key = ALL_UNITS if unit is None else unit
        with self._lock:
            (self._garbled.add if on else self._garbled.discard)(key)

    def exception(self, unit: int | None, code: int | None) -> None:
        """Answer every request to ``unit`` with Modbus exception ``code`` (None clears)."""
        key = ALL_UNITS if unit is None else unit
        with self._lock:
            if code is None:
                self._exceptions.pop(key, None)
            else:
                self._exceptions[key] = ExcCodes(code)

    def delay(self, seconds: float) -> None:
        """Hold every reply back by ``seconds`` (0 clears)."""
        if seconds < 0:
            raise ValueError(f"delay must be >= 0 s, got {seconds}")
        self.delay_s = float(seconds)

    def stick_sensor(self, on: bool = True) -> None:
        """Freeze (or unfreeze) the torque sensor's input registers."""
        self.sensor_stuck = on

    def disconnect(self) -> None:
        """Drop every open connection now (the server keeps listening)."""
        if self._disconnect is None:
            raise RuntimeError("the Modbus server is not running: nothing to disconnect")
        self._disconnect()

    def clear(self) -> None:
        """Remove every fault."""
        with self._lock:
            self._silent.clear()
            self._garbled.clear()
            self._exceptions.clear()
        self.delay_s = 0.0
        self.sensor_stuck = False

    # -- used by the face ---------------------------------------------------------------
    def attach_disconnect(self, fn: Callable[[], None] | None) -> None:
        self._disconnect = fn

    def exception_for(self, unit: int) -> ExcCodes | None:
        with self._lock:
            return self._exceptions.get(unit, self._exceptions.get(ALL_UNITS))

    def _unit_of(self, frame: bytes) -> int | None:
        if self.rtu:
            return frame[0] if frame else None
        return frame[6] if len(frame) > 6 else None  # MBAP header: unit id is byte 6

    def filter_reply(self, frame: bytes) -> bytes:
        """Apply silence/garble to an outgoing reply frame; b"" means send nothing."""
        unit = self._unit_of(frame)
        with self._lock:
            silent = ALL_UNITS in self._silent or unit in self._silent
            garbled = ALL_UNITS in self._garbled or unit in self._garbled
        if silent:
            self.replies_dropped += 1
            return b""
        if garbled and frame:
            self.replies_garbled += 1
            data = bytearray(frame)
            if self.rtu:
                data[-1] ^= 0xA5  # breaks the CRC
            else:
                data[2] ^= 0x5A  # MBAP protocol id must be 0
            return bytes(data)
        return frame
