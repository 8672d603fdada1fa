"""Driver for the serial ASCII torque transducer (protocol: ``docs/transducer-protocol.md``).

Works over any pyserial URL: a tty or pty path (``/dev/ttyUSB0``, ``/dev/pts/7``),
``socket://host:port`` or ``rfc2217://host:port``. Every failure is one of the project's
device errors (``drivers/errors.py``) naming the transducer, what the driver waited for and
what came; readings beyond the configured range raise :class:`DeviceOutOfRange`.

Example::

    cfg = TransducerConfig(url="/dev/pts/7", full_scale_Nm=20.0)
    with SerialTorqueTransducer(cfg) as tt:
        print(tt.identity(), tt.read().torque_Nm)
        tt.start_stream(500)
        for reading in tt.readings(1000):
            ...
        print(tt.stop_stream().lost)
"""

from __future__ import annotations

import contextlib
import select
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Literal

import serial
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from drivers.errors import (
    DeviceDisconnected,
    DeviceError,
    DeviceFault,
    DeviceOutOfRange,
    DeviceProtocolError,
    DeviceTimeout,
)
from drivers.lifecycle import OpenedOnEnter
from drivers.transducer.protocol import (
    MAX_LINE_BYTES,
    SEQ_MODULO,
    STATUS_OK,
    STATUS_OVERLOAD,
    DeviceLine,
    ErrorReply,
    Measurement,
    Reply,
    max_stream_rate_Hz,
    parse_line,
    parse_quantity,
)

TERMINATOR_NAMES = {"CRLF": "\r\n", "CR": "\r", "LF": "\n"}
POLL_S = 0.02  # read poll of ports that cannot be select()ed (rfc2217://)


