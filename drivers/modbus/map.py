"""The Modbus register maps of the torque sensor and the loading drive, declared as data.

Both the drivers (``drivers/modbus/torque_sensor.py``, ``drivers/loading_drive.py``) and the
simulated devices (``simulators/modbus/server.py``) read this module, so the wire layout is
written down once. ``docs/modbus.md`` explains it for a technician (with mbpoll lines).

Conventions (binding for both sides):

- Addresses are 0-based protocol addresses (mbpoll's ``-r`` is 1-based: ``-r 1`` = address 0).
- ``float32`` is IEEE 754 single in two registers, high word first ("ABCD", big-endian words;
  mbpoll needs ``-B``). ``uint32`` likewise, high word first.
- Input registers (function code 4) and holding registers (3, 6, 16) are separate tables.
- Torques in N*m, times in ms where a register says so.

The decoders here turn raw register words into values and raise
:class:`drivers.errors.DeviceProtocolError` (naming the device, what was expected, what came)
for anything the map does not allow; they never raise anything else.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

from pymodbus.client.mixin import ModbusClientMixin as _CODEC

from drivers.errors import DeviceProtocolError

Table = Literal["input", "holding"]
Datatype = Literal["uint16", "uint32", "float32"]

WORDS_PER_TYPE: dict[str, int] = {"uint16": 1, "uint32": 2, "float32": 2}

SENSOR_DEVICE_ID = 1
"""Default Modbus unit id of the torque sensor."""
DRIVE_DEVICE_ID = 2
"""Default Modbus unit id of the loading drive."""


@dataclass(frozen=True)
class Register:
    """One value in a device's register map.

    ``address`` is the 0-based protocol address of its first word; ``access`` is ``"r"``
    (read-only) or ``"rw"``.
    """

    name: str
    table: Table
    address: int
    datatype: Datatype
    access: Literal["r", "rw"]
    unit: str
    description: str

    @property
    def count(self) -> int:
        """Number of 16-bit registers the value spans."""
        return WORDS_PER_TYPE[self.datatype]

    @property
    def end(self) -> int:
        """One past the last register address."""
        return self.address + self.count


class SensorStatus(enum.IntFlag):
    """Torque sensor status word (input register ``status``)."""

    VALID = 0x0001  # a measurement is available
    OVERLOAD = 0x0002  # |torque| beyond the full scale
    TARED = 0x0004  # a tare offset is being subtracted
    FAULT = 0x0008  # sensor-internal fault (bridge open, supply low)


class SensorCommand(enum.IntEnum):
    """Values the master writes into the sensor's ``command`` holding register."""

    NONE = 0
    TARE = 1  # take the present raw reading as the zero
    CLEAR_TARE = 2  # forget the tare offset


class DriveStatusBits(enum.IntFlag):
    """Loading drive status word (input register ``status``)."""

    ENABLED = 0x0001  # power stage on, following the setpoint
    FAULT = 0x0002  # a fault is latched (see ``fault_code``); reset with FAULT_RESET
    LIMIT = 0x0004  # the last setpoint was refused for exceeding the torque limit
    WATCHDOG = 0x0008  # the communication watchdog tripped


class DriveControl(enum.IntFlag):
    """Loading drive control word (holding register ``control``)."""

    ENABLE = 0x0001  # 1: power stage on; 0: off (zero torque)
    FAULT_RESET = 0x0080  # clear a latched fault (the drive stays disabled)


class DriveFaultCode(enum.IntEnum):
    """Loading drive fault codes (input register ``fault_code``). Faults latch."""

    NONE = 0
    SETPOINT_OVER_LIMIT = 1  # a setpoint beyond the torque limit was written (refused)
    WATCHDOG_TIMEOUT = 2  # no keep-alive write within the watchdog time
    SETPOINT_NOT_FINITE = 3  # NaN or infinity written as setpoint (refused)


def register_block(*registers: Register) -> dict[str, Register]:
    """A device's register table keyed by register name."""
    return {r.name: r for r in registers}


TORQUE_SENSOR_MAP: dict[str, Register] = register_block(
    Register("torque", "input", 0, "float32", "r", "N*m",
             "measured torque, tare offset subtracted, signed"),
    Register("status", "input", 2, "uint16", "r", "-", "status word, see SensorStatus"),
    Register("sample_counter", "input", 3, "uint32", "r", "-",
             "count of internal conversions (1 kHz); stops when the sensor hangs"),
    Register("full_scale", "input", 5, "float32", "r", "N*m", "rated measuring range"),
    Register("command", "holding", 0, "uint16", "rw", "-",
             "write 1 = tare, 2 = clear tare (reads back 0)"),
    Register("tare_offset", "holding", 1, "float32", "rw", "N*m",
             "offset subtracted from the raw torque"),
)

LOADING_DRIVE_MAP: dict[str, Register] = register_block(
    Register("status", "input", 0, "uint16", "r", "-", "status word, see DriveStatusBits"),
    Register("fault_code", "input", 1, "uint16", "r", "-", "latched fault, see DriveFaultCode"),
    Register("actual_torque", "input", 2, "float32", "r", "N*m", "torque the drive delivers"),
    Register("active_setpoint", "input", 4, "float32", "r", "N*m",
             "setpoint in force (0 while disabled)"),
    Register("control", "holding", 0, "uint16", "rw", "-", "control word, see DriveControl"),
    Register("setpoint", "holding", 1, "float32", "rw", "N*m",
             "torque setpoint; |value| > torque_limit is refused (exception 3 + fault 1)"),
    Register("keepalive", "holding", 3, "uint16", "rw", "-",
             "write any value to feed the communication watchdog"),
    Register("watchdog_ms", "holding", 4, "uint16", "rw", "ms",
             "communication watchdog time, 10..60000"),
    Register("torque_limit", "holding", 5, "float32", "r", "N*m",
             "the drive's own torque limit (set at commissioning)"),
)

