"""Simulated serial torque transducer: device model, protocol face (pty or TCP), backdoor.

Three parts kept apart, as in lewis:

- :class:`TransducerDevice`, the device model: answers command lines and takes samples
  from a :class:`~simulators.plant.api.Plant`; no I/O;
- :class:`TransducerSimulator`, the protocol face: serves the device's ASCII line protocol
  (``docs/transducer-protocol.md``) on a pseudo-terminal (the driver opens the slave path,
  e.g. ``/dev/pts/7``) or on a TCP port on 127.0.0.1 (pyserial URL ``socket://...``);
- :class:`TransducerBackdoor`, fault injection: silence, delay, garbled lines, error
  replies, a stuck (stale) measurement, dropped samples and disconnect.

Stand-alone: ``python -m simulators.transducer [--transport pty|tcp]`` prints
``{"transducer": "<address>", ...}`` on its first stdout line and serves until killed.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import random
import select
import signal
import socket
import threading
import time
import tty
from collections import deque
from dataclasses import dataclass
from typing import Literal

from drivers.lifecycle import RunsWhileEntered
from drivers.transducer.protocol import (
    ERROR_TEXT,
    MAX_COMMAND_CHARS,
    SEQ_MODULO,
    STATUS_OK,
    STATUS_OVERLOAD,
    format_measurement,
    frame_line,
    max_stream_rate_Hz,
)
from simulators.modbus.plant_backdoor import SineTestPlant
from simulators.plant.api import Plant

Transport = Literal["pty", "tcp"]

DEFAULT_IDENTITY = "RIGSIM,TT-20,SN000001,FW1.0"
TARE_LIMIT_FRACTION = 0.10  # TARE is refused when |torque| exceeds 10 % of the range
OUTPUT_BUFFER_BYTES = 32768  # the device's UART buffer; stream lines beyond it are dropped
CATCH_UP_S = 0.5  # the device sends what it owes for up to 0.5 s of stall in one burst
DEFAULT_RATE_HZ = 100.0


@dataclass
class SineTorqueSource(SineTestPlant):
    """A transducer on a calibration bench: the closed-form plant of
    :class:`~simulators.modbus.plant_backdoor.SineTestPlant` with a 5 N*m, 0.5 Hz sine at 22 deg C.

    Drive disabled: ``torque = offset_Nm + amplitude_Nm * sin(2 pi frequency_Hz t)`` (N*m);
    drive enabled: the commanded torque plus ``offset_Nm`` (an ideal drive).
    """

    amplitude_Nm: float = 5.0
    temperature_C: float = 22.0


class TransducerBackdoor:
    """Fault injection for the simulated transducer (thread-safe, takes effect at once).

    Each fault stays until cleared (``clear()`` or calling the method with ``False``/0).
    """

    def __init__(self, seed: int = 0) -> None:
        self._lock = threading.Lock()
        self._rng = random.Random(seed)
        self._disconnect = threading.Event()
        self.clear()

    def clear(self) -> None:
        """Remove every fault (a pending disconnect is not undone)."""
        with self._lock:
            self.silent = False
            self.delay_s = 0.0
            self.garble_probability = 0.0
            self.error: tuple[int, str] | None = None
            self.stuck_on = False
            self.drop_count = 0
            self.noise = bytearray()

    def silence(self, on: bool = True) -> None:
        """The device reads but neither answers nor streams (a dead UART or cable)."""
        with self._lock:
            self.silent = on

    def delay(self, seconds: float) -> None:
        """Every line leaves the device ``seconds`` (s) late."""
        if not seconds >= 0.0:
            raise ValueError(f"delay must be >= 0 s, got {seconds}")
        with self._lock:
            self.delay_s = float(seconds)

    def garble(self, probability: float = 1.0) -> None:
        """Corrupt one byte of each line the device sends, with ``probability`` (0..1)."""
        if not 0.0 <= probability <= 1.0:
            raise ValueError(f"probability must be in [0, 1], got {probability}")
        with self._lock:
            self.garble_probability = float(probability)

    def error_replies(self, code: int | None = 7, text: str | None = None) -> None:
        """Answer every command with ``ERR <code> <text>``; ``code=None`` stops it."""
        with self._lock:
            self.error = None if code is None else (code, text or ERROR_TEXT.get(code, "fault"))

    def stuck(self, on: bool = True) -> None:
        """Freeze the measurement: the device repeats its last sample (seq, time, value)."""
        with self._lock:
            self.stuck_on = on

    def drop_next(self, count: int) -> None:
        """Lose the next ``count`` streamed lines on the wire (lost samples)."""
        with self._lock:
            self.drop_count = int(count)

    def inject(self, data: bytes) -> None:
        """Send raw ``data`` (line noise, any bytes) just before the device's next line."""
        with self._lock:
            self.noise += data

    def disconnect(self) -> None:
        """Drop the link: TCP closes the client's connection; a pty is torn down for good."""
        self._disconnect.set()

    # --- used by the face ---------------------------------------------------------------

    def take_noise(self) -> bytes:
        with self._lock:
            data = bytes(self.noise)
            self.noise.clear()
            return data

    def take_drop(self) -> bool:
        with self._lock:
            if self.drop_count > 0:
                self.drop_count -= 1
                return True
            return False

    def maybe_garble(self, line: bytes) -> bytes:
        """``line`` (terminator included) with one byte changed, or unchanged."""
        with self._lock:
            if self.garble_probability <= 0.0 or self._rng.random() >= self.garble_probability:
                return line
            end = len(line.rstrip(b"\r\n"))
            pos = self._rng.randrange(end)
            while True:  # any change but CR/LF, so one garbled line stays one line
                new = line[pos] ^ self._rng.randrange(1, 256)
                if new not in (0x0A, 0x0D):
                    break
        return line[:pos] + bytes([new]) + line[pos + 1 :]

    def take_disconnect(self) -> bool:
        if self._disconnect.is_set():
            self._disconnect.clear()
            return True
        return False


