"""Shared test fixtures."""

from __future__ import annotations

import fcntl
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

import pytest

from tests.support.paths import REPO


@pytest.fixture
def repo_root() -> Path:
    return REPO


# ------------------------------------------------------------------------- one BLAS thread each
# Two pytest-xdist workers on a 2-core machine, each with numpy's OpenBLAS starting a thread per
# core, and the subprocesses the tests start (simulated rigs, servers, diagnosis pools) with as
# many again, oversubscribe the machine and starve the simulated rig's real time. The variables
# are set in the controller's pytest_configure, before xdist starts its workers, so the workers
# and every subprocess a test starts inherit them; a worker also limits a BLAS already loaded.
# OPENBLAS_CORETYPE is left as it is.


def pytest_configure(config: pytest.Config) -> None:
    from rig.core.blas import ONE_THREAD_ENV

    os.environ.update(ONE_THREAD_ENV)
    if os.environ.get("PYTEST_XDIST_WORKER") is not None:
        from rig.core.blas import worker_initializer

        worker_initializer()


# ------------------------------------------------------- tests that load the machine on purpose
# The suite runs on two pytest-xdist workers. Most tests wait on the simulated rig's real
# time and share the machine well; a few load it on purpose (the load test's busy processes,
# four simulated rigs at once, diagnosis pools of two processes) and would starve the other
# worker's simulated devices. Those are marked ``alone``: they take an exclusive lock shared
# by the workers, every other test takes it shared. The lock is taken outside the test's
# timeout (the outermost wrapper of the test protocol), so waiting for it is not counted.
# Consecutive alone tests of a worker hold it throughout: one wait for the other worker's
# test in progress per run of alone tests, not one per test.
#
# Tests marked ``realtime`` (below) also take a second lock exclusively: one measurement on
# simulated devices at a time, beside at most a test that only computes. Two at once (two
# simulated rigs, two engines, a browser) overcommitted the two cores: in the CI runs of
# 2026-11-28 the torque channel came 30-40 ms late against the twist, encoder heartbeats
# went unread for 1.5 s and TE runs dropped rows, 4-6 failures a run, each passing alone.


def _lock_path(name: str) -> Path | None:
    run = os.environ.get("PYTEST_XDIST_TESTRUNUID")
    return None if run is None else Path(tempfile.gettempdir()) / f"rig-tests-{run}-{name}.lock"


class _WorkerLock:
    """One flock shared by the workers: this worker's open file and the mode it holds."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.file: Any = None
        self.mode: int | None = None

    def hold(self, mode: int | None) -> None:
        """Hold ``mode`` (LOCK_EX or LOCK_SH), or nothing (None)."""
        if self.mode == mode:
            return
        if self.file is None:
            self.file = open(_lock_path(self.name), "a+")  # noqa: SIM115 - the worker's life
        if self.mode is not None:
            fcntl.flock(self.file, fcntl.LOCK_UN)
            self.mode = None
        if mode is not None:
            fcntl.flock(self.file, mode)
            self.mode = mode


_machine = _WorkerLock("machine")
"""``alone`` tests hold it exclusively, every other test shared."""
_measuring = _WorkerLock("realtime")
"""``realtime`` tests hold it exclusively: one measurement on simulated devices at a time."""


def _alone(item: pytest.Item | None) -> bool:
    return item is not None and item.get_closest_marker("alone") is not None


def _realtime(item: pytest.Item | None) -> bool:
    return item is not None and item.get_closest_marker("realtime") is not None


@pytest.hookimpl(hookwrapper=True, tryfirst=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):
    if _lock_path("machine") is None:  # one process: nothing to share
        yield
        return
    # always the machine's lock first, then the measuring one: no two workers wait on each
    # other in opposite orders
    _machine.hold(fcntl.LOCK_EX if _alone(item) else fcntl.LOCK_SH)
    _measuring.hold(fcntl.LOCK_EX if _realtime(item) else None)
    try:
        yield
    finally:
        # An exclusive lock is kept into the next test when that one needs it too (a
        # module of alone or realtime tests): released between them, the other worker
        # slipped one of its tests in each time, and this worker waited for it to end,
        # idle, before each. A shared lock is never kept (it would keep the other worker's
        # alone tests waiting). The measuring lock is let go with the machine's, so that
        # the next test takes them in order again.
        if not (_alone(item) and _alone(nextitem)):
            _measuring.hold(None)
            _machine.hold(None)
        elif not _realtime(nextitem):
            _measuring.hold(None)


# --------------------------------------------------- tests that measure on the simulated rig
# A test that talks to the simulated devices over the real protocols measures in real time:
# the devices' threads and processes share two cores with the other worker's test, a
# PostgreSQL server and a browser, and a scheduling stall of a second can trip a heartbeat or
# a page's wait. Such a test gets one more try (pytest-rerunfailures: the summary counts it
# as "rerun", with the first failure's report); a deterministic failure fails twice. Every
# other test gets no second try. A module that starts simulated devices (the simulated rig,
# an encoder node, a transducer, a Modbus server, a page on the rig) says so itself:
# ``pytestmark = pytest.mark.realtime``.

REALTIME_RERUNS = 1
REALTIME_RERUN_DELAY_S = 2.0


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if (item.get_closest_marker("realtime") is not None
                and item.get_closest_marker("flaky") is None):  # a module's own tries stand
            item.add_marker(pytest.mark.flaky(reruns=REALTIME_RERUNS,
                                              reruns_delay=REALTIME_RERUN_DELAY_S))


# --------------------------------------------------------------------------- the store's back-ends


@pytest.fixture(scope="session")
def pg_server():
    """A throw-away PostgreSQL cluster for the whole session (tests/support/pg_server.py)."""
    from tests.support.pg_server import PgServer, required_bin_dir

    server = PgServer(required_bin_dir())
    server.start()
    yield server
    server.destroy()


@pytest.fixture
def pg_url(pg_server) -> str:
    """The URL of a new, empty schema of the session's PostgreSQL server."""
    return pg_server.create_schema()


