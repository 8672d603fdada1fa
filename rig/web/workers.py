"""Long work of the page (a campaign's diagnosis, report rendering) in a worker process.

The server's event loop answers the E-stop and the status; its thread pool serves page
requests. Neither may be held by an analysis: :func:`run_in_worker` runs a picklable function
in a separate process (one worker, spawned on first use, kept for the next request) and waits
for it on the calling request's thread. The engine has its own process anyway
(rig/web/engine_host.py); this keeps the page itself responsive.

The plan previews' pool (issue 21 item 10) runs at a lower CPU priority
(:data:`POOL_NICE`: a flood of previews cannot take the CPU from acquisition, whatever
process that runs in) and takes at most :data:`QUEUE_LIMIT` requests at a time: beyond it
:class:`PoolBusy` at once (the page answers 503), instead of a queue of waiting threads.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import threading
import time
from collections.abc import Callable
from concurrent.futures import BrokenExecutor, CancelledError, Future, ProcessPoolExecutor
from multiprocessing import resource_tracker
from typing import Any, TypeVar

from rig.core.blas import worker_initializer
from rig.core.errors import RigError

__all__ = ["PoolBusy", "pool_full", "run_in_worker", "shutdown_workers", "warm_up",
           "worker_pids"]

T = TypeVar("T")
POOLS = {"analysis": 1, "preview": 1}
"""Worker processes per pool: "analysis" (diagnosis, quality view: cached once computed) and
"preview" (plan previews), so that neither waits for the other."""

POOL_NICE = {"preview": 10}
"""Niceness added to a pool's worker processes (Linux: 10 gets about a tenth of the CPU of a
normal process that wants it)."""
QUEUE_LIMIT = {"preview": 4}
"""Requests a pool takes at a time (computing and waiting); None: no limit."""

_lock = threading.Lock()
_pools: dict[str, ProcessPoolExecutor] = {}
_in_flight: dict[str, int] = {}


class PoolBusy(RigError):
    """The pool already has its :data:`QUEUE_LIMIT` of requests: retry later."""


def _worker_start(increment: int) -> None:
    """In a new worker process: one BLAS thread, and a lower CPU priority by ``increment``.
    Ctrl-C is the server's to handle (it reaches every process of the terminal's group): the
    worker ignores it and is stopped by :func:`shutdown_workers`. The worker was started
    with SIGINT blocked (:func:`_submit`), so that a Ctrl-C during its start-up (the imports
    before this runs) stays pending; ignored now, unblocking it discards it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    worker_initializer()
    if increment:
        os.nice(increment)
    threading.Thread(target=_end_with_parent, args=(os.getppid(),), daemon=True,
                     name="parent-watch").start()


PARENT_POLL_S = 0.5
"""How often a worker checks that the server that started it is still its parent (s)."""


def _end_with_parent(parent: int) -> None:
    """End this worker once the server is gone (``kill -9``: no shutdown ends it; reparented,
    it would hold its memory, and the resource tracker, for ever). A parent-death signal
    would not do: it fires when the *thread* that spawned the worker ends, and the page's
    request threads come and go."""
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os._exit(0)


def _executor(pool: str) -> ProcessPoolExecutor:
    with _lock:
        if pool not in _pools:
            # one BLAS thread (rig/core/blas.py): the work runs beside the rig's real time; a
            # preview worker also at a lower CPU priority
            nice = POOL_NICE.get(pool, 0)
            _pools[pool] = ProcessPoolExecutor(
                max_workers=POOLS[pool], mp_context=multiprocessing.get_context("spawn"),
                initializer=_worker_start, initargs=(nice,))
        return _pools[pool]


def pool_full(pool: str) -> bool:
    """Whether ``pool`` has its :data:`QUEUE_LIMIT` of requests now (a request would get
    :class:`PoolBusy`)."""
    limit = QUEUE_LIMIT.get(pool)
    with _lock:
        return limit is not None and _in_flight.get(pool, 0) >= limit


def worker_pids(pool: str) -> list[int]:
    """The process ids of ``pool``'s workers (none before its first use)."""
    with _lock:
        executor = _pools.get(pool)
        processes = getattr(executor, "_processes", None) or {}
        return sorted(processes)


def _submit(pool: str, fn: Callable[..., Any], *args: Any) -> Future[Any]:
    """Submit to ``pool``'s executor with SIGINT blocked in this thread: a worker process the
    submission spawns inherits the mask through exec, so a Ctrl-C that reaches the process
    group while the worker is still importing does not end it with a KeyboardInterrupt
    traceback (Python only installs its SIGINT handler; the mask keeps the signal pending
    until :func:`_worker_start` ignores it). The resource tracker is started first: when
    multiprocessing starts it during a spawn it *unblocks* SIGINT on its way out (it blocks
    and then unblocks its signals instead of restoring the mask), and the worker spawned
    next would start unprotected."""
    resource_tracker.ensure_running()
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        return _executor(pool).submit(fn, *args)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _ready() -> bool:
    return True


def warm_up(*pools: str) -> None:
    """Start the pools' processes now (a first request then does not wait for imports)."""
    for pool in pools:
        _submit(pool, _ready)


def _call(fn: Callable[..., T], *args: Any) -> tuple[bool, Any]:
    """In the worker: the result, or the error as one line (exceptions with their own
    constructors do not always survive pickling)."""
    try:
        return True, fn(*args)
    except Exception as exc:
        return False, str(exc) or type(exc).__name__


def run_in_worker(fn: Callable[..., T], *args: Any, timeout_s: float = 600.0,
                  pool: str = "analysis") -> T:
    """``fn(*args)`` in a worker process of ``pool``; an error there is raised here as a
    RigError with its message; :class:`PoolBusy` when the pool has its queue limit."""
    limit = QUEUE_LIMIT.get(pool)
    with _lock:
        if limit is not None and _in_flight.get(pool, 0) >= limit:
            raise PoolBusy(f"the {pool} worker is busy with {limit} requests: retry in a "
                           "second")
        _in_flight[pool] = _in_flight.get(pool, 0) + 1
    try:
        ok, value = _submit(pool, _call, fn, *args).result(timeout=timeout_s)
    except (BrokenExecutor, CancelledError) as exc:  # shutdown_workers stopped it
        raise RigError(f"the {pool} worker was stopped (the page is shutting down)") from exc
    finally:
        with _lock:
            _in_flight[pool] -= 1
    if not ok:
        raise RigError(value)
    return value


STOP_TIMEOUT_S = 2.0
"""Time a worker process has to end after SIGTERM before it is killed (s)."""


def shutdown_workers() -> None:
    """Stop the worker processes and wait until they have ended (the app's shutdown).

    Queued requests are cancelled and the workers are terminated (SIGTERM; SIGKILL after
    :data:`STOP_TIMEOUT_S`): a worker holds no state worth its work, and one asked to stop
    politely would first finish its current analysis, then tear its interpreter down, the
    preview worker at its lower priority on a loaded machine. Left to the interpreter's exit
    (``shutdown(wait=False)`` alone), ``rig serve`` waited up to 2 s for them after Ctrl-C.
    """
    with _lock:
        pools = list(_pools.values())
        _pools.clear()
    processes = []
    for pool in pools:
        # ProcessPoolExecutor keeps its processes by pid (no public accessor before 3.14's
        # terminate_workers)
        processes += list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            process.terminate()
    for process in processes:
        process.join(STOP_TIMEOUT_S)
        if process.is_alive():
            process.kill()
            process.join(STOP_TIMEOUT_S)
