"""Long work of the page (a campaign's diagnosis, report rendering) in a worker process.

The server's event loop answers the E-stop and the status; its thread pool serves page
requests. Neither may be held by an analysis: :func:`run_in_worker` runs a picklable function
in a separate process (one worker, spawned on first use, kept for the next request) and waits
for it on the calling request's thread. The engine has its own process anyway
(rig/engine/host.py); this keeps the page itself responsive.
"""

from __future__ import annotations

import multiprocessing
import threading
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from typing import Any, TypeVar

from rig.blas import worker_initializer
from rig.errors import RigError

__all__ = ["run_in_worker", "shutdown_workers", "warm_up"]

T = TypeVar("T")
POOLS = {"analysis": 1, "preview": 1}
"""Worker processes per pool: "analysis" (diagnosis, quality view: cached once computed) and
"preview" (plan previews), so that neither waits for the other."""

_lock = threading.Lock()
_pools: dict[str, ProcessPoolExecutor] = {}


def _executor(pool: str) -> ProcessPoolExecutor:
    with _lock:
        if pool not in _pools:
            # one BLAS thread (rig/blas.py): the diagnosis runs beside the rig's real time
            _pools[pool] = ProcessPoolExecutor(max_workers=POOLS[pool],
                                               mp_context=multiprocessing.get_context("spawn"),
                                               initializer=worker_initializer)
        return _pools[pool]


def _ready() -> bool:
    return True


def warm_up(*pools: str) -> None:
    """Start the pools' processes now (a first request then does not wait for imports)."""
    for pool in pools:
        _executor(pool).submit(_ready)


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
    RigError with its message."""
    ok, value = _executor(pool).submit(_call, fn, *args).result(timeout=timeout_s)
    if not ok:
        raise RigError(value)
    return value


def shutdown_workers() -> None:
    """Stop the worker processes (the app's shutdown)."""
    with _lock:
        pools = list(_pools.values())
        _pools.clear()
    for pool in pools:
        pool.shutdown(wait=False, cancel_futures=True)