class StoreMaker:
    """Opens stores on one back-end: ``make_store(root)`` is ``Store(root)`` on SQLite and
    ``Store(<url of a schema kept for root>, samples=root)`` on PostgreSQL."""

    def __init__(self, backend: str, server) -> None:
        self.backend = backend
        self.server = server
        self._urls: dict[Path, str] = {}

    def target(self, root: Path) -> str:
        """What ``--store`` / ``Store()`` is given for the store at ``root``."""
        if self.backend == "sqlite":
            return str(root)
        root = Path(root).absolute()
        if root not in self._urls:
            self._urls[root] = self.server.create_schema()
        return self._urls[root]

    def env(self, root: Path) -> dict[str, str]:
        """Environment a child process needs besides ``target(root)``."""
        return {} if self.backend == "sqlite" else {"RIG_SAMPLES_DIR": str(Path(root))}

    def location(self, root: Path) -> str:
        """``Store.location`` of the store at ``root`` (what ``rig runs`` prints)."""
        return str(Path(root).absolute()) if self.backend == "sqlite" else self.target(root)

    def __call__(self, root: Path, **kwargs):
        from rig.store import Store

        if self.backend == "sqlite":
            return Store(root, **kwargs)
        return Store(self.target(root), samples=root, **kwargs)


@pytest.fixture(params=["sqlite", "postgresql"])
def make_store(request) -> StoreMaker:
    """The store test suite runs on both back-ends through this fixture."""
    server = request.getfixturevalue("pg_server") if request.param == "postgresql" else None
    return StoreMaker(request.param, server)


# ------------------------------------------------------------- one simulated rig for the pages


@pytest.fixture(scope="session")
def simulated_rig():
    """The simulated rig shared by the page tests (tests/support/simulated_page.py): opened by the
    first test that uses it, kept open while the next test uses it too, closed as soon as
    one does not (:func:`pytest_runtest_teardown` below) and at the end."""
    from tests.support.simulated_page import SHARED

    yield SHARED
    SHARED.close()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_teardown(item: pytest.Item, nextitem: pytest.Item | None):
    yield  # the test's own fixtures (its pages) are closed first
    shared = sys.modules.get("tests.support.simulated_page")  # imported by a test that used it
    if shared is not None and (
            nextitem is None or "simulated_rig" not in getattr(nextitem, "fixturenames", ())):
        shared.SHARED.close()
