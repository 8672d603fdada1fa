"""The engine's own process: what keeps the rig safe and the samples flowing, out of reach of
the page.

``rig serve`` does not run the rig in the web server's process. :class:`EngineHost` starts a
child process (multiprocessing, *spawn*) that opens the rig and holds the
:class:`rig.web.controller.RigController`: the devices, the engine's threads (drive keepalive,
interlocks, acquisition and merge), the idle monitor and the store writer. Nothing else runs
there: no page request, no SSE client, no diagnosis, no report rendering. The web server holds
an :class:`EngineHost` in place of the controller; its routes call the same methods.

The local channel (docs/reliability.md, "Engine process"):

- **commands**: a ``multiprocessing.connection`` socket (an abstract Unix socket on Linux,
  authenticated by a random key). Each server thread has its own connection, so an E-stop is
  never queued behind a start or a status poll. A request is ``(name, args, kwargs)``; the
  answer ``("ok", value)``, ``("attr", value)`` or ``("err", class name, message)``. Errors of
  the rig (:class:`rig.core.errors.RigError` and :class:`rig.web.controller.ControlError`) come
  back as the same class.
- **live data**: a one-way pipe from the engine to the server with the rows and events for
  the page (``begin_run``, ``add_rows``, ``add_event``), batched every 20 ms by a sender
  thread; the engine only appends to an in-memory queue. When the server is slow the queue's
  rows (display only: the store has them all) are dropped first, never the events.

If the server dies (even by SIGKILL), the engine notices within 0.2 s, stops any
measurement (safe state: zero torque, drive disabled), closes the open run as aborted and
exits. Optional real-time priority (``SCHED_FIFO``, ``[rig] realtime_priority``) is set on
this process when the rig is opened (rig/core/realtime.py), never on the server.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import secrets
import signal
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from multiprocessing.connection import Client, Connection, Listener
from typing import Any

from rig.core.errors import RigError
from rig.core.process_exit import prepare_exit

__all__ = ["EngineHost", "EngineSpec"]

log = logging.getLogger(__name__)

SEND_TICK_S = 0.02
"""Live rows and events are sent to the server every 20 ms (s)."""
MAX_PENDING_ROWS = 100_000
"""Live rows waiting for a slow server before the oldest are dropped (display only)."""
START_TIMEOUT_S = 60.0
"""Time for the engine process to import and report ready (s)."""


@dataclass(frozen=True)
class EngineSpec:
    """What the engine process opens: the store and the rig (picklable)."""

    store: str
    samples: str | None = None
    simulated_unit: str | None = None
    """The example unit of the simulated rig; None with ``rig_path``."""
    simulated_plant: str | None = None
    """A plant TOML the simulated rig runs instead of the example unit's plant."""
    rig_path: str | None = None
    description: str = ""
    log_file: str | None = None
    extra: dict[str, Any] = field(default_factory=dict)


# ---------------------------------------------------------------------- the engine process


class _ForwardingHub:
    """The engine's side of the live hub: appends to a queue; a thread sends batches."""

    def __init__(self, conn: Connection) -> None:
        self._conn = conn
        self._lock = threading.Lock()
        self._rows: deque[tuple[float, ...]] = deque(maxlen=MAX_PENDING_ROWS)
        self._messages: list[tuple[str, Any]] = []
        self._wake = threading.Event()
        self.broken = threading.Event()
        threading.Thread(target=self._send_loop, name="engine live sender", daemon=True).start()

    def begin_run(self, run_id: str, label: str | None = None, test: str | None = None) -> None:
        with self._lock:
            self._flush_rows_locked()
            self._messages.append(("begin_run", (run_id, label, test)))

    def add_rows(self, rows: list[tuple[float, ...]]) -> None:
        with self._lock:
            self._rows.extend(rows)

    def add_event(self, event: dict[str, Any]) -> None:
        with self._lock:
            self._flush_rows_locked()
            self._messages.append(("add_event", event))

    def _flush_rows_locked(self) -> None:
        if self._rows:
            self._messages.append(("add_rows", list(self._rows)))
            self._rows.clear()

    def _send_loop(self) -> None:
        while not self.broken.is_set():
            time.sleep(SEND_TICK_S)
            with self._lock:
                self._flush_rows_locked()
                batch, self._messages = self._messages, []
            if not batch:
                continue
            try:
                self._conn.send(batch)
            except (OSError, EOFError, ValueError):
                self.broken.set()


