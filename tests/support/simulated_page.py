"""The control page on one shared simulated rig, for the page tests that drive a rig through
the web API (tests/conftest.py's ``simulated_rig`` fixture).

Opening the simulated rig (``rig sim`` as its own process, every device connected, the drive
keepalive) and closing it again takes 5-10 s on a loaded 2-core machine; the page tests each
did it once or twice. :class:`SharedRig` opens it on first use and keeps it open while the
tests that follow in the same process use it; tests/conftest.py closes it as soon as the
next test does not (an idle simulated rig takes CPU from the tests around it). Each page
(:func:`page_on`) still has its own store, live hub and controller, so a test sees only its
own runs, events and audit trail; the rig's safe state and a reset of latched faults are
checked when a page closes, so the next page finds the rig idle.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from fastapi.testclient import TestClient


class SharedRig:
    """One simulated rig session (rig/web/simulated.py's plant), opened on first use."""

    def __init__(self) -> None:
        self._stack: contextlib.ExitStack | None = None
        self._session: Any = None

    def session(self) -> Any:
        """The open rig session (opened now if it is not)."""
        if self._session is None:
            from rig.web.simulated import simulated_session_factory

            stack = contextlib.ExitStack()
            self._session = stack.enter_context(simulated_session_factory()())
            self._stack = stack
        return self._session

    def factory(self) -> Any:
        """A session factory for :class:`rig.web.controller.RigController` whose sessions
        are this rig, left open when the controller closes."""
        return lambda: contextlib.nullcontext(self.session())

    @property
    def is_open(self) -> bool:
        return self._session is not None

    def close(self) -> None:
        stack, self._stack, self._session = self._stack, None, None
        if stack is not None:
            stack.close()


SHARED = SharedRig()

OPERATOR = "Test Operator"
"""The operator of the page tests' start requests."""


def identified(body: dict[str, Any], operator: str = OPERATOR, serial: str | None = None
               ) -> dict[str, Any]:
    """A start request ``body`` with who measures which unit, as ``POST /api/control/start``
    needs them (issue 33 item 9): ``operator`` unless the body has one, and the unit's
    ``serial`` (given, else the body's, else ``test-<kind>``)."""
    unit = dict(body.get("unit") or {})
    unit["serial"] = serial or unit.get("serial") or f"test-{unit.get('kind', 'pair')}"
    return {**body, "operator": body.get("operator") or operator, "unit": unit}


def wait_for(client: TestClient, done: Any, timeout_s: float, poll_s: float = 0.05) -> dict:
    """Poll /api/status until ``done(status)``; AssertionError with the last status."""
    deadline = time.monotonic() + timeout_s
    while True:
        status = client.get("/api/status").json()
        if done(status):
            return status
        assert time.monotonic() < deadline, f"timed out; last status {status}"
        time.sleep(poll_s)


@contextlib.contextmanager
def page_on(rig: SharedRig, root: Path, token: str, hub: Any = None
            ) -> Iterator[tuple[TestClient, Any, Any]]:
    """A new control page (its own store at ``root``, live hub and controller) on ``rig``,
    through FastAPI's TestClient; yields (client, store, controller). Leaving it, a running
    measurement is aborted (the controller's close) and latched faults are reset."""
    from rig.store import Store
    from rig.web import create_app
    from rig.web.controller import RigController
    from rig.web.live import LiveHub
    from rig.web.settings import resolve_settings

    store = Store(root)
    controller = RigController(store, hub if hub is not None else LiveHub(), rig.factory(),
                               simulated=True)
    app = create_app(resolve_settings(store_root=root, token=token), controller)
    with TestClient(app) as client:
        wait_for(client, lambda s: s["state"] != "starting", 90.0)
        try:
            yield client, store, controller
        finally:
            if rig.is_open:
                state = client.get("/api/status").json()["state"]
                if state in ("running", "paused"):
                    client.post("/api/control/abort", headers={"Authorization": f"Bearer {token}"})
                    wait_for(client, lambda s: s["state"] not in ("running", "paused"), 60.0)
                if client.get("/api/status").json()["faults"]:
                    controller.reset_faults("tests/support/simulated_page.py")