WATCHDOG_MS_RANGE = (10, 60000)
"""Allowed values of the drive's ``watchdog_ms`` register (0 = off is not allowed)."""


def table_span(register_map: dict[str, Register], table: Table) -> tuple[int, int]:
    """(first address, register count) covering every value of ``table`` in the map."""
    regs = [r for r in register_map.values() if r.table == table]
    first = min(r.address for r in regs)
    return first, max(r.end for r in regs) - first


def _words(words: Sequence[int], count: int, device: str, what: str) -> list[int]:
    """Check ``words`` are ``count`` 16-bit register values and return them as a list."""
    try:
        values = [int(w) for w in words]
    except (TypeError, ValueError) as exc:
        raise DeviceProtocolError(device, f"{count} register word(s) for {what}",
                                  f"{words!r}") from exc
    if len(values) != count:
        raise DeviceProtocolError(device, f"{count} register word(s) for {what}",
                                  f"{len(values)} word(s) {values!r}")
    for w in values:
        if not 0 <= w <= 0xFFFF:
            raise DeviceProtocolError(device, f"16-bit register words for {what}",
                                      f"{w} in {values!r}")
    return values


def decode_uint16(words: Sequence[int], device: str, what: str) -> int:
    """One register word -> unsigned integer 0..65535."""
    return _words(words, 1, device, what)[0]


def decode_uint32(words: Sequence[int], device: str, what: str) -> int:
    """Two register words (high word first) -> unsigned integer 0..2**32-1."""
    hi, lo = _words(words, 2, device, what)
    return (hi << 16) | lo


def decode_float32(words: Sequence[int], device: str, what: str) -> float:
    """Two register words (high word first, IEEE 754 single) -> finite float.

    NaN and infinities are not valid measurements or setpoints: DeviceProtocolError.
    """
    hi, lo = _words(words, 2, device, what)
    value = float(_CODEC.convert_from_registers([hi, lo], _CODEC.DATATYPE.FLOAT32))
    if not math.isfinite(value):
        raise DeviceProtocolError(device, f"a finite float32 for {what}",
                                  f"{value} (words 0x{hi:04X} 0x{lo:04X})")
    return float(value)


def encode_float32(value: float) -> list[int]:
    """Float -> two register words (high word first, IEEE 754 single)."""
    return list(_CODEC.convert_to_registers(float(value), _CODEC.DATATYPE.FLOAT32))


def float_from_words(words: Sequence[int]) -> float:
    """Two register words (high word first, IEEE 754 single) -> float, NaN and inf kept (the
    simulated devices decode what a master wrote, whatever it is)."""
    return float(_CODEC.convert_from_registers([int(words[0]), int(words[1])],
                                               _CODEC.DATATYPE.FLOAT32))


def encode_uint32(value: int) -> list[int]:
    """Unsigned integer 0..2**32-1 -> two register words (high word first)."""
    value = int(value) & 0xFFFFFFFF
    return [value >> 16, value & 0xFFFF]


def decode_flags(word: int, flags: type[enum.IntFlag], device: str, what: str) -> enum.IntFlag:
    """A status word -> ``flags`` member; bits the map does not define are a protocol error."""
    value = decode_uint16([word], device, what)
    known = 0
    for member in flags:
        known |= int(member)
    if value & ~known:
        raise DeviceProtocolError(device, f"{what} with only bits 0x{known:04X} defined",
                                  f"0x{value:04X}")
    return flags(value)


def decode_fault_code(word: int, device: str) -> DriveFaultCode:
    """The drive's fault code register -> :class:`DriveFaultCode`; unknown codes are errors."""
    value = decode_uint16([word], device, "fault_code")
    try:
        return DriveFaultCode(value)
    except ValueError as exc:
        known = ", ".join(f"{c.value} {c.name}" for c in DriveFaultCode)
        raise DeviceProtocolError(device, f"a fault code in ({known})", str(value)) from exc


def values_of(register_map: dict[str, Register], table: Table, first: int,
              words: Sequence[int], device: str) -> dict[str, float | int]:
    """Decode every value of ``table`` in a block of words read from address ``first``."""
    out: dict[str, float | int] = {}
    words = list(words)
    span_first, span_count = table_span(register_map, table)
    if first != span_first or len(words) != span_count:
        raise DeviceProtocolError(
            device, f"{span_count} {table} registers from address {span_first}",
            f"{len(words)} from address {first}")
    for reg in register_map.values():
        if reg.table != table:
            continue
        lo = reg.address - first
        chunk = words[lo:lo + reg.count] if lo >= 0 else []
        if reg.datatype == "float32":
            out[reg.name] = decode_float32(chunk, device, reg.name)
        elif reg.datatype == "uint32":
            out[reg.name] = decode_uint32(chunk, device, reg.name)
        else:
            out[reg.name] = decode_uint16(chunk, device, reg.name)
    return out
