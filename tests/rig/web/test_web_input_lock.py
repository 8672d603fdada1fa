"""The input lock answers at once (issue 33 item 7): a lock move that takes seconds (a lock at
+-3599 deg turns the input for 10-20 s) is answered with 202 ``moving`` within 1 s, goes on in
the engine's side, and its progress (angle, target, done or failed) comes on the live stream
(server-sent events, as the page reads it) and in the status. A second lock while it moves is
refused with one line, Start too; a fault of the input motor during the move ends at the safe
state with the lock unconfirmed.

The simulated rig runs in this process (its backdoor sets the motor's fault), over the real
protocols (Modbus TCP input motor and drive); the page's app is served by uvicorn on
127.0.0.1. The simulated input turns at 360 deg/s: a lock 720 deg away takes 2 s."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import pytest

from rig.hardware.simrig import SimulatedRig
from rig.measurement.service import open_session
from rig.store import Store
from rig.web import create_app
from rig.web.controller import RigController
from rig.web.live import LiveHub
from rig.web.server import BackgroundServer
from rig.web.settings import resolve_settings
from rig.web.simulated import example_plant, example_unit
from tests.support.simulated_page import identified

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(240)]

TOKEN = "input-lock-operator"
AUTH = {"Authorization": f"Bearer {TOKEN}"}


class Stream:
    """The page's live stream (/api/live) read on a thread: its ``input_lock`` events."""

    def __init__(self, url: str) -> None:
        self.events: list[dict[str, Any]] = []
        self.connected = threading.Event()
        self.seen = 0
        self._stop = False
        self._thread = threading.Thread(target=self._read, args=(url,), daemon=True)
        self._thread.start()
        assert self.connected.wait(30.0)

    def _read(self, url: str) -> None:
        with httpx.stream("GET", url + "api/live", timeout=60.0) as r:
            event = None
            for line in r.iter_lines():
                if self._stop:
                    return
                if line.startswith("event: "):
                    event = line[7:]
                elif line.startswith("data: ") and event:
                    if event == "hello":
                        self.connected.set()
                    elif event == "input_lock":
                        self.events.append({**json.loads(line[6:]), "t": time.monotonic()})

    def wait_for(self, state: str, target: float, timeout_s: float = 30.0) -> dict[str, Any]:
        """The first event of ``state`` of a move to ``target`` (deg) not seen yet."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for i, ev in enumerate(self.events):
                if i >= self.seen and ev["state"] == state and ev["target_deg"] == target:
                    self.seen = i + 1
                    return ev
            time.sleep(0.05)
        raise AssertionError(f"no {state!r} input_lock event; got {self.events[self.seen:]}")


def _status(url: str) -> dict[str, Any]:
    return httpx.get(url + "api/status", timeout=30).json()


def _lock(url: str, angle: float) -> tuple[httpx.Response, float]:
    t0 = time.monotonic()
    r = httpx.post(url + "api/devices/input-lock", json={"angle_deg": angle, "confirm": True},
                   headers=AUTH, timeout=60)
    return r, time.monotonic() - t0


def _wait(url: str, done: Any, timeout_s: float = 60.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout_s
    while True:
        status = _status(url)
        if done(status):
            return status
        assert time.monotonic() < deadline, f"timed out; last status {status}"
        time.sleep(0.1)


def test_a_long_input_lock_answers_at_once_and_streams_its_progress(tmp_path: Path) -> None:
    store = Store(tmp_path / "store")
    with SimulatedRig(example_plant(), sync_period_s=0.004) as sim:
        controller = RigController(store, LiveHub(),
                                   lambda: open_session(rig=sim.rig_config_path),
                                   simulated=True)
        app = create_app(resolve_settings(store_root=store.root, token=TOKEN), controller)
        with BackgroundServer(app) as server:
            url = server.url
            _wait(url, lambda s: s["state"] == "idle", 90.0)
            stream = Stream(url)
            r, _ = _lock(url, 0.0)  # where it is: a short move answers with its end
            assert r.status_code == 200 and "locked by the motor at 0.000" in r.json()["message"]
            stream.wait_for("done", 0.0)

            # a move of 2 s: answered at once, moving
            r, answered_s = _lock(url, 720.0)
            assert answered_s < 1.0, answered_s
            assert r.status_code == 202, r.text
            body = r.json()
            assert body["moving"] is True and body["target_deg"] == 720.0
            assert "moving to 720.000 deg" in body["message"]
            moving = _status(url)["input_lock"]
            assert moving["confirmed"] is False and moving["moving"]["target_deg"] == 720.0
            # a second lock, or a start, while it moves: refused, one line
            second, _ = _lock(url, 0.0)
            assert second.status_code == 409
            assert second.json()["detail"] == ("the input is already moving to 720.000 deg: "
                                               "wait until it is locked (or press E-STOP to "
                                               "stop it)")
            unit = example_unit("seed000-pair1")
            start = httpx.post(url + "api/control/start", headers=AUTH, timeout=60, json=identified(
                {"unit": unit, "plan": {"rated_torque_Nm": 10.0}}))
            assert start.status_code == 409 and "still moving" in start.json()["detail"]
            first = stream.wait_for("moving", 720.0)
            done = stream.wait_for("done", 720.0)
            progress = [ev for ev in stream.events if ev["state"] == "moving"
                        and ev["target_deg"] == 720.0 and ev["angle_deg"] is not None]
            assert len(progress) >= 4, stream.events  # every 0.25 s over ~2 s
            angles = [ev["angle_deg"] for ev in progress]
            assert angles == sorted(angles) and 0.0 < angles[0] < angles[-1] < 720.0
            assert all(ev["target_deg"] == 720.0 for ev in progress)
            assert done["t"] - first["t"] > 1.0  # the move took longer than the answer
            assert "locked by the motor at 720.0" in done["message"]
            lock = _status(url)["input_lock"]
            assert lock["confirmed"] is True and lock["moving"] is None
            assert lock["angle_deg"] == pytest.approx(720.0, abs=0.05)

            # a fault of the input motor during the move: failed, safe state, not confirmed
            r, answered_s = _lock(url, 0.0)
            assert r.status_code == 202 and answered_s < 1.0
            stream.wait_for("moving", 0.0)
            time.sleep(0.5)
            sim.modbus_server.input_motor.fault = True
            failed = stream.wait_for("failed", 0.0)
            assert "fault" in failed["message"] and "turning to 0.000 deg" in failed["message"]
            drive = sim.modbus_server.drive
            assert not drive.enabled and drive.setpoint_Nm == 0.0
            status = _status(url)
            assert status["input_lock"]["confirmed"] is False
            assert status["input_lock"]["moving"] is None
            assert "fault" in status["input_lock"]["failed"]
            assert status["safe"] is True
            # the input was stopped where it was: it does not go on to 0 deg
            held = sim.plant.snapshot().input_angle_deg
            time.sleep(0.5)
            assert 0.0 < held < 720.0
            assert sim.plant.snapshot().input_angle_deg == pytest.approx(held, abs=0.01)
            sim.modbus_server.input_motor.fault = False
            stream._stop = True
