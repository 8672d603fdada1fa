"""A simulated SLCAN (Lawicel ASCII) USB-CAN adapter on a TCP socket.

python-can's own ``slcan`` interface reaches it through pyserial's ``socket://`` URL
(``can.Bus(interface="slcan", channel="socket://127.0.0.1:PORT", sleep_after_open=0,
bitrate=500000)``), so the driver side runs the real library, in this or another process.
Behind the adapter is an internal python-can virtual bus (``channel``) where the simulated
CANopen nodes live (:class:`simulators.encoder_node.EncoderNode`).

Lawicel commands served (each line ends with CR; reply CR = ok, BEL = error):
``O`` open, ``L`` open listen-only, ``C`` close, ``S0``-``S8`` bitrate (closed only),
``sxxyy`` BTR0/BTR1 (closed only), ``V`` version (``Vhhss``), ``N`` serial (``Nxxxx``),
``F`` status flags, ``Z0``/``Z1`` time stamps off/on, ``tiiildd..``/``Tiiiiiiiildd..``
standard/extended frames, ``riiil``/``Riiiiiiiil`` remote frames (reply ``z``/``Z`` + CR).
Received frames go to the client in the same format, with a 4-hex-digit ms time stamp
when ``Z1`` is on. A malformed line, an unknown command or an over-long line gets BEL;
the parser never raises anything but :class:`SlcanSyntaxError` (fuzzed in tests).

The backdoor (:class:`SlcanBackdoor`) garbles outgoing frame lines (bad hex or wrong DLC),
sends raw line noise, drops the TCP connection, or unplugs the CAN side (no frames pass either way).
"""

from __future__ import annotations

import contextlib
import socket
import string
import struct
import threading
import time
from dataclasses import dataclass
from typing import Literal

import can

from drivers.lifecycle import RunsWhileEntered
from simulators.canbus.virtual import virtual_bus

OK = b"\r"
ERROR = b"\a"
MAX_LINE = 32  # the longest valid line: "T" + 8 id + 1 dlc + 16 data = 26 chars
_HEX = frozenset(string.hexdigits.encode())
BITRATES = {
    0: 10_000,
    1: 20_000,
    2: 50_000,
    3: 100_000,
    4: 125_000,
    5: 250_000,
    6: 500_000,
    7: 800_000,
    8: 1_000_000,
}


class SlcanSyntaxError(ValueError):
    """A line that is not a valid Lawicel command: names the line and what is wrong."""

    def __init__(self, line: bytes, reason: str) -> None:
        self.line = line
        self.reason = reason
        super().__init__(f"SLCAN line {line!r}: {reason}")


@dataclass(frozen=True)
class SlcanCommand:
    """One parsed Lawicel command; ``frame`` is set for t/T/r/R, ``arg`` for S/s/Z."""

    kind: str
    frame: can.Message | None = None
    arg: str = ""


def _hex(line: bytes, field: bytes, what: str) -> int:
    if not field or any(b not in _HEX for b in field):
        raise SlcanSyntaxError(line, f"{what} {field!r} is not hexadecimal")
    return int(field, 16)


def parse_line(line: bytes) -> SlcanCommand:
    """Parse one Lawicel command line (without its CR). Raises :class:`SlcanSyntaxError`."""
    if len(line) > MAX_LINE:
        raise SlcanSyntaxError(line[:MAX_LINE] + b"...", f"longer than {MAX_LINE} characters")
    if not line:
        return SlcanCommand("")
    kind = chr(line[0])
    rest = line[1:]
    if kind in "OLCVNF":
        if rest:
            raise SlcanSyntaxError(line, f"command {kind} takes no argument")
        return SlcanCommand(kind)
    if kind == "S":
        if len(rest) != 1 or rest[0] - 0x30 not in BITRATES:
            raise SlcanSyntaxError(line, "bitrate code must be S0..S8")
        return SlcanCommand(kind, arg=rest.decode())
    if kind == "s":
        if len(rest) != 4:
            raise SlcanSyntaxError(line, "BTR setting must be 4 hex digits (sxxyy)")
        _hex(line, rest, "BTR")
        return SlcanCommand(kind, arg=rest.decode())
    if kind == "Z":
        if rest not in (b"0", b"1"):
            raise SlcanSyntaxError(line, "time stamp setting must be Z0 or Z1")
        return SlcanCommand(kind, arg=rest.decode())
    if kind in "tTrR":
        return SlcanCommand(kind, frame=_parse_frame(line))
    raise SlcanSyntaxError(line, f"unknown command {kind!r}")


