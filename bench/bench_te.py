"""``python -m bench te``: the transmission error test.

Acquisition (``acquisition_*``): a whole TE run (seed 000 pair 1, 120 rpm of the input, one
output revolution each way, 3 N*m brake) through the real stack (``rig measure --simulated``:
the simulated rig in its own process, CANopen over SLCAN, Modbus TCP, the serial
transducer) at several SYNC periods. Per period: the sample rate sustained while the input
turns (rows with ``direction`` != 0 per second), the samples lost (rows the SYNCs of that
time should have given and the run does not have: driver queues, merge drops, input samples
of another SYNC), and the run's state. ``te_acquisition_max_rate_Hz`` is the highest rate
with 0 samples lost. ``BENCH_TE_PERIODS`` (ms, comma-separated; default ``4,2,1``).

The analysis of a TE run (``analysis_*``, analysis/transmission) adds its own rows here.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from rig.campaign import SimulationSection
from rig.config import load_rig_config
from rig.devices import open_rig
from rig.engine.devices import DevicesIO
from rig.measure import (
    RigSession,
    measure_plan,
    plant_config_for,
    relaxed_heartbeats,
    run_meta,
    write_plant_toml,
)
from rig.plans import TEParams, te_plan
from rig.runformat import read_run
from rig.simrig import SimulatedRig
from rig.store import Store
from simulators.plant.config import load_plant_config

PARAMS = TEParams(rated_torque_Nm=10.0, ratio=-8.0, input_speed_rpm=120.0,
                  brake_torque_fraction=0.3)
EFFECTS = {"kinematic_error": {"enabled": True},
           "tooth_spacing_error": {"enabled": True, "transition_fraction": 0.5}}


def _periods_s() -> list[float]:
    text = os.environ.get("BENCH_TE_PERIODS", "4,2,1")
    return [float(p) / 1000.0 for p in text.split(",") if p.strip()]


def _one_run(period_s: float, tmp: Path) -> dict[str, Any]:
    unit = dict(load_plant_config().unit, serial="bench-te")
    plant = plant_config_for(unit, SimulationSection(seed=1, plant={"effects": EFFECTS}))
    plant_toml = write_plant_toml(plant, tmp / "plant.toml")
    with SimulatedRig(plant_toml, in_process=False, rig_config_path=tmp / "rig.toml",
                      sync_period_s=period_s, stream_rate_Hz=min(1.0 / period_s, 1000.0)
                      ) as sim:
        config = relaxed_heartbeats(load_rig_config(sim.rig_config_path))
        with open_rig(config) as devices:
            session = RigSession(devices, DevicesIO(devices), sim.rig_config_path, sim, plant,
                                 2.0)
            engine, outcomes = measure_plan(session, Store(tmp / "store"), te_plan(PARAMS),
                                            run_meta(unit, session))
    run = read_run(outcomes[-1].path)
    d = run.data
    turning = d["direction"] != 0
    seconds = 0.0
    recorded = expected = 0
    for sign in (1, -1):
        t = d["t_s"][d["direction"] == sign]
        if t.size < 2:
            continue
        span = float(t[-1] - t[0])
        seconds += span
        recorded += int(t.size)
        expected += int(round(span / period_s)) + 1
    return {"sync_period_ms": period_s * 1000.0,
            "rate_Hz": recorded / seconds if seconds else 0.0,
            "lost": max(expected - recorded, 0),
            "dropped_reported": int(run.meta["result"].get("samples_dropped", 0)),
            "rows_turning": int(turning.sum()), "state": engine.state,
            "reason": engine.stopping_reason}


def acquisition_rate() -> Iterator[dict[str, Any]]:
    """The sample rate the acquisition sustains while the input turns, per SYNC period,
    and the highest with 0 samples lost."""
    best = 0.0
    for period in _periods_s():
        with tempfile.TemporaryDirectory(prefix="bench-te-") as tmp:
            row = _one_run(period, Path(tmp))
        ok = row["state"] == "completed" and row["lost"] == 0
        if ok:
            best = max(best, row["rate_Hz"])
        yield {"name": "te_acquisition_rate", "value": row["rate_Hz"], "unit": "Hz",
               **{k: v for k, v in row.items() if k != "rate_Hz"}}
    yield {"name": "te_acquisition_max_rate_Hz", "value": best, "unit": "Hz",
           "what": "highest sustained rate with 0 samples lost while the input turns"}


def run() -> Iterator[dict[str, Any]]:
    """Every ``acquisition_*`` and ``analysis_*`` benchmark of this module."""
    for name in sorted(globals()):
        fn = globals()[name]
        if name.startswith(("acquisition_", "analysis_")) and callable(fn):
            yield from fn()


if __name__ == "__main__":
    import json

    for item in run():
        print(json.dumps(item), flush=True)
