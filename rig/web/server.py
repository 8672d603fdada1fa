"""Running the page's app with uvicorn on a socket bound first (so port 0 gives a free port
whose number is known before the first request): :func:`bind`, :class:`RigServer` (stops
cleanly: the live streams end first) and :class:`BackgroundServer` (a server on a thread, for
tests and benchmarks); :func:`claim_store`, one page per store folder."""

from __future__ import annotations

import contextlib
import fcntl
import os
import socket
import threading
import time
from pathlib import Path

import uvicorn
from fastapi import FastAPI

SERVE_LOCK = ".serve.lock"
"""The file in a store folder that the ``rig serve`` serving it holds an ``flock`` on."""


class StoreServedAlready(RuntimeError):
    """Another live ``rig serve`` holds the store's lock; the message names it (one line)."""


def claim_store(root: Path) -> int | None:
    """Hold an exclusive ``flock`` on ``root/.serve.lock`` for as long as this process lives
    (the kernel drops it when the process ends, however it ends: no stale lock after a
    kill -9); the file keeps this process's PID. Returns the file descriptor (keep it open),
    or None for a store this process cannot write (nothing can be measured into it there).
    :class:`StoreServedAlready` names the PID of the live holder."""
    path = root / SERVE_LOCK
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError:
        try:
            fd = os.open(path, os.O_RDONLY)
        except OSError:
            return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = ""
        with contextlib.suppress(OSError, ValueError):
            holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
        os.close(fd)
        raise StoreServedAlready(
            f"the store {root} is served already by rig serve (PID {holder or 'unknown'}): "
            "one page per store; use that page, or stop it first") from None
    with contextlib.suppress(OSError):
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    return fd


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host``:``port`` (port 0: a free one)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError:
        sock.close()
        raise
    sock.listen(128)
    return sock


class RigServer(uvicorn.Server):
    """uvicorn's server, whose stop (Ctrl-C, SIGTERM, ``should_exit``) first ends every live
    stream of the app's :class:`~rig.web.live.LiveHub` (``app.state.hub``).

    uvicorn stops by waiting for every open connection to finish its response (up to
    ``timeout_graceful_shutdown``), then cancels what is left. A server-sent-events stream
    never finishes by itself: without this, each open page held the stop up for the whole
    timeout and then printed an "Exception in ASGI application ... CancelledError" traceback.
    Ended first, the streams complete their responses, the connections close and the stop
    takes a fraction of a second (tests/rig/web/test_serve_stop.py).
    """

    async def shutdown(self, sockets: list[socket.socket] | None = None) -> None:
        app = self.config.app
        hub = getattr(getattr(app, "state", None), "hub", None)
        if hub is not None:
            hub.close_streams()
        await super().shutdown(sockets=sockets)


def uvicorn_server(app: FastAPI) -> RigServer:
    """A server for ``app`` (warnings only, lifespan on, 5 s graceful shutdown for requests
    other than the live streams, which end at once)."""
    config = uvicorn.Config(app, log_level="warning", lifespan="on",
                            timeout_graceful_shutdown=5)
    return RigServer(config)


class BackgroundServer:
    """``app`` served on 127.0.0.1 (a free port) by a thread; a context manager.

    ``url`` is ``http://127.0.0.1:<port>/``. Entering waits until the lifespan has started
    (``start_timeout_s``); leaving shuts the server down (the lifespan's end runs).
    """

    def __init__(self, app: FastAPI, host: str = "127.0.0.1", start_timeout_s: float = 60.0
                 ) -> None:
        self.app = app
        self.sock = bind(host, 0)
        self.port = self.sock.getsockname()[1]
        self.url = f"http://{host}:{self.port}/"
        self.server = uvicorn_server(app)
        self._thread = threading.Thread(target=self._run, name="rig web test server",
                                        daemon=True)
        self.start_timeout_s = start_timeout_s
        self.error: BaseException | None = None

    def _run(self) -> None:
        try:
            self.server.run(sockets=[self.sock])
        except BaseException as exc:  # reported by __enter__/__exit__
            self.error = exc

    def __enter__(self) -> BackgroundServer:
        self._thread.start()
        deadline = time.monotonic() + self.start_timeout_s
        while not self.server.started:
            if self.error is not None or not self._thread.is_alive():
                raise RuntimeError(f"the page's server did not start: {self.error!r}")
            if time.monotonic() > deadline:
                raise TimeoutError(f"the page's server did not start in "
                                   f"{self.start_timeout_s:g} s")
            time.sleep(0.02)
        return self

    def __exit__(self, *exc: object) -> None:
        self.server.should_exit = True
        self._thread.join(timeout=60.0)
        self.sock.close()
