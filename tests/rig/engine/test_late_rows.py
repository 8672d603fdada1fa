"""The engine waits for rows a busy PC reads late.

A loaded CI machine read the simulated devices 0.5-2 s behind (the rig simulated in the
test's own process); the torque zero then found no rows of its 0.2 s window within the
stale-sample tolerance (1 s) and stopped a healthy run: "expected torque samples over 0.2 s
for the torque zero, got none". Here the SLCAN adapter passes 150 frames a second of the
~500 the encoders send (its ``throttle`` backdoor): the frames wait in a growing queue and
reach the engine in order, later by 0.7 s every second, until the throttle lifts.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import pytest

from rig.engine import EngineOptions
from rig.hardware.simrig import SimulatedRig
from rig.measurement.service import measure_plan, open_session, run_meta
from rig.plans import Plan
from rig.plans.steps import ReadTorqueZero
from rig.store import Store
from simulators.plant.config import load_plant_config

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

UNIT = dict(load_plant_config().unit, serial="late-rows")


def test_the_torque_zero_waits_for_rows_that_come_late(tmp_path: Path) -> None:
    plan = Plan(name="torque zero", params={},
                build=lambda: iter([ReadTorqueZero("before", 0.2, settle_s=0.5)]))
    with SimulatedRig(None, seed=3, sync_period_s=0.004, stream_rate_Hz=250.0) as sim:
        adapter = sim.backdoors["slcan"]
        throttled: dict[str, Any] = {}

        def progress(event: Any) -> None:
            if event.kind == "step" and "t" not in throttled:
                adapter.throttle(150.0)
                throttled["t"] = threading.Timer(4.0, adapter.throttle, (None,))
                throttled["t"].start()

        with open_session(rig=sim.rig_config_path) as session:
            options = EngineOptions(stale_timeout_s=session.stale_timeout_s)
            engine, outcomes = measure_plan(session, Store(tmp_path / "store"), plan,
                                            run_meta(UNIT, session), options=options,
                                            progress=progress)
        throttled["t"].cancel()
        adapter.throttle(None)
    assert "t" in throttled and outcomes == []
    assert engine.state == "completed" and engine.stopping_reason is None, engine.stopping_reason
