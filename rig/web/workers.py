"""Long work of the page (a campaign's diagnosis, report rendering) in a worker process.

The server's event loop answers the E-stop and the status; its thread pool serves page
requests. Neither may be held by an analysis: :func:`run_in_worker` runs a picklable function
in a separate process (one worker, spawned on first use, kept for the next request) and waits
for it on the calling request's thread. The engine has its own process anyway
(rig/engine_host.py); this keeps the page itself responsive.
"""

from __future__ import annotations

import multiprocessing
import threading
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from typing import Any, TypeVar

from rig.errors import RigError

__all__ = ["run_in_worker", "shutdown_workers"]

T = TypeVar("T")
WORKERS = 1
"""Worker processes (one is enough: page diagnoses are cached once computed)."""

_lock = threading.Lock()
_pool: ProcessPoolExecutor | None = None


def _executor() -> ProcessPoolExecutor:
    global _pool
    with _lock:
        if _pool is None:
            _pool = ProcessPoolExecutor(max_workers=WORKERS,
                                        mp_context=multiprocessing.get_context("spawn"))
        return _pool


def _call(fn: Callable[..., T], *args: Any) -> tuple[bool, Any]:
    """In the worker: the result, or the error as one line (exceptions with their own
    constructors do not always survive pickling)."""
    try:
        return True, fn(*args)
    except Exception as exc:
        return False, str(exc) or type(exc).__name__


def run_in_worker(fn: Callable[..., T], *args: Any, timeout_s: float = 600.0) -> T:
    """``fn(*args)`` in the worker process; an error there is raised here as a RigError
    with its message."""
    ok, value = _executor().submit(_call, fn, *args).result(timeout=timeout_s)
    if not ok:
        raise RigError(value)
    return value


def shutdown_workers() -> None:
    """Stop the worker process (the app's shutdown)."""
    global _pool
    with _lock:
        pool, _pool = _pool, None
    if pool is not None:
        pool.shutdown(wait=False, cancel_futures=True)