def _serve_connection(conn: Connection, controller: Any, stop: threading.Event) -> None:
    """Answer one server thread's requests until it hangs up."""
    with conn:
        while not stop.is_set():
            try:
                name, args, kwargs = conn.recv()
            except (EOFError, OSError):
                return
            try:
                if name == "__close__":  # the main loop closes the rig and exits
                    stop.set()
                    reply = ("ok", None)
                elif name == "__getattr__":
                    value = getattr(controller, args[0])
                    reply = ("attr", "callable" if callable(value) else value)
                else:
                    reply = ("ok", getattr(controller, name)(*args, **kwargs))
            except Exception as exc:  # sent back to the caller, raised there
                reply = ("err", type(exc).__name__, str(exc))
            try:
                conn.send(reply)
            except (OSError, ValueError) as exc:  # an unpicklable value: said, not fatal
                with contextlib.suppress(OSError, ValueError):
                    conn.send(("err", "RigError", f"engine: cannot send the answer of "
                                                  f"{name}: {exc}"))


def _session_factory(spec: EngineSpec) -> Any:
    if spec.simulated_plant is not None:
        from rig.web.simulated import plant_session_factory

        return plant_session_factory(spec.simulated_plant)
    if spec.simulated_unit is not None:
        from rig.web.simulated import simulated_session_factory

        return simulated_session_factory(spec.simulated_unit)
    from rig.measurement.service import open_session

    rig_path = spec.rig_path

    def factory() -> Any:
        return open_session(rig=rig_path)

    return factory