class TransducerConfig(BaseModel):
    """Settings of one transducer, e.g. a ``[devices.transducer]`` TOML table.

    ``url`` any pyserial URL; ``baudrate`` in Bd (8N1); ``timeout_s`` the longest wait for a
    reply (s); ``terminator`` of device lines (``"\\r\\n"``, ``"\\r"``, ``"\\n"`` or the
    names CRLF/CR/LF); ``stream_rate_Hz`` the default stream rate; ``full_scale_Nm`` the
    transducer's range (N*m), which the device must report and no reading may exceed.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    url: str = Field(min_length=1)
    name: str = "torque transducer"
    baudrate: int = Field(default=460800, gt=0)
    timeout_s: float = Field(default=0.5, gt=0.0, le=60.0)
    terminator: Literal["\r\n", "\r", "\n"] = "\r\n"
    stream_rate_Hz: float = Field(default=500.0, ge=1.0)
    full_scale_Nm: float = Field(default=20.0, gt=0.0)

    @field_validator("terminator", mode="before")
    @classmethod
    def _terminator_by_name(cls, value: object) -> object:
        return TERMINATOR_NAMES.get(value, value) if isinstance(value, str) else value

    @model_validator(mode="after")
    def _rate_fits_the_line(self) -> TransducerConfig:
        limit = self.max_rate_Hz
        if self.stream_rate_Hz > limit:
            raise ValueError(
                f"stream_rate_Hz {self.stream_rate_Hz:g} exceeds {limit:g} Hz, the most "
                f"{self.baudrate} Bd carries for a {self.full_scale_Nm:g} N*m transducer"
            )
        return self

    @property
    def max_rate_Hz(self) -> float:
        """Fastest stream rate (Hz) the serial line carries at this baud rate."""
        return max_stream_rate_Hz(self.baudrate, self.full_scale_Nm, "Nm", self.terminator)


@dataclass(frozen=True)
class TorqueReading:
    """One torque sample.

    ``t_s``: host time.monotonic() (s) when the sample came (for a query: the midpoint
    between command and reply); ``torque_Nm``: tared torque (N*m); ``seq``: the device's
    sample counter (mod 1e6); ``device_t_s``: the device clock (s); ``status``: OK/OV.
    """

    t_s: float
    torque_Nm: float
    seq: int
    device_t_s: float
    status: str = STATUS_OK


@dataclass(frozen=True)
class TransducerIdentity:
    """The fields of the ``*IDN?`` reply."""

    manufacturer: str
    model: str
    serial: str
    firmware: str


@dataclass
class StreamStats:
    """Counts of the present (or last) stream: samples received, lost (sequence gaps),
    lines that could not be parsed, and the rate asked for (Hz)."""

    rate_Hz: float = 0.0
    received: int = 0
    lost: int = 0
    bad_lines: int = 0


@dataclass(frozen=True)
class TransducerHealth:
    """Result of :meth:`SerialTorqueTransducer.health`: never raises, says what is wrong."""

    ok: bool
    detail: str
    temperature_C: float | None = None
    overruns: int | None = None
    streaming: bool = False


class SerialTorqueTransducer(OpenedOnEnter):
    """The transducer behind a narrow interface: read, stream, tare, health, close.

    Not thread-safe: use one instance from one thread (or guard it with a lock).
    """

    def __init__(self, config: TransducerConfig) -> None:
        self.config = config
        self.device = f"{config.name} at {config.url}"
        self._port: serial.SerialBase | None = None
        self._fileno: int | None = None
        self._buf = bytearray()
        self._chunk_t = 0.0  # host time (s) the last chunk came
        self._split = config.terminator[-1].encode("ascii")
        self._pending: deque[tuple[Measurement, float]] = deque()  # ST lines not yet read
        self._streaming = False
        self._last_stream_seq: int | None = None
        self._last_query_seq: int | None = None
        self.stats = StreamStats()
        self.late_replies = 0
        """Replies of earlier commands that came after their timeout (skipped)."""

    # --- lifecycle ------------------------------------------------------------------------

    def open(self) -> TransducerIdentity:
        """Open the port, stop any stream left running, check identity, unit and range."""
        cfg = self.config
        try:
            port = serial.serial_for_url(cfg.url, baudrate=cfg.baudrate, timeout=0)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DeviceDisconnected(self.device, "a serial port that opens", str(exc)) from exc
        self._port = port
        try:
            self._fileno = port.fileno()
        except (AttributeError, OSError, serial.SerialException):
            self._fileno = None
            port.timeout = POLL_S
        self._buf.clear()
        self._pending.clear()
        self._streaming = False
        self._last_query_seq = self._last_stream_seq = None
        self._resync()
        identity = self.identity()
        unit = self._query("UNIT?", "UNIT")
        if unit.args != "Nm":
            raise DeviceProtocolError(self.device, "'UNIT Nm'", repr(f"UNIT {unit.args}"))
        range_Nm = self.range_Nm()
        if abs(range_Nm - cfg.full_scale_Nm) > 1e-6 * cfg.full_scale_Nm + 1e-3:
            raise DeviceOutOfRange(
                self.device,
                f"a range of {cfg.full_scale_Nm:g} N*m (config full_scale_Nm)",
                f"RANGE {range_Nm:g} Nm",
            )
        return identity

    def close(self) -> None:
        """Stop a running stream (best effort) and close the port (idempotent)."""
        if self._port is None:
            return
        if self._streaming:
            with contextlib.suppress(DeviceError):  # closing anyway: it may be gone
                self.stop_stream()
        self._port.close()
        self._port = None
        self._streaming = False

    # --- queries --------------------------------------------------------------------------

    def identity(self) -> TransducerIdentity:
        """``*IDN?``: manufacturer, model, serial number, firmware."""
        reply = self._query("*IDN?", "IDN")
        fields = reply.args.split(",")
        if len(fields) != 4 or not all(fields):
            raise DeviceProtocolError(
                self.device, "'IDN <maker>,<model>,<serial>,<firmware>'", repr(reply.args)
            )
        return TransducerIdentity(*fields)

    def range_Nm(self) -> float:
        """``RANGE?``: the full scale (N*m)."""
        return parse_quantity(self._query("RANGE?", "RANGE"), "Nm", self.device)

    def temperature_C(self) -> float:
        """``TEMP?``: the housing temperature (deg C)."""
        return parse_quantity(self._query("TEMP?", "TEMP"), "C", self.device)

    def read(self) -> TorqueReading:
        """``TQ?``: one reading; raises DeviceOutOfRange beyond the range, DeviceFault if the
        device repeats its last sample (a stuck measurement)."""
        t_sent = time.monotonic()
        line, t_came = self._transact("TQ?", lambda x: isinstance(x, Measurement)
                                      and x.tag == "TQ")
        if not (isinstance(line, Measurement) and line.tag == "TQ"):
            raise DeviceProtocolError(self.device, "a 'TQ ...' reply to 'TQ?'", repr(line))
        if line.seq == self._last_query_seq:
            raise DeviceFault(
                self.device,
                f"a new sample after TQ seq {line.seq:06d}",
                f"seq {line.seq:06d} again (stale data: the measurement is stuck)",
            )
        self._last_query_seq = line.seq
        return self._checked(line, 0.5 * (t_sent + t_came))

    def tare(self) -> float:
        """``TARE``: zero the present torque; returns the stored tare offset (N*m).

        The device refuses while streaming (ERR 4) or beyond 10 % of the range (ERR 6);
        both raise DeviceFault.
        """
        self._expect_ok("TARE")
        return parse_quantity(self._query("TARE?", "TARE"), "Nm", self.device)

    def clear_tare(self) -> None:
        """``TARE CLR``: forget the tare offset."""
        self._expect_ok("TARE CLR")

    def health(self) -> TransducerHealth:
        """``STAT?`` and ``TEMP?``; a device error becomes ``ok=False`` with its message."""
        try:
            parts = self._query("STAT?", "STAT").args.split(" ")
            if len(parts) != 2 or not parts[1].isdigit():
                raise DeviceProtocolError(self.device, "'STAT <OK|OV> <overruns>'", repr(parts))
            temperature = self.temperature_C()
        except DeviceError as exc:
            return TransducerHealth(ok=False, detail=str(exc), streaming=self._streaming)
        state, overruns = parts[0], int(parts[1])
        detail = "ok" if state == STATUS_OK else "overload: torque beyond the range"
        return TransducerHealth(
            ok=state == STATUS_OK,
            detail=detail,
            temperature_C=temperature,
            overruns=overruns,
            streaming=self._streaming,
        )

    # --- streaming ------------------------------------------------------------------------

    @property
    def streaming(self) -> bool:
        return self._streaming

    def start_stream(self, rate_Hz: float | None = None) -> None:
        """``STREAM <rate>``: the device sends samples at ``rate_Hz`` (Hz) until stopped."""
        rate = float(rate_Hz if rate_Hz is not None else self.config.stream_rate_Hz)
        limit = self.config.max_rate_Hz
        if not 1.0 <= rate <= limit:
            raise DeviceOutOfRange(
                self.device,
                f"a stream rate in [1, {limit:g}] Hz at {self.config.baudrate} Bd",
                f"{rate:g} Hz",
            )
        self._expect_ok(f"STREAM {rate:g}")
        self._streaming = True
        self._last_stream_seq = None
        self.stats = StreamStats(rate_Hz=rate)

    def next_reading(self, timeout_s: float | None = None) -> TorqueReading:
        """The next streamed sample, waiting at most ``timeout_s`` (default: the config's
        timeout, at least 3 sample periods).

        Lost samples (sequence gaps) are counted in :attr:`stats`. A garbled line raises
        DeviceProtocolError and is counted; the stream stays usable, the next call goes on.
        """
        if self._pending:
            line, t_came = self._pending.popleft()
            return self._accept_sample(line, t_came)
        if not self._streaming:
            raise RuntimeError(f"{self.device}: no stream running (call start_stream())")
        wait = timeout_s if timeout_s is not None else self.config.timeout_s
        wait = max(wait, 3.0 / self.stats.rate_Hz)
        expected = f"a stream sample at {self.stats.rate_Hz:g} Hz within {wait:g} s"
        raw, t_came = self._read_line(time.monotonic() + wait, expected)
        try:
            line = parse_line(raw, self.device)
        except DeviceProtocolError:
            self.stats.bad_lines += 1
            raise
        if isinstance(line, ErrorReply):
            raise DeviceFault(self.device, "a stream sample", f"'ERR {line.code} {line.text}'")
        if not (isinstance(line, Measurement) and line.tag == "ST"):
            self.stats.bad_lines += 1
            raise DeviceProtocolError(self.device, "a stream sample ('ST ...')", repr(raw))
        return self._accept_sample(line, t_came)

    def readings(self, count: int | None = None) -> Iterator[TorqueReading]:
        """Iterate over ``count`` streamed samples (forever if None)."""
        taken = 0
        while count is None or taken < count:
            yield self.next_reading()
            taken += 1

    def stop_stream(self) -> StreamStats:
        """``STOP``; samples that came before the device's OK stay readable by
        :meth:`next_reading`. Returns the stream's counts."""
        if not self._streaming:
            return self.stats
        self._write("STOP")
        try:
            for raw, line, t_came in self._lines_within_timeout(
                f"'OK' to 'STOP' within {self.config.timeout_s:g} s"
            ):
                if line is None:
                    self.stats.bad_lines += 1
                elif isinstance(line, Measurement) and line.tag == "ST":
                    self._pending.append((line, t_came))
                elif isinstance(line, Reply) and line.keyword == "OK":
                    break
                else:
                    raise DeviceProtocolError(self.device, "'OK' to 'STOP'", repr(raw))
        finally:
            self._streaming = False
        return self.stats

    # --- internals ------------------------------------------------------------------------

    def _accept_sample(self, line: Measurement, t_came: float) -> TorqueReading:
        last = self._last_stream_seq
        if last is not None:
            if line.seq == last:
                raise DeviceFault(
                    self.device,
                    f"a new sample after seq {last:06d}",
                    f"seq {line.seq:06d} again (stale data: the measurement is stuck)",
                )
            self.stats.lost += (line.seq - last - 1) % SEQ_MODULO
        self._last_stream_seq = line.seq
        self.stats.received += 1
        return self._checked(line, t_came)

    def _checked(self, line: Measurement, t_s: float) -> TorqueReading:
        """The reading, or DeviceOutOfRange when it lies beyond the range."""
        fs = self.config.full_scale_Nm
        if line.status == STATUS_OVERLOAD or abs(line.torque_Nm) > fs:
            raise DeviceOutOfRange(
                self.device,
                f"|torque| <= {fs:g} N*m (the range)",
                f"{line.torque_Nm:+.5f} N*m, status {line.status}, seq {line.seq:06d}",
            )
        return TorqueReading(t_s, line.torque_Nm, line.seq, line.device_t_s, line.status)

    def _query(self, command: str, keyword: str) -> Reply:
        line, _ = self._transact(command, lambda x: isinstance(x, Reply) and x.keyword == keyword)
        if not (isinstance(line, Reply) and line.keyword == keyword):
            raise DeviceProtocolError(
                self.device, f"a '{keyword} ...' reply to {command!r}", repr(line)
            )
        return line

    def _expect_ok(self, command: str) -> None:
        line, _ = self._transact(command, lambda x: isinstance(x, Reply) and x.keyword == "OK")
        if not (isinstance(line, Reply) and line.keyword == "OK"):
            raise DeviceProtocolError(self.device, f"'OK' to {command!r}", repr(line))

    def _transact(self, command: str, wanted: Callable[[DeviceLine], bool] | None = None
                  ) -> tuple[DeviceLine, float]:
        """Send ``command``, return its reply and the host time it came (stream samples
        that come meanwhile are kept for next_reading).

        ``wanted`` tells this command's reply: another reply that comes first is the late
        answer of an earlier command that timed out (a busy PC or a slow line), counted in
        :attr:`late_replies` and skipped. Stale input is discarded before the command is
        sent, but a late reply still on its way then came after it, and was taken for this
        command's (seen under load: "expected a 'TQ ...' reply to 'TQ?', got TEMP")."""
        if not self._streaming:
            self._discard_stale_input()
        self._write(command)
        timeout = self.config.timeout_s
        deadline = time.monotonic() + timeout
        while True:
            raw, t_came = self._read_line(deadline, f"a reply to {command!r} within {timeout:g} s")
            line = parse_line(raw, self.device)
            if isinstance(line, Measurement) and line.tag == "ST":
                self._pending.append((line, t_came))
                continue
            if isinstance(line, ErrorReply):
                raise DeviceFault(
                    self.device, f"a reply to {command!r}", f"'ERR {line.code} {line.text}'"
                )
            if wanted is not None and not wanted(line):
                self.late_replies += 1
                continue
            return line, t_came

    def _resync(self) -> None:
        """On open: stop a stream a previous session left running, skip stale lines."""
        self._discard_stale_input()
        self._write("STOP")
        for _, line, _ in self._lines_within_timeout(
            f"'OK' to 'STOP' (sent on open) within {self.config.timeout_s:g} s"
        ):
            # None: a partial line left over from before we opened
            if isinstance(line, ErrorReply):
                raise DeviceFault(
                    self.device, "'OK' to 'STOP' (sent on open)", f"'ERR {line.code} {line.text}'"
                )
            if isinstance(line, Reply) and line.keyword == "OK":
                return

    def _lines_within_timeout(
        self, expected: str
    ) -> Iterator[tuple[bytes, DeviceLine | None, float]]:
        """The lines that come within ``config.timeout_s`` from now (then DeviceTimeout naming
        ``expected``): each raw, parsed (None: not a line of the protocol) and the host time
        it came."""
        deadline = time.monotonic() + self.config.timeout_s
        while True:
            raw, t_came = self._read_line(deadline, expected)
            try:
                line = parse_line(raw, self.device)
            except DeviceProtocolError:
                line = None
            yield raw, line, t_came

    def _port_or_raise(self) -> serial.SerialBase:
        if self._port is None:
            raise DeviceDisconnected(self.device, "an open port (call open())", "a closed port")
        return self._port

    def _write(self, command: str) -> None:
        port = self._port_or_raise()
        data = (command + self.config.terminator).encode("ascii")
        try:
            port.write(data)
        except (serial.SerialException, OSError) as exc:
            raise DeviceDisconnected(
                self.device, f"to send {command!r}", f"link lost: {exc}"
            ) from exc

    def _discard_stale_input(self) -> None:
        """Drop unparsed input that came unasked (late replies of an earlier timeout)."""
        self._buf.clear()
        while self._read_chunk(0.0):
            pass

    def _read_chunk(self, wait_s: float) -> bytes:
        """What the port has within ``wait_s`` (s); b"" if nothing came."""
        port = self._port_or_raise()
        try:
            if self._fileno is not None:
                ready, _, _ = select.select([self._fileno], [], [], max(0.0, wait_s))
                return port.read(65536) if ready else b""
            data = port.read(1)
            waiting = port.in_waiting if data else 0
            return data + port.read(waiting) if waiting else data
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DeviceDisconnected(self.device, "an open serial link", str(exc)) from exc

    def _read_line(self, deadline: float, expected: str) -> tuple[bytes, float]:
        """One raw line (terminator included) and the host time (s) the chunk holding its
        end came; raises DeviceTimeout naming ``expected`` when ``deadline`` passes."""
        while True:
            cut = self._buf.find(self._split)
            if cut >= 0:
                raw = bytes(self._buf[: cut + 1])
                del self._buf[: cut + 1]
                if raw.strip(b"\r\n"):
                    return raw, self._chunk_t
                continue  # the LF of a CR LF split on CR, or an empty line
            if len(self._buf) > MAX_LINE_BYTES:
                raw = bytes(self._buf)
                self._buf.clear()
                raise DeviceProtocolError(
                    self.device,
                    f"a line ended by {self.config.terminator!r} within {MAX_LINE_BYTES} bytes",
                    repr(raw),
                )
            left = deadline - time.monotonic()
            if left <= 0:
                partial = f"partial line {bytes(self._buf)!r}" if self._buf else "nothing"
                raise DeviceTimeout(self.device, expected, partial)
            chunk = self._read_chunk(left)
            if chunk:
                self._chunk_t = time.monotonic()
                self._buf += chunk