def _parse_frame(line: bytes) -> can.Message:
    kind = chr(line[0])
    extended = kind in "TR"
    remote = kind in "rR"
    id_len = 8 if extended else 3
    if len(line) < 1 + id_len + 1:
        raise SlcanSyntaxError(line, "frame too short for identifier and DLC")
    can_id = _hex(line, line[1 : 1 + id_len], "identifier")
    if can_id > (0x1FFFFFFF if extended else 0x7FF):
        raise SlcanSyntaxError(line, f"identifier 0x{can_id:X} out of range")
    dlc_char = line[1 + id_len]
    if not 0x30 <= dlc_char <= 0x38:
        raise SlcanSyntaxError(line, f"DLC {chr(dlc_char)!r} is not 0..8")
    dlc = dlc_char - 0x30
    payload = line[2 + id_len :]
    if remote:
        if payload:
            raise SlcanSyntaxError(line, "a remote frame carries no data")
        data = b""
    else:
        if len(payload) != 2 * dlc:
            got = len(payload)
            raise SlcanSyntaxError(line, f"DLC {dlc} needs {2 * dlc} hex digits, got {got}")
        if dlc:
            _hex(line, payload, "data")
        data = bytes.fromhex(payload.decode("ascii"))
    return can.Message(
        arbitration_id=can_id,
        is_extended_id=extended,
        is_remote_frame=remote,
        dlc=dlc,
        data=data,
    )


def format_frame(msg: can.Message, timestamp_ms: int | None = None) -> bytes:
    """The Lawicel line (with CR) for a received frame; time stamp 0..59999 ms if given."""
    if msg.is_remote_frame:
        head = f"R{msg.arbitration_id:08X}" if msg.is_extended_id else f"r{msg.arbitration_id:03X}"
        text = f"{head}{msg.dlc:d}"
    else:
        head = f"T{msg.arbitration_id:08X}" if msg.is_extended_id else f"t{msg.arbitration_id:03X}"
        text = f"{head}{len(msg.data):d}{bytes(msg.data).hex().upper()}"
    if timestamp_ms is not None:
        text += f"{timestamp_ms % 60000:04X}"
    return text.encode() + OK


class SlcanSession:
    """The Lawicel state machine of one connection: bytes in, replies and frames out.

    :meth:`feed` takes any bytes (split anywhere) and returns the reply bytes and the
    frames to put on the CAN side. It never raises on bad input: errors become BEL.
    """

    def __init__(self, version: str = "1013", serial_number: str = "SIM1") -> None:
        self.version = version
        self.serial_number = serial_number
        self.is_open = False
        self.listen_only = False
        self.bitrate = 500_000
        self.timestamps = False
        self.errors = 0
        self._buffer = bytearray()
        self._overflow = False

    def feed(self, data: bytes) -> tuple[bytes, list[can.Message]]:
        replies = bytearray()
        frames: list[can.Message] = []
        for byte in data:
            if byte == 0x0A:  # LF after CR from terminals: ignored
                continue
            if byte != 0x0D:
                if len(self._buffer) <= MAX_LINE:
                    self._buffer.append(byte)
                else:
                    self._overflow = True
                continue
            line = bytes(self._buffer)
            self._buffer.clear()
            if self._overflow:
                self._overflow = False
                self.errors += 1
                replies += ERROR
                continue
            reply, frame = self._execute(line)
            replies += reply
            if frame is not None:
                frames.append(frame)
        return bytes(replies), frames

    def _execute(self, line: bytes) -> tuple[bytes, can.Message | None]:
        try:
            command = parse_line(line)
        except SlcanSyntaxError:
            self.errors += 1
            return ERROR, None
        kind = command.kind
        if kind == "":
            return OK, None
        if kind in "OL":
            if self.is_open:
                return ERROR, None
            self.is_open, self.listen_only = True, kind == "L"
            return OK, None
        if kind == "C":
            if not self.is_open:
                return ERROR, None
            self.is_open = False
            return OK, None
        if kind in "Ss":
            if self.is_open:
                return ERROR, None
            if kind == "S":
                self.bitrate = BITRATES[int(command.arg)]
            return OK, None
        if kind == "V":
            return f"V{self.version}".encode() + OK, None
        if kind == "N":
            return f"N{self.serial_number}".encode() + OK, None
        if kind == "F":
            return (b"F00" + OK, None) if self.is_open else (ERROR, None)
        if kind == "Z":
            self.timestamps = command.arg == "1"
            return OK, None
        # t/T/r/R: transmit
        if not self.is_open or self.listen_only:
            return ERROR, None
        ack = b"Z" if command.frame is not None and command.frame.is_extended_id else b"z"
        return ack + OK, command.frame