class TransducerDevice:
    """The transducer's behaviour: command lines in, reply bodies (no checksum) out.

    ``full_scale_Nm`` is the range (N*m); ``baudrate`` bounds the stream rate as on a real
    UART (see :func:`drivers.transducer.protocol.max_stream_rate_Hz`). Not thread-safe:
    the face calls it from its one serving thread.
    """

    def __init__(
        self,
        plant: Plant,
        backdoor: TransducerBackdoor,
        full_scale_Nm: float = 20.0,
        baudrate: int = 460800,
        identity: str = DEFAULT_IDENTITY,
        terminator: str = "\r\n",
    ) -> None:
        self.plant = plant
        self.backdoor = backdoor
        self.full_scale_Nm = float(full_scale_Nm)
        self.identity = identity
        self.max_rate_Hz = max_stream_rate_Hz(baudrate, full_scale_Nm, "Nm", terminator)
        self.overruns = 0
        self._table = self._commands()
        self.reset()

    def reset(self) -> None:
        """Power-on state (``*RST``): not streaming, no tare, counters at 0."""
        self.tare_Nm = 0.0
        self.rate_Hz = min(DEFAULT_RATE_HZ, self.max_rate_Hz)
        self.streaming = False
        self.stream_seq = 0
        self.query_seq = 0
        self.next_due_s = 0.0
        self.last_body: dict[str, str] = {}

    # --- commands -------------------------------------------------------------------------

    def handle(self, line: str, now_s: float) -> list[str]:
        """Reply bodies for one command line; ``now_s`` is the face's monotonic time (s)."""
        text = " ".join(line.strip().upper().split())
        if not text:
            return []
        if len(line) > MAX_COMMAND_CHARS:
            return [_err(1)]
        error = self.backdoor.error
        if error is not None:
            return [f"ERR {error[0]} {error[1]}"]
        name, _, arg = text.partition(" ")
        handler = self._table.get(name)
        if handler is None:
            return [_err(3)]
        return [handler(arg, now_s)]

    def _commands(self):
        return {
            "*IDN?": self._no_arg(lambda: f"IDN {self.identity}"),
            "*RST": self._no_arg(self._reset_ok),
            "TQ?": self._no_arg(self._query),
            "TEMP?": self._no_arg(lambda: f"TEMP {self.plant.snapshot().temperature_C:+.2f} C"),
            "RANGE?": self._no_arg(lambda: f"RANGE {self.full_scale_Nm:.3f} Nm"),
            "UNIT?": self._no_arg(lambda: "UNIT Nm"),
            "RATE?": self._no_arg(lambda: f"RATE {self.rate_Hz:g}"),
            "STAT?": self._no_arg(self._status),
            "TARE?": self._no_arg(lambda: f"TARE {self.tare_Nm:+.5f} Nm"),
            "TARE": self._tare,
            "STREAM": self._stream,
            "STOP": self._no_arg(self._stop),
        }

    @staticmethod
    def _no_arg(reply):
        return lambda arg, now_s: _err(2) if arg else reply()

    def _reset_ok(self) -> str:
        self.reset()
        return "OK"

    def _stop(self) -> str:
        self.streaming = False
        return "OK"

    def _status(self) -> str:
        raw = self.plant.snapshot().torque_Nm
        state = STATUS_OVERLOAD if abs(raw) > self.full_scale_Nm else STATUS_OK
        return f"STAT {state} {self.overruns}"

    def _tare(self, arg: str, now_s: float) -> str:
        if self.streaming:
            return _err(4)
        if arg == "CLR":
            self.tare_Nm = 0.0
            return "OK"
        if arg:
            return _err(2)
        raw = self.plant.snapshot().torque_Nm
        if abs(raw) > TARE_LIMIT_FRACTION * self.full_scale_Nm:
            return _err(6)
        self.tare_Nm = raw
        return "OK"

    def _stream(self, arg: str, now_s: float) -> str:
        if self.streaming:
            return _err(4)
        if arg:
            try:
                rate = float(arg)
            except ValueError:
                return _err(2)
            if not (math.isfinite(rate) and 1.0 <= rate <= self.max_rate_Hz):
                return _err(5)
            self.rate_Hz = rate
        self.streaming = True
        self.stream_seq = 0
        self.next_due_s = now_s
        return "OK"

    def _query(self) -> str:
        body = self._measure("TQ", self.query_seq)
        self.query_seq = (self.query_seq + 1) % SEQ_MODULO
        return body

    def _measure(self, tag: str, seq: int) -> str:
        if self.backdoor.stuck_on and tag in self.last_body:
            return self.last_body[tag]
        snap = self.plant.snapshot()
        status = STATUS_OVERLOAD if abs(snap.torque_Nm) > self.full_scale_Nm else STATUS_OK
        torque = snap.torque_Nm - self.tare_Nm
        body = format_measurement(tag, seq, snap.t_s, torque, "Nm", status)
        self.last_body[tag] = body
        return body

    # --- streaming ------------------------------------------------------------------------

    def next_due(self) -> float | None:
        """Monotonic time (s) of the next streamed sample, or None when not streaming."""
        return self.next_due_s if self.streaming else None

    def due_samples(self, now_s: float) -> list[str]:
        """Bodies of the stream samples due by ``now_s`` (monotonic s).

        A stalled serving thread owes samples: up to ``CATCH_UP_S`` worth (at least 50) go
        out in one burst; beyond that they are skipped but counted (sequence gap and
        ``overruns``), as a real device would.
        """
        bodies: list[str] = []
        if not self.streaming:
            return bodies
        period = 1.0 / self.rate_Hz
        burst = max(50, int(CATCH_UP_S * self.rate_Hz))
        while self.next_due_s <= now_s and len(bodies) < burst:
            bodies.append(self._measure("ST", self.stream_seq))
            self.stream_seq = (self.stream_seq + 1) % SEQ_MODULO
            self.next_due_s += period
        if self.next_due_s <= now_s:
            skipped = int((now_s - self.next_due_s) / period) + 1
            self.stream_seq = (self.stream_seq + skipped) % SEQ_MODULO
            self.overruns += skipped
            self.next_due_s += skipped * period
        return bodies


