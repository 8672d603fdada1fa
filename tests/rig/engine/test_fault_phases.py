"""The fault matrix: each device fault, injected through the simulated devices' backdoors at
a phase of a hysteresis run, ends in the safe state with the run kept as aborted and a
message naming the device and what it expected.

The simulated rig runs in this process (for its backdoors and the loading drive's own state:
the safe state is read from the drive, not from the engine); the engine talks to it over the
real protocols (SLCAN on TCP, Modbus TCP, the transducer's pty). Each case records its row of
the matrix with ``record_property`` (fault, phase, outcome, time to safe state, samples kept,
message): ``python -m bench.fault_matrix`` turns the results into docs/reliability.md's table.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from rig.hardware.simrig import SimulatedRig
from rig.measurement.service import measure_plan, open_session, plant_config_for, run_meta
from rig.plans import LoopParams, hysteresis_plan
from rig.plans.campaign_file import SimulationSection
from rig.runformat import read_run
from rig.store import Store
from simulators.plant.config import load_plant_config

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

UNIT = dict(load_plant_config().unit, serial="fault-matrix")
PLANT = plant_config_for(UNIT, SimulationSection(seed=3, plant={"effects": {"friction": {
    "enabled": True, "model": "lugre", "viscous_Nms_per_arcmin": 0.002}}}))
PLAN = hysteresis_plan(LoopParams(rated_torque_Nm=10.0, steps_per_quarter=2, dwell_s=0.1,
                                  pre_cycles=0, cycles=1, rate_Nm_per_s=25.0))
SAFE_WITHIN_S = 3.0
"""The slowest allowed path to the safe state: detection (the drivers' timeouts, ~1-2 s)
plus the safe-state command; the drive's own watchdog (0.5 s) backs it up."""

Inject = Callable[[SimulatedRig], None]
FAULTS: dict[str, tuple[Inject, tuple[str, ...]]] = {
    "encoder PDO stall": (lambda s: s.backdoors["encoder"].silence(), ("encoder",)),
    "encoder heartbeat loss": (lambda s: s.backdoors["encoder"].lose_heartbeat(),
                               ("encoder",)),
    "encoder EMCY": (lambda s: s.backdoors["encoder"].emergency(0x5000, 0x81), ("encoder",)),
    "encoder position frozen": (lambda s: s.backdoors["encoder"].stick(), ("encoder",)),
    "drive disabled by another master": (lambda s: _outside_disable(s), ("loading drive",)),
    "SLCAN link dropped": (lambda s: s.backdoors["slcan"].disconnect(),
                           ("encoder", "CAN", "slcan")),
    "Modbus torque sensor exception": (
        lambda s: s.backdoors["modbus"].exception(s.modbus_server.sensor_id, 4),
        ("torque sensor",)),
    "Modbus silence (all units)": (lambda s: s.backdoors["modbus"].silence(),
                                   ("drive", "torque sensor", "climate", "input motor")),
    "transducer silence": (lambda s: s.backdoors["transducer"].silence(),
                           ("torque transducer", "acquisition")),
    "transducer garbled": (lambda s: s.backdoors["transducer"].garble(1.0),
                           ("torque transducer", "acquisition")),
}
PHASES = {
    "ramp to +T": lambda msg: msg.startswith("torque to +10"),
    "settled sample": lambda msg: msg.startswith("sample"),
}


def _outside_disable(sim: SimulatedRig) -> None:
    """Another Modbus master (a plain pymodbus client, not our driver) writes 0 to the
    drive's control register mid-run: fault-matrix row 2."""
    from pymodbus.client import ModbusTcpClient

    from drivers.modbus.map import DRIVE_DEVICE_ID, LOADING_DRIVE_MAP

    host, port = sim.modbus_server.address.rsplit(":", 1)
    client = ModbusTcpClient(host, port=int(port), timeout=1.0, retries=0)
    try:
        assert client.connect()
        client.write_register(LOADING_DRIVE_MAP["control"].address, 0,
                              device_id=DRIVE_DEVICE_ID)
    finally:
        client.close()


def _drive_safe(sim: SimulatedRig) -> bool:
    drive = sim.modbus_server.drive
    return (not drive.enabled) and drive.setpoint_Nm == 0.0


@pytest.mark.parametrize("phase", list(PHASES))
@pytest.mark.parametrize("fault", list(FAULTS))
def test_fault_at_phase_ends_safe_with_the_run_kept(fault: str, phase: str, tmp_path: Path,
                                                     record_property: Any) -> None:
    inject, devices = FAULTS[fault]
    at_phase = PHASES[phase]
    store = Store(tmp_path / "store")
    with SimulatedRig(PLANT, seed=3, sync_period_s=0.004, stream_rate_Hz=250.0) as sim:
        injected: dict[str, float] = {}
        safe_at: dict[str, float] = {}
        in_run = threading.Event()

        def progress(event: Any) -> None:
            if event.kind == "run_started":
                in_run.set()
            if (in_run.is_set() and "t" not in injected and event.kind == "step"
                    and at_phase(event.message)):
                inject(sim)
                injected["t"] = time.monotonic()

        def watch() -> None:
            while "t" not in injected:
                time.sleep(0.002)
            while time.monotonic() - injected["t"] < 30:
                if _drive_safe(sim):
                    safe_at["t"] = time.monotonic()
                    return
                time.sleep(0.002)

        watcher = threading.Thread(target=watch, daemon=True)
        watcher.start()
        with open_session(rig=sim.rig_config_path) as session:
            engine, outcomes = measure_plan(session, store, PLAN, run_meta(UNIT, session),
                                            progress=progress)
        watcher.join(35)
        assert "t" in injected, (f"the phase {phase!r} never came: the run ended "
                             f"{engine.state}: {engine.stopping_reason}")
        safe_s = safe_at["t"] - injected["t"] if "t" in safe_at else None
        (outcome,) = outcomes
        run = read_run(outcome.path)
        record_property("fault", fault)
        record_property("phase", phase)
        record_property("outcome", f"{engine.state}; run {outcome.status}")
        record_property("safe_s", "" if safe_s is None else f"{safe_s:.3f}")
        record_property("samples_kept", str(run.n_samples))
        record_property("message", outcome.reason or "")

    assert engine.state == "aborted" and outcome.status == "aborted", (fault, outcome.reason)
    assert run.meta["status"] == "aborted" and run.meta["reason"] == outcome.reason
    assert run.n_samples > 10  # every sample measured before the fault is kept
    assert safe_s is not None and safe_s < SAFE_WITHIN_S, (fault, safe_s)
    assert any(name in outcome.reason for name in devices), outcome.reason
    assert "expected" in outcome.reason, outcome.reason
    assert "lost_motion_arcmin" not in (run.meta.get("result") or {}) or \
        run.meta["result"]["lost_motion_arcmin"] is None  # no metric from an aborted run


def test_encoder_frozen_before_the_start_is_a_fault_not_a_zero_lost_motion(tmp_path: Path):
    """Outside-probe row 8: the encoder's reading frozen before the run starts. Its PDOs and
    heartbeats keep coming on time, so only the physics tells: the torque moves, the twist
    does not. The run ends aborted naming the encoder, at zero torque, with no lost motion."""
    store = Store(tmp_path / "store")
    with SimulatedRig(PLANT, seed=3, sync_period_s=0.004, stream_rate_Hz=250.0) as sim:
        sim.backdoors["encoder"].stick()
        with open_session(rig=sim.rig_config_path) as session:
            engine, outcomes = measure_plan(session, store, PLAN, run_meta(UNIT, session))
        assert _drive_safe(sim)
    (outcome,) = outcomes
    assert engine.state == "aborted" and outcome.status == "aborted"
    assert "encoder" in outcome.reason and "frozen" in outcome.reason, outcome.reason
    run = read_run(outcome.path)
    assert run.meta["status"] == "aborted" and run.n_samples > 10
    assert (run.meta.get("result") or {}).get("lost_motion_arcmin") is None


def test_a_late_torque_channel_stops_the_run_instead_of_passing(tmp_path: Path):
    """Outside-probe row 7: the torque transducer's stream delayed 0.8 s from the start. The
    loop paired each twist with the torque of 0.8 s before and passed with a negative
    stiffness; the cross-check torque sensor, compared at the same instant, disagrees by
    more than 10 % of rated during the first ramp: the run stops, safe, incomplete."""
    store = Store(tmp_path / "store")
    with SimulatedRig(PLANT, seed=3, sync_period_s=0.004, stream_rate_Hz=250.0) as sim:
        sim.backdoors["transducer"].delay(0.8)
        with open_session(rig=sim.rig_config_path) as session:
            engine, outcomes = measure_plan(session, store, PLAN, run_meta(UNIT, session))
        assert _drive_safe(sim)
    (outcome,) = outcomes
    assert engine.state == "aborted" and outcome.status == "aborted", outcome.reason
    assert "cross-check torque sensor" in outcome.reason and "expected" in outcome.reason
    run = read_run(outcome.path)
    assert run.meta["outcome"] == "incomplete"
    assert (run.meta.get("result") or {}).get("stiffness_Nm_per_arcmin") is None