GarbleKind = Literal["bad_hex", "wrong_dlc"]


class SlcanBackdoor:
    """Fault injection for one :class:`SlcanAdapter`."""

    def __init__(self, adapter: SlcanAdapter) -> None:
        self._adapter = adapter
        self.garble_left = 0
        self.garble_kind: GarbleKind = "bad_hex"
        self.unplugged = False
        self.frames_per_s: float | None = None

    def garble(self, n_frames: int = 1, kind: GarbleKind = "bad_hex") -> None:
        """Corrupt the next ``n_frames`` frame lines sent to the client.

        ``bad_hex``: non-hex characters in the identifier; ``wrong_dlc``: the DLC digit is one
        less than the data carried (the receiver then takes too few bytes).
        """
        if kind not in ("bad_hex", "wrong_dlc"):
            raise ValueError(f"kind must be 'bad_hex' or 'wrong_dlc', got {kind!r}")
        self.garble_kind = kind
        self.garble_left = int(n_frames)

    def disconnect(self) -> None:
        """Drop the client's TCP connection (like pulling the USB cable)."""
        self._adapter.drop_client()

    def inject(self, raw: bytes) -> bool:
        """Send ``raw`` bytes to the client as they are (line noise); False if no client."""
        conn = self._adapter._client
        return conn is not None and self._adapter._send(conn, raw)

    def throttle(self, frames_per_s: float | None) -> None:
        """Pass at most ``frames_per_s`` frames a second to the client (None: no limit): a
        PC that reads the bus slower than it fills, so that the frames wait in a growing
        queue and reach the program late, in order (a starved receive thread)."""
        if frames_per_s is not None and not frames_per_s > 0:
            raise ValueError(f"frames_per_s must be > 0 or None, got {frames_per_s}")
        self.frames_per_s = frames_per_s

    def unplug(self, on: bool = True) -> None:
        """Disconnect the CAN side: no frames pass in either direction."""
        self.unplugged = on

    def apply(self, line: bytes) -> bytes:
        if self.garble_left <= 0:
            return line
        self.garble_left -= 1
        if self.garble_kind == "bad_hex":
            return line[:1] + b"XYZ" + line[4:]
        head = 9 if line[:1] in (b"T", b"R") else 4
        dlc = line[head] - 0x30
        return line[:head] + bytes([0x30 + max(0, dlc - 1)]) + line[head + 1 :]


