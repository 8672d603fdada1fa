"""The ASCII line protocol of the serial torque transducer: pure parsing and formatting.

The protocol is specified in ``docs/transducer-protocol.md``. In short: the host sends
commands such as ``TQ?`` or ``STREAM 500`` ended by CR, LF or CR LF; every line the device
sends is ``<body>*<HH><terminator>``, where ``HH`` is the XOR of the body's bytes in two
upper-case hex digits (as in NMEA 0183), so a garbled line is always recognised.

Measurement lines (the reply to ``TQ?`` and every streamed sample) read
``<TQ|ST> <seq:6 digits> <device time s> <torque> <unit> <OK|OV>``, e.g.
``ST 000123 12.345678 +12.34560 Nm OK*1F``.

No I/O here: the driver (``drivers/transducer/serial.py``) and the simulator
(``simulators/transducer.py``) share these definitions.
"""

from __future__ import annotations

import operator
import re
from dataclasses import dataclass
from functools import reduce
from typing import NoReturn

from drivers.errors import DeviceProtocolError

SEQ_MODULO = 1_000_000  # the sequence counter has 6 decimal digits and wraps to 0
DEVICE_TIME_MODULO_S = 100_000.0  # the device clock (s since power-on) wraps at 1e5 s
MAX_COMMAND_CHARS = 64  # longer command lines get ERR 1
MAX_LINE_BYTES = 128  # longer device lines are a protocol error
MAX_STREAM_RATE_HZ = 2000.0  # the transducer's fastest output rate
UART_BITS_PER_BYTE = 10  # 8N1: start + 8 data + stop

MEASUREMENT_TAGS = ("TQ", "ST")  # TQ: reply to TQ?; ST: streamed sample
STATUS_OK = "OK"
STATUS_OVERLOAD = "OV"  # |torque| above the full scale (range)

ERROR_TEXT: dict[int, str] = {
    1: "line too long",
    2: "bad argument",
    3: "unknown command",
    4: "not allowed while streaming",
    5: "rate out of range",
    6: "tare out of range",
    7: "internal fault",
}

_BODY_CHARS = re.compile(rb"[\x20-\x7e]+")  # printable ASCII
_HEX2 = re.compile(rb"[0-9A-F]{2}")
_MEASUREMENT = re.compile(
    r"(?P<tag>TQ|ST) (?P<seq>\d{6}) (?P<t>\d{1,5}\.\d{6}) "
    r"(?P<torque>[+-]\d{1,6}\.\d{5}) (?P<unit>[A-Za-z.]{1,6}) (?P<status>OK|OV)"
)
_ERROR = re.compile(r"ERR (?P<code>\d{1,3}) (?P<text>[ -~]{1,60})")
_REPLY = re.compile(r"(?P<keyword>[A-Z]{2,8})(?: (?P<args>[ -~]{1,100}))?")


@dataclass(frozen=True)
class Measurement:
    """One torque sample as the device sent it.

    ``seq`` counts samples (mod 1e6), ``device_t_s`` is the device clock (s, mod 1e5),
    ``torque_Nm`` the tared torque (N*m, 1e-5 N*m resolution), ``status`` OK or OV.
    """

    tag: str
    seq: int
    device_t_s: float
    torque_Nm: float
    unit: str
    status: str


@dataclass(frozen=True)
class ErrorReply:
    """``ERR <code> <text>``: the device refused the last command."""

    code: int
    text: str


@dataclass(frozen=True)
class Reply:
    """Any other reply: ``OK`` or ``<KEYWORD> <args>`` (``RANGE 20.000 Nm``, ``IDN ...``)."""

    keyword: str
    args: str


DeviceLine = Measurement | ErrorReply | Reply


def checksum(body: bytes) -> int:
    """XOR of all bytes of ``body`` (0..255), the NMEA 0183 line checksum."""
    return reduce(operator.xor, body, 0)


def frame_line(body: str, terminator: str = "\r\n") -> bytes:
    """Encode one device line: ``<body>*<HH><terminator>`` in ASCII."""
    raw = body.encode("ascii")
    return raw + b"*%02X" % checksum(raw) + terminator.encode("ascii")


