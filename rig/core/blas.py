"""numpy's BLAS threads: one per process wherever the product runs work beside other work.

numpy and scipy each load an OpenBLAS that starts one thread per core and spins while it waits.
The diagnosis does many small matrix products and least-squares fits: on a 2-core machine its
BLAS threads cost more in hand-overs than they gain, and two diagnoses (or a diagnosis beside
the simulated rig's real-time devices) with a thread per core each oversubscribe the machine
(``rig diagnose`` of a 14-run campaign: 27-34 s with the default threads, 3.6-9 s with one; two
at once: 43-47 s each against 9.5-11.8 s). So:

* :func:`limit_blas_threads` limits the BLAS (and OpenMP) pools of this process while a block
  runs (threadpoolctl), e.g. around one diagnosis;
* :func:`worker_initializer` is the ``initializer`` of worker-process pools: the worker keeps
  one BLAS thread for its life, and the processes it starts inherit :data:`ONE_THREAD_ENV`;
* :func:`one_thread_env` is the environment for subprocesses (set before numpy loads: OpenBLAS
  reads it once, when the library is loaded).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from functools import wraps
from typing import Any, ParamSpec, TypeVar

__all__ = ["ONE_THREAD_ENV", "blas_threads", "limit_blas_threads", "limited",
           "one_thread_env", "worker_initializer"]

ONE_THREAD_ENV: dict[str, str] = {
    "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
}
"""The variables the BLAS libraries numpy and scipy may load read at load time (OpenBLAS,
OpenMP, MKL). ``OPENBLAS_CORETYPE`` (which kernel OpenBLAS picks) is left alone."""

P = ParamSpec("P")
T = TypeVar("T")


def one_thread_env(base: Mapping[str, str] | None = None) -> dict[str, str]:
    """``base`` (default ``os.environ``) with :data:`ONE_THREAD_ENV` set: the environment of a
    subprocess that must start with one BLAS thread."""
    env = dict(os.environ if base is None else base)
    env.update(ONE_THREAD_ENV)
    return env


@contextmanager
def limit_blas_threads(threads: int = 1) -> Iterator[None]:
    """Limit every BLAS and OpenMP pool loaded in this process to ``threads`` while the block
    runs; the previous limits come back after it (threadpoolctl)."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=threads):
        yield


def limited(fn: Callable[P, T]) -> Callable[P, T]:
    """``fn`` run under :func:`limit_blas_threads` (one thread); picklable by reference when
    used as a decorator at module level."""

    @wraps(fn)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> T:
        with limit_blas_threads():
            return fn(*args, **kwargs)

    return wrapper


def worker_initializer() -> None:
    """``initializer`` of a worker process: one BLAS thread for the process' life.

    Sets :data:`ONE_THREAD_ENV` (for libraries loaded later and for the worker's own
    subprocesses), then limits the libraries already loaded (a forked worker has numpy's
    OpenBLAS from its parent, started with a thread per core)."""
    os.environ.update(ONE_THREAD_ENV)
    import numpy  # noqa: F401  (load numpy's BLAS now, so the limit below reaches it)
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1)


def blas_threads() -> dict[str, Any]:
    """The thread count of each BLAS/OpenMP library loaded in this process
    (``{filepath: num_threads}``), numpy's and scipy's loaded first."""
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401
    from threadpoolctl import threadpool_info

    return {i["filepath"]: i["num_threads"] for i in threadpool_info()}