class SlcanAdapter(RunsWhileEntered):
    """The adapter as a TCP server on 127.0.0.1 (one client at a time, like a tty).

    ``start()`` returns the pyserial URL ``socket://127.0.0.1:PORT``; ``stop()`` closes
    everything. Safe to start/stop from any thread.
    """

    def __init__(
        self,
        channel: str = "rig-encoders",
        host: str = "127.0.0.1",
        port: int = 0,
        serial_number: str = "SIM1",
    ) -> None:
        self.channel = channel
        self.host = host
        self.port = port
        self.serial_number = serial_number
        self.backdoor = SlcanBackdoor(self)
        self.frames_to_client = 0
        self.frames_from_client = 0
        self._bus: can.BusABC | None = None
        self._server: socket.socket | None = None
        self._client: socket.socket | None = None
        self._session: SlcanSession | None = None
        self._send_lock = threading.Lock()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._t0 = time.monotonic()

    @property
    def address(self) -> str:
        return f"socket://{self.host}:{self.port}"

    def start(self) -> str:
        # the frames keep the kernel's receive time (a node samples on SYNC at that time)
        self._bus = virtual_bus(self.channel, preserve_timestamps=True)
        server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        server.bind((self.host, self.port))
        server.listen(1)
        server.settimeout(0.2)
        self.port = server.getsockname()[1]
        self._server = server
        self._stop.clear()
        for target, name in ((self._accept_loop, "accept"), (self._bus_to_client, "bus->tcp")):
            thread = threading.Thread(target=target, name=f"slcan {name}", daemon=True)
            thread.start()
            self._threads.append(thread)
        return self.address

    def stop(self) -> None:
        self._stop.set()
        self.drop_client()
        for thread in self._threads:
            thread.join(timeout=2.0)
        self._threads.clear()
        if self._server is not None:
            self._server.close()
            self._server = None
        if self._bus is not None:
            self._bus.shutdown()
            self._bus = None

    def drop_client(self) -> None:
        with self._send_lock:
            client, self._client, self._session = self._client, None, None
        if client is not None:
            with contextlib.suppress(OSError):
                client.shutdown(socket.SHUT_RDWR)
            client.close()

    def _accept_loop(self) -> None:
        assert self._server is not None
        while not self._stop.is_set():
            try:
                conn, _ = self._server.accept()
            except (TimeoutError, OSError):
                continue
            if self._client is not None:  # the port is busy, as a tty would be
                conn.close()
                continue
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            session = SlcanSession(serial_number=self.serial_number)
            with self._send_lock:
                self._client, self._session = conn, session
            thread = threading.Thread(
                target=self._client_loop, args=(conn, session), name="slcan tcp->bus", daemon=True
            )
            thread.start()

    def _client_loop(self, conn: socket.socket, session: SlcanSession) -> None:
        conn.settimeout(0.2)
        kernel_stamps = _receive_timestamps(conn)
        while not self._stop.is_set() and self._client is conn:
            try:
                data, received = _recv_stamped(conn, kernel_stamps)
            except TimeoutError:
                continue
            except OSError:
                break
            if not data:
                break
            replies, frames = session.feed(data)
            for frame in frames:
                frame.timestamp = received
            if replies and not self._send(conn, replies):
                break
            bus = self._bus
            if bus is None or self.backdoor.unplugged:
                continue
            for frame in frames:
                bus.send(frame)
                self.frames_from_client += 1
        if self._client is conn:
            self.drop_client()

    def _send(self, conn: socket.socket, data: bytes) -> bool:
        with self._send_lock:
            if self._client is not conn:
                return False
            try:
                conn.sendall(data)
            except OSError:
                return False
        return True

    def _bus_to_client(self) -> None:
        while not self._stop.is_set():
            bus = self._bus
            if bus is None:
                return
            msg = bus.recv(0.1)
            session, conn = self._session, self._client
            if msg is None or session is None or conn is None or not session.is_open:
                continue
            if self.backdoor.unplugged:
                continue
            stamp = int((time.monotonic() - self._t0) * 1000) if session.timestamps else None
            line = self.backdoor.apply(format_frame(msg, stamp))
            if self._send(conn, line):
                self.frames_to_client += 1
            rate = self.backdoor.frames_per_s
            if rate is not None:
                self._stop.wait(1.0 / rate)


SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)  # Linux's value
RECV_CHUNK = 32
"""Bytes read at a time from the client: a few frames (a SYNC is 6 bytes), so that each
frame's receive time is that of the bytes around it, not of a long backlog's end."""


def _receive_timestamps(conn: socket.socket) -> bool:
    """Ask the kernel to stamp received bytes (Linux ``SO_TIMESTAMPNS``); False where it
    cannot (the read's own time is used then)."""
    try:
        conn.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    except OSError:
        return False
    return True


def _recv_stamped(conn: socket.socket, kernel: bool) -> tuple[bytes, float]:
    """Up to :data:`RECV_CHUNK` bytes and the time (s, ``time.time()`` scale) they reached
    this host: the kernel's stamp when there is one, else now. A starved simulator thread
    reads late; the stamp is when the bytes came, as a bus device would see them."""
    if not kernel:
        return conn.recv(RECV_CHUNK), time.time()
    data, ancillary, _, _ = conn.recvmsg(RECV_CHUNK, socket.CMSG_SPACE(16))
    for level, kind, payload in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(payload) >= 16:
            seconds, nanoseconds = struct.unpack("qq", payload[:16])
            return data, seconds + nanoseconds * 1e-9
    return data, time.time()