def _err(code: int) -> str:
    return f"ERR {code} {ERROR_TEXT[code]}"


class _Link:
    """One byte link to the driver: a pty master fd or a connected TCP socket."""

    def __init__(self, fd: int, sock: socket.socket | None = None) -> None:
        self.fd = fd
        self.sock = sock
        os.set_blocking(fd, False)

    def read(self) -> bytes | None:
        """Bytes that came, None if none yet, b"" when the peer has gone."""
        try:
            data = self.sock.recv(4096) if self.sock else os.read(self.fd, 4096)
        except BlockingIOError:
            return None
        except OSError:
            return b""
        return data

    def write(self, data: bytes) -> int:
        """Bytes written (0 when the peer is not reading); -1 when the peer has gone."""
        try:
            return self.sock.send(data) if self.sock else os.write(self.fd, data)
        except BlockingIOError:
            return 0
        except OSError:
            return -1

    def close(self) -> None:
        if self.sock:
            self.sock.close()
        else:
            os.close(self.fd)


class TransducerSimulator(RunsWhileEntered):
    """The transducer face: serves the protocol on a pty or a 127.0.0.1 TCP port.

    ``start()`` returns the address the driver opens (a pty path such as ``/dev/pts/7``
    or ``socket://127.0.0.1:PORT``); ``stop()`` ends serving. Both may be called from any
    thread (from asyncio: ``await asyncio.to_thread(sim.start)``). One serving thread
    handles commands, streaming and the backdoor's faults.
    """

    def __init__(
        self,
        plant: Plant,
        transport: Transport = "pty",
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        full_scale_Nm: float = 20.0,
        baudrate: int = 460800,
        terminator: str = "\r\n",
        identity: str = DEFAULT_IDENTITY,
        seed: int = 0,
    ) -> None:
        if transport not in ("pty", "tcp"):
            raise ValueError(f"transport must be 'pty' or 'tcp', got {transport!r}")
        self.transport = transport
        self.host, self.port = host, port
        self.terminator = terminator
        self.backdoor = TransducerBackdoor(seed)
        self.device = TransducerDevice(
            plant, self.backdoor, full_scale_Nm, baudrate, identity, terminator
        )
        self.address: str | None = None
        self._stop = threading.Event()
        self._wake_r, self._wake_w = -1, -1
        self._thread: threading.Thread | None = None
        self._listener: socket.socket | None = None
        self._pty_slave = -1
        self._pty_master = -1

    # --- lifecycle ------------------------------------------------------------------------

    def start(self) -> str:
        """Open the pty or listening socket, start serving, return the address."""
        if self._thread is not None:
            raise RuntimeError("transducer simulator already started")
        self._stop.clear()
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)
        if self.transport == "pty":
            self._pty_master, self._pty_slave = os.openpty()
            tty.setraw(self._pty_slave)
            self.address = os.ttyname(self._pty_slave)
            target = self._serve_pty
        else:
            self._listener = socket.create_server((self.host, self.port))
            self._listener.setblocking(False)
            host, port = self._listener.getsockname()[:2]
            self.address = f"socket://{host}:{port}"
            target = self._serve_tcp
        self._thread = threading.Thread(target=target, name="transducer-sim", daemon=True)
        self._thread.start()
        return self.address

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop serving and release the pty/socket (idempotent)."""
        if self._thread is None:
            return
        self._stop.set()
        self._wake()
        self._thread.join(timeout_s)
        self._thread = None
        for fd in (self._wake_r, self._wake_w, self._pty_slave):
            if fd >= 0:
                os.close(fd)
        self._wake_r = self._wake_w = self._pty_slave = -1
        if self._listener is not None:
            self._listener.close()
            self._listener = None

    def _wake(self) -> None:
        if self._wake_w >= 0:
            with contextlib.suppress(BlockingIOError):
                os.write(self._wake_w, b"x")

    def disconnect(self) -> None:
        """Same as ``backdoor.disconnect()``, waking the serving thread at once."""
        self.backdoor.disconnect()
        self._wake()

    # --- serving --------------------------------------------------------------------------

    def _serve_pty(self) -> None:
        link = _Link(self._pty_master)
        self._serve(link)
        link.close()  # after a disconnect or stop the pty is gone: readers get EIO
        self._pty_master = -1

    def _serve_tcp(self) -> None:
        assert self._listener is not None
        while not self._stop.is_set():
            ready, _, _ = select.select([self._listener, self._wake_r], [], [], 0.5)
            self._drain_wake()
            if self._listener not in ready:
                self.backdoor.take_disconnect()  # nobody to disconnect
                continue
            try:
                conn, _ = self._listener.accept()
            except BlockingIOError:
                continue
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            link = _Link(conn.fileno(), conn)
            self._serve(link)
            link.close()

    def _drain_wake(self) -> None:
        try:
            while os.read(self._wake_r, 512):
                pass
        except BlockingIOError:
            pass

    def _serve(self, link: _Link) -> None:
        """Serve one connection until stop, disconnect or the peer going away."""
        inbuf = bytearray()
        outbuf = bytearray()
        pending: deque[tuple[float, bytes, bool]] = deque()  # (release_s, line, is_sample)
        backdoor, device = self.backdoor, self.device
        while not self._stop.is_set():
            if backdoor.take_disconnect():
                return
            now = time.monotonic()
            wake_at = [now + 0.2]
            if (due := device.next_due()) is not None:
                wake_at.append(due)
            if pending:
                wake_at.append(pending[0][0])
            timeout = max(0.0, min(wake_at) - now)
            wlist = [link.fd] if outbuf else []
            ready, _, _ = select.select([link.fd, self._wake_r], wlist, [], timeout)
            if self._wake_r in ready:
                self._drain_wake()
            now = time.monotonic()
            if link.fd in ready:
                data = link.read()
                if data == b"":
                    return  # the client closed its end
                if data:
                    for line in _split_lines(inbuf, data):
                        if backdoor.silent:
                            continue
                        for body in device.handle(line, now):
                            self._queue(pending, body, False, now)
                    if len(inbuf) > 4 * MAX_COMMAND_CHARS:  # no terminator in sight
                        inbuf.clear()
                        if not backdoor.silent:
                            self._queue(pending, _err(1), False, now)
            for body in device.due_samples(now):
                if backdoor.silent or backdoor.take_drop():
                    continue
                self._queue(pending, body, True, now)
            while pending and pending[0][0] <= now:
                _, line, is_sample = pending.popleft()
                if is_sample and len(outbuf) + len(line) > OUTPUT_BUFFER_BYTES:
                    device.overruns += 1  # UART buffer full: the sample is lost
                    continue
                outbuf += line
            if outbuf:
                written = link.write(bytes(outbuf))
                if written < 0:
                    return
                del outbuf[:written]

    def _queue(self, pending: deque, body: str, is_sample: bool, now: float) -> None:
        line = self.backdoor.maybe_garble(frame_line(body, self.terminator))
        line = self.backdoor.take_noise() + line
        release = now + self.backdoor.delay_s
        if pending:
            release = max(release, pending[-1][0])  # lines keep their order
        pending.append((release, line, is_sample))


def _split_lines(inbuf: bytearray, data: bytes) -> list[str]:
    """Append ``data`` to ``inbuf`` and take out the complete lines (CR, LF or CR LF)."""
    inbuf += data
    lines: list[str] = []
    while True:
        cuts = [i for i in (inbuf.find(b"\r"), inbuf.find(b"\n")) if i >= 0]
        if not cuts:
            return lines
        cut = min(cuts)
        lines.append(inbuf[:cut].decode("ascii", errors="replace"))
        del inbuf[: cut + 1]


def main(argv: list[str] | None = None) -> int:
    """Serve one simulated transducer until SIGTERM/SIGINT; print its address as JSON."""
    parser = argparse.ArgumentParser(prog="python -m simulators.transducer")
    parser.add_argument("--transport", choices=["pty", "tcp"], default="pty")
    parser.add_argument("--port", type=int, default=0, help="TCP port (0: a free one)")
    parser.add_argument("--full-scale", type=float, default=20.0, help="range, N*m")
    parser.add_argument("--baudrate", type=int, default=460800)
    parser.add_argument("--amplitude", type=float, default=5.0, help="sine torque, N*m")
    parser.add_argument("--frequency", type=float, default=0.5, help="sine frequency, Hz")
    args = parser.parse_args(argv)
    plant = SineTorqueSource(amplitude_Nm=args.amplitude, frequency_Hz=args.frequency)
    sim = TransducerSimulator(
        plant, args.transport, port=args.port, full_scale_Nm=args.full_scale,
        baudrate=args.baudrate,
    )
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    signal.signal(signal.SIGINT, lambda *_: done.set())
    address = sim.start()
    print(json.dumps({"transducer": address, "transport": args.transport}), flush=True)
    done.wait()
    sim.stop()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