def _engine_main(spec: EngineSpec, address: Any, authkey: bytes, live: Connection,
                 ready: Connection) -> None:
    """The engine process: open the store and the rig, answer commands, forward live data."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the server decides when to stop
    if spec.log_file:
        logging.basicConfig(filename=spec.log_file, level=logging.INFO,
                            format="%(asctime)s engine %(levelname)s %(name)s: %(message)s")
    parent = os.getppid()
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        from rig.store import Store
        from rig.web.controller import RigController

        store = Store(spec.store, samples=spec.samples)
        hub = _ForwardingHub(live)
        simulated = spec.simulated_unit is not None or spec.simulated_plant is not None
        unit_factory = None
        if simulated:  # a unit of another kind than the plant's: restarted with its plant
            from rig.web.simulated import unit_session_factory as unit_factory
        controller = RigController(store, hub, _session_factory(spec),  # type: ignore[arg-type]
                                   simulated=simulated, description=spec.description,
                                   unit_session_factory=unit_factory)
        listener = Listener(address, authkey=authkey)
    except Exception as exc:
        ready.send(("err", f"{type(exc).__name__}: {exc}"))
        return
    controller.start()
    ready.send(("ok", "started"))

    def accept_loop() -> None:
        while not stop.is_set():
            try:
                conn = listener.accept()
            except (OSError, EOFError):
                if stop.is_set():
                    return
                continue  # a client that failed authentication: ignored
            threading.Thread(target=_serve_connection, args=(conn, controller, stop),
                             name="engine command", daemon=True).start()

    threading.Thread(target=accept_loop, name="engine accept", daemon=True).start()
    # The server gone (closed the live pipe, or died): safe state, close the rig, exit.
    while not stop.is_set():
        if os.getppid() != parent or hub.broken.is_set():
            log.error("the web server is gone: stopping the engine (safe state)")
            break
        stop.wait(0.2)
    stop.set()
    try:
        controller.close()
    finally:
        with contextlib.suppress(OSError):
            listener.close()
        prepare_exit()  # the server waits for this process to end


# ---------------------------------------------------------------------- the server's side


def _error(cls_name: str, message: str) -> Exception:
    from rig.web.controller import ControlError

    known: dict[str, type[Exception]] = {"ControlError": ControlError, "RigError": RigError,
                                         "ValueError": ValueError, "KeyError": KeyError}
    return known.get(cls_name, RigError)(message if cls_name in known
                                         else f"engine: {cls_name}: {message}")


class EngineHost:
    """The controller of the page, running in the engine process (see the module doc).

    Any method of :class:`rig.web.controller.RigController` is called as on the controller
    itself (``host.status(True)``, ``host.estop()`` ...); ``store`` and ``hub`` are the
    server's own.
    """

    def __init__(self, spec: EngineSpec, store: Any, hub: Any) -> None:
        self.spec = spec
        self.store = store
        self.hub = hub
        self.scheduling = ""
        self._authkey = secrets.token_bytes(32)
        self._address = f"\0backlash-rig-engine-{os.getpid()}-{secrets.token_hex(6)}"
        self._local = threading.local()
        self._conns: list[Connection] = []
        self._conns_lock = threading.Lock()
        self._process: multiprocessing.process.BaseProcess | None = None
        self._live: Connection | None = None
        self._closing = False

    # -- lifecycle ---------------------------------------------------------------------
    def start(self) -> None:
        """Start the engine process and wait until it answers (RigError if it cannot)."""
        ctx = multiprocessing.get_context("spawn")
        live_recv, live_send = ctx.Pipe(duplex=False)
        ready_recv, ready_send = ctx.Pipe(duplex=False)
        self._process = ctx.Process(target=_engine_main, name="rig engine", daemon=False,
                                    args=(self.spec, self._address, self._authkey,
                                          live_send, ready_send))
        self._process.start()
        live_send.close()
        ready_send.close()
        if not ready_recv.poll(START_TIMEOUT_S):
            self._process.kill()
            raise RigError(f"the engine process did not start within {START_TIMEOUT_S:.0f} s")
        status, detail = ready_recv.recv()
        if status != "ok":
            self._process.join(5)
            raise RigError(f"the engine process could not start: {detail}")
        self.scheduling = detail
        self._live = live_recv
        threading.Thread(target=self._live_loop, name="engine live receiver",
                         daemon=True).start()

    def close(self) -> None:
        """Stop any measurement (safe state), close the rig, end the engine process."""
        self._closing = True
        with contextlib.suppress(RigError, OSError, EOFError):
            self._call("__close__")
        process = self._process
        if process is not None:
            process.join(45)  # the engine closes the rig (safe state) and exits
            if process.is_alive():
                process.terminate()
                process.join(5)
            if process.is_alive():
                process.kill()
        with self._conns_lock:
            for conn in self._conns:
                with contextlib.suppress(OSError):
                    conn.close()
            self._conns.clear()
        if self._live is not None:
            with contextlib.suppress(OSError):
                self._live.close()

    @property
    def pid(self) -> int | None:
        """The engine process's id (None before start)."""
        return None if self._process is None else self._process.pid

    # -- calls ---------------------------------------------------------------------------
    def _conn(self) -> Connection:
        conn = getattr(self._local, "conn", None)
        if conn is None or conn.closed:
            try:
                conn = Client(self._address, authkey=self._authkey)
            except (OSError, EOFError) as exc:
                raise RigError(f"the engine process does not answer ({exc}): the rig is "
                               f"left to the drive's watchdog; restart rig serve") from exc
            self._local.conn = conn
            with self._conns_lock:
                self._conns.append(conn)
        return conn

    def _call(self, name: str, *args: Any, **kwargs: Any) -> Any:
        conn = self._conn()
        try:
            conn.send((name, args, kwargs))
            reply = conn.recv()
        except (OSError, EOFError) as exc:
            self._local.conn = None
            raise RigError(f"the engine process stopped answering ({exc})") from exc
        if reply[0] == "err":
            raise _error(reply[1], reply[2])
        return reply[1]

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        kind, value = self._call_raw_attr(name)
        if kind == "attr" and value == "callable":
            return lambda *args, **kwargs: self._call(name, *args, **kwargs)
        return value

    def _call_raw_attr(self, name: str) -> tuple[str, Any]:
        conn = self._conn()
        try:
            conn.send(("__getattr__", (name,), {}))
            reply = conn.recv()
        except (OSError, EOFError) as exc:
            self._local.conn = None
            raise RigError(f"the engine process stopped answering ({exc})") from exc
        if reply[0] == "err":
            raise AttributeError(reply[2]) if reply[1] == "AttributeError" else _error(*reply[1:])
        return reply[0], reply[1]

    # -- live data -----------------------------------------------------------------------
    def _live_loop(self) -> None:
        live = self._live
        assert live is not None
        while True:
            try:
                batch = live.recv()
            except (EOFError, OSError):
                if not self._closing:
                    log.error("the engine process ended")
                    with contextlib.suppress(Exception):
                        self.hub.add_event({"type": "state", "state": "fault",
                                            "message": "the engine process ended"})
                return
            for method, payload in batch:
                try:
                    if method == "begin_run":  # (run id, label, test kind)
                        self.hub.begin_run(*payload)
                    else:
                        getattr(self.hub, method)(payload)
                except Exception:  # the display must never stop the receiver
                    log.exception("live %s", method)