def format_measurement(
    tag: str, seq: int, device_t_s: float, torque_Nm: float, unit: str, status: str
) -> str:
    """The body of a measurement line, e.g. ``ST 000123 12.345678 +12.34560 Nm OK``."""
    t = device_t_s % DEVICE_TIME_MODULO_S
    return f"{tag} {seq % SEQ_MODULO:06d} {t:.6f} {torque_Nm:+.5f} {unit} {status}"


def stream_line_bytes(full_scale_Nm: float, unit: str = "Nm", terminator: str = "\r\n") -> int:
    """Longest streamed line in bytes for a transducer of range ``full_scale_Nm`` (N*m).

    The budget assumes readings up to 10x the range (a hard overload) and the widest
    device time, checksum and terminator included.
    """
    widest = format_measurement(
        "ST", SEQ_MODULO - 1, DEVICE_TIME_MODULO_S - 1e-6, -10.0 * full_scale_Nm, unit, "OV"
    )
    return len(frame_line(widest, terminator))


def max_stream_rate_Hz(
    baudrate: int, full_scale_Nm: float, unit: str = "Nm", terminator: str = "\r\n"
) -> float:
    """Fastest stream rate (Hz) the UART carries at ``baudrate`` (8N1), capped at 2 kHz.

    rate_max = baudrate / (10 bit/byte * line bytes); e.g. a 20 N*m transducer has 44-byte
    lines, so 460800 Bd carries 1047 Hz and 115200 Bd 261 Hz.
    """
    bytes_per_s = baudrate / UART_BITS_PER_BYTE
    rate = bytes_per_s / stream_line_bytes(full_scale_Nm, unit, terminator)
    return min(float(int(rate)), MAX_STREAM_RATE_HZ)


def parse_line(raw: bytes, device: str = "torque transducer") -> DeviceLine:
    """Parse one line as the device sent it (terminator optional) into a typed reply.

    Raises :class:`DeviceProtocolError` naming ``device``, what a line must look like and
    quoting the bytes that came, for anything that is not a well-formed, checksummed line.
    """
    if len(raw) > MAX_LINE_BYTES:
        _bad(device, "a line of at most 128 bytes", raw)
    line = raw.rstrip(b"\r\n").lstrip(b"\r\n")
    star = line.rfind(b"*")
    if star < 0 or len(line) - star != 3:
        _bad(device, "a line ending in '*HH' (checksum)", raw)
    body, given = line[:star], line[star + 1 :]
    if not _BODY_CHARS.fullmatch(body) or b"*" in body:
        _bad(device, "printable ASCII before the checksum", raw)
    if not _HEX2.fullmatch(given) or int(given, 16) != checksum(body):
        _bad(device, f"checksum {checksum(body):02X} (two upper-case hex digits)", raw)
    text = body.decode("ascii")
    if m := _MEASUREMENT.fullmatch(text):
        return Measurement(
            tag=m["tag"],
            seq=int(m["seq"]),
            device_t_s=float(m["t"]),
            torque_Nm=float(m["torque"]),
            unit=m["unit"],
            status=m["status"],
        )
    if text.startswith(("TQ ", "ST ")):
        _bad(device, "'<TQ|ST> <seq> <t_s> <torque> <unit> <OK|OV>'", raw)
    if m := _ERROR.fullmatch(text):
        return ErrorReply(code=int(m["code"]), text=m["text"])
    if text.startswith("ERR"):
        _bad(device, "'ERR <code> <text>'", raw)
    if m := _REPLY.fullmatch(text):
        return Reply(keyword=m["keyword"], args=m["args"] or "")
    _bad(device, "'<KEYWORD> [args]' in upper case", raw)


def parse_quantity(reply: Reply, unit: str, device: str = "torque transducer") -> float:
    """The number of a ``<KEYWORD> <number> <unit>`` reply (``RANGE 20.000 Nm`` -> 20.0)."""
    parts = reply.args.split(" ")
    try:
        if len(parts) == 2 and parts[1] == unit:
            return float(parts[0])
    except ValueError:
        pass
    raise DeviceProtocolError(
        device, f"'{reply.keyword} <number> {unit}'", repr(f"{reply.keyword} {reply.args}")
    )


def _bad(device: str, expected: str, raw: bytes) -> NoReturn:
    raise DeviceProtocolError(device, expected, repr(bytes(raw)))
