"""The drive keepalive in its own small process, so nothing in the measuring program can
hold it up.

Measured under the load test (3 busy processes, a diagnosis, 20 live-stream clients on 2
cores), the keepalive *thread* of the measuring process woke 50-200 ms late: it shares the
interpreter lock with acquisition, the merge and the store writer, and a thread holding that
lock can itself be waiting for the CPU. The drive saw gaps up to 0.28 s against a 0.5 s
watchdog. A process of its own that sleeps between writes is woken by the kernel within a
few ms even on a loaded PC (a sleeper gets the CPU ahead of processes that spin), and no
lock of ours stands between it and the drive: it writes over its own Modbus TCP connection.

What it does, every ``period_s`` on a fixed schedule (a late write does not push the next
one back):

- the measuring program is alive if it called :meth:`KeepaliveProcess.alive` within
  ``master_timeout_s`` (a time in shared memory): then one FC6 write of a rolling counter to
  the drive's keepalive register; otherwise nothing (a hung program must let the drive's
  watchdog make it safe);
- when the program that started it is gone (even after SIGKILL) it exits at the next tick.

It never commands torque or enables anything: it can only keep an enabled drive from
falling to its safe state while the measuring program is alive, which is what the keepalive
thread did. Only for Modbus TCP (a second connection to the drive); on an RS-485 line (RTU)
there is one master, and the thread of :mod:`rig.hardware.devices` feeds it.

The child (``python -m rig.hardware.keepalive_process``, started by :class:`KeepaliveProcess`)
imports
only ``pymodbus.client`` and the standard library (about 50 ms). The two processes share one
small page (a mapped temporary file): the parent writes when it was last alive and the stop
flag, the child its counts, the time of its last acknowledged write and its last error.
"""

from __future__ import annotations

import contextlib
import json
import mmap
import os
import struct
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

__all__ = ["KeepaliveTarget", "KeepaliveProcess"]

# the shared page: alive_mono, last_write_mono (d), sent, errors (q), withheld, stop (B),
# error length (H), then the last error's bytes
_HEAD = struct.Struct("<ddqqBBH")
_ERROR_BYTES = 300
_SIZE = _HEAD.size + _ERROR_BYTES


@dataclass(frozen=True)
class KeepaliveTarget:
    """Where the keepalive goes: the drive on Modbus TCP (``host``, ``port``, ``unit``), its
    keepalive holding register (``address``), the reply timeout (s), and the schedule:
    ``period_s`` (s) between writes, ``master_timeout_s`` (s, None: never withheld)."""

    host: str
    port: int
    unit: int
    address: int
    timeout_s: float
    period_s: float
    master_timeout_s: float | None


class _Page:
    """The figures both processes see: a small shared file mapped in both (single writer per
    field: the parent writes alive_mono and stop, the child the rest)."""

    def __init__(self, path: str) -> None:
        with open(path, "r+b") as f:
            self._mm = mmap.mmap(f.fileno(), _SIZE)
        self._last: tuple = _HEAD.unpack_from(self._mm, 0)

    def get(self) -> tuple:
        """The head fields; after close (a reader racing the stop), the last ones read."""
        with contextlib.suppress(ValueError):
            self._last = _HEAD.unpack_from(self._mm, 0)
        return self._last

    def set_double(self, index: int, value: float) -> None:
        with contextlib.suppress(ValueError):  # closed: a caller racing the stop
            struct.pack_into("<d", self._mm, 8 * index, value)

    def set_counts(self, sent: int, errors: int) -> None:
        struct.pack_into("<qq", self._mm, 16, sent, errors)

    def set_flag(self, index: int, value: bool) -> None:
        with contextlib.suppress(ValueError):
            self._mm[32 + index] = 1 if value else 0

    def set_error(self, text: str) -> None:
        raw = text.encode("utf-8", "replace")[:_ERROR_BYTES]
        self._mm[_HEAD.size:_HEAD.size + len(raw)] = raw
        struct.pack_into("<H", self._mm, 34, len(raw))

    def error(self) -> str | None:
        try:
            n = struct.unpack_from("<H", self._mm, 34)[0]
            raw = bytes(self._mm[_HEAD.size:_HEAD.size + n])
        except ValueError:  # closed
            return None
        return raw.decode("utf-8", "replace") or None

    def close(self) -> None:
        with contextlib.suppress(BufferError, ValueError):
            self._mm.close()


