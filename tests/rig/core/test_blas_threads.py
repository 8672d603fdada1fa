"""One BLAS thread wherever the product runs work in parallel (rig/core/blas.py, issue 20 point 5).

Each test first gives this process a BLAS with two threads and clears the variables the
test workers inherit (tests/conftest.py), so what a worker reports is what the product set up
for it, not what the test session did.
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy  # noqa: F401  (numpy's OpenBLAS loaded in this process)
import pytest
import scipy.linalg  # noqa: F401  (and scipy's)
from threadpoolctl import threadpool_info, threadpool_limits

from rig.core.blas import ONE_THREAD_ENV, blas_threads, limit_blas_threads
from rig.validate.cases import parallel_map

pytestmark = pytest.mark.alone  # pools of two processes


def _blas_counts() -> list[int]:
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


@pytest.fixture
def two_threads_here(monkeypatch):
    """This process with two BLAS threads and none of the one-thread variables set."""
    for key in ONE_THREAD_ENV:
        monkeypatch.delenv(key, raising=False)
    with threadpool_limits(limits=2):
        if max(_blas_counts()) < 2:
            pytest.fail("this machine's OpenBLAS gives fewer than 2 threads: the tests below "
                        "would not tell a limited worker from a default one")
        yield


def _worker_threads(_item: int) -> tuple[dict[str, int], dict[str, str | None]]:
    return blas_threads(), {k: os.environ.get(k) for k in ONE_THREAD_ENV}


def test_validate_diagnosis_pool_workers_run_with_one_blas_thread(two_threads_here):
    results = list(parallel_map(_worker_threads, [0, 1, 2, 3], jobs=2))
    assert len(results) == 4
    for threads, env in results:
        assert threads and set(threads.values()) == {1}, threads
        assert env == ONE_THREAD_ENV  # and the processes the worker starts inherit it
    assert max(_blas_counts()) == 2  # the caller's own limits are left alone


def test_the_serial_path_maps_with_one_thread_and_restores_the_callers():
    with threadpool_limits(limits=2):
        (threads, _), = list(parallel_map(_worker_threads, [0], jobs=1))
        assert set(threads.values()) == {1}
        assert max(_blas_counts()) == 2
        with limit_blas_threads():
            assert set(_blas_counts()) == {1}
        assert max(_blas_counts()) == 2


def test_reanalyse_dask_workers_run_with_one_blas_thread(two_threads_here):
    import dask
    import distributed  # noqa: F401  (its configuration defaults loaded before the override)

    from rig.store.reanalyse import _client

    # without Dask's own default (its nanny sets these variables too): ours must do it
    with dask.config.set({"distributed.nanny.pre-spawn-environ": {}}):
        client = _client(None, 1)
        try:
            threads = client.submit(blas_threads, pure=False).result(timeout=60)
        finally:
            cluster = client.cluster
            client.close()
            cluster.close()
    assert threads and set(threads.values()) == {1}, threads


def test_web_analysis_worker_runs_with_one_blas_thread(two_threads_here):
    from rig.web.workers import run_in_worker, shutdown_workers

    try:
        threads = run_in_worker(blas_threads, timeout_s=120)
    finally:
        shutdown_workers()
    assert threads and set(threads.values()) == {1}, threads


def test_test_workers_and_their_subprocesses_start_with_one_blas_thread():
    for key, value in ONE_THREAD_ENV.items():
        assert os.environ.get(key) == value, key
    out = subprocess.run(
        [sys.executable, "-c", "import json; from rig.core.blas import blas_threads; "
         "print(json.dumps(sorted(set(blas_threads().values()))))"],
        capture_output=True, text=True, timeout=60, check=True)
    assert out.stdout.strip() == "[1]"