class KeepaliveProcess:
    """Start, watch and stop the keepalive process (see the module doc)."""

    def __init__(self, target: KeepaliveTarget) -> None:
        self.target = target
        fd, self._path = tempfile.mkstemp(prefix="rig-keepalive-", suffix=".page")
        with os.fdopen(fd, "wb") as f:
            f.write(bytes(_SIZE))
        self._page = _Page(self._path)
        self.alive()
        self._proc: subprocess.Popen | None = None

    def start(self) -> None:
        """Start the process (returns at once; it feeds from its first tick)."""
        # the child imports this very module, from where this process has it
        root = str(Path(__file__).resolve().parents[2])
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(
            p for p in (root, os.environ.get("PYTHONPATH", "")) if p)}
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "rig.hardware.keepalive_process", self._path,
             json.dumps(asdict(self.target)), str(os.getpid())],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, env=env, close_fds=True)

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop feeding and wait for the process to end (killed if it does not)."""
        self._page.set_flag(1, True)
        proc, self._proc = self._proc, None
        if proc is not None:
            try:
                proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(2.0)
        self._page.get()  # the final figures, readable after the close
        self._page.close()
        with contextlib.suppress(OSError):
            os.unlink(self._path)

    def alive(self) -> None:
        """The measuring program is alive (call it at least every ``master_timeout_s``)."""
        self._page.set_double(0, time.monotonic())

    @property
    def running(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    @property
    def sent(self) -> int:
        """Keepalives the drive acknowledged."""
        return int(self._page.get()[2])

    @property
    def errors(self) -> int:
        return int(self._page.get()[3])

    @property
    def last_error(self) -> str | None:
        return self._page.error()

    @property
    def withheld(self) -> bool:
        """True while the measuring program is silent and the keepalive is withheld."""
        return bool(self._page.get()[4])

    def fed_within(self, seconds: float) -> bool:
        """True if the drive acknowledged a keepalive within the last ``seconds``."""
        last = self._page.get()[1]
        return last > 0 and time.monotonic() - last <= seconds


def _feed(target: KeepaliveTarget, page: _Page, parent_pid: int) -> None:
    """The child's loop (module doc)."""
    from pymodbus.client import ModbusTcpClient

    client = ModbusTcpClient(target.host, port=target.port, timeout=target.timeout_s,
                             retries=0)
    counter = 0x8000  # its own range of the rolling counter (the thread counts from 0)
    sent = errors = 0
    next_t = time.monotonic()
    try:
        while True:
            next_t += target.period_s
            now = time.monotonic()
            if next_t < now:
                next_t = now  # behind: write now, and keep the period from here
            time.sleep(max(0.0, next_t - now))
            head = page.get()
            if head[5] or os.getppid() != parent_pid:
                break  # told to stop, or the measuring program is gone: stop feeding
            silent_s = time.monotonic() - head[0]
            if target.master_timeout_s is not None and silent_s > target.master_timeout_s:
                page.set_flag(0, True)
                continue
            page.set_flag(0, False)
            counter = (counter + 1) & 0xFFFF
            error = _write(client, target, counter)
            if error is None:
                sent += 1
                page.set_double(1, time.monotonic())
            else:
                errors += 1
                page.set_error(error)
            page.set_counts(sent, errors)
    finally:
        with contextlib.suppress(Exception):
            client.close()


def _write(client: Any, target: KeepaliveTarget, value: int) -> str | None:
    """One keepalive write; None if the drive acknowledged it, else what went wrong."""
    try:
        if not client.connected and not client.connect():
            return f"no connection to tcp {target.host}:{target.port}"
        reply = client.write_register(target.address, value, device_id=target.unit)
    except Exception as exc:  # noqa: BLE001 - any failure: reconnect on the next tick
        client.close()
        return f"{type(exc).__name__}: {exc}"
    if reply.isError():
        return f"Modbus exception code {getattr(reply, 'exception_code', None)}"
    return None


def main(argv: list[str]) -> int:
    """``python -m rig.hardware.keepalive_process PAGE TARGET_JSON PARENT_PID`` (started by
    :class:`KeepaliveProcess`, not by hand)."""
    page = _Page(argv[0])
    try:
        _feed(KeepaliveTarget(**json.loads(argv[1])), page, int(argv[2]))
    finally:
        page.close()
        with contextlib.suppress(OSError):
            os.unlink(argv[0])  # also when the measuring program was killed and cannot
    return 0


if __name__ == "__main__":
    with contextlib.suppress(KeyboardInterrupt):
        sys.exit(main(sys.argv[1:]))
