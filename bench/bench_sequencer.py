"""The engine's overhead on the simulated rig (its own process, real protocols).

* ``sequencer_overhead_pct``: (wall time of a hysteresis run - the sum of its planned
  times) / the sum of its planned times, for the GB/T loop in equal torque steps with the
  settle steps left out (ramps at 25 N*m/s, 0.2 s dwell and 0.05 s sample per step: what the
  engine itself costs). Target: under 5 %.
* ``sequencer_overhead_with_settle_pct``: the same plan with its settle steps (twist rate
  below 2 arcmin/s held for 0.1 s): adds the time the unit takes to come to rest.
* ``engine_rows_per_s``: merged rows recorded per second of run (the encoder's rate).
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

from rig.measurement.service import measure_plan, open_session, plant_config_for, run_meta
from rig.plans import LoopParams, Plan, hysteresis_plan
from rig.plans.campaign_file import SimulationSection
from rig.plans.estimate import estimate
from rig.plans.steps import Settle
from rig.runformat import read_run
from rig.store import Store
from simulators.plant.config import load_plant_config

DRAG = {"effects": {"friction": {"enabled": True, "model": "lugre",
                                 "viscous_Nms_per_arcmin": 0.002}}}
LOOP = LoopParams(rated_torque_Nm=10.0, steps_per_quarter=4, dwell_s=0.2, sample_s=0.05,
                  pre_cycles=0, rate_Nm_per_s=25.0, zero_band_Nm=0.3, zero_rate_Nm_per_s=0.6)


def _without_settle(plan: Plan) -> Plan:
    return Plan("hysteresis-no-settle", plan.params,
                lambda: (s for s in plan.steps() if not isinstance(s, Settle)))


def _timed(session: Any, store: Store, plan: Plan) -> tuple[float, float, int, float]:
    """(wall s from the first step to the end, planned s, rows, run length s)."""
    unit = dict(load_plant_config().unit, serial="bench")
    marks: dict[str, float] = {}

    def on_event(event: Any) -> None:
        if event.kind == "step" and "first" not in marks:
            marks["first"] = time.monotonic()
        if event.kind == "finished":
            marks["end"] = time.monotonic()

    engine, outcomes = measure_plan(session, store, plan, run_meta(unit, session),
                                    progress=on_event)
    if engine.state != "completed":
        raise RuntimeError(f"bench run {engine.state}: {engine.stopping_reason}")
    run = read_run(outcomes[0].path)
    planned = estimate(plan.steps()).total_s
    return marks["end"] - marks["first"], planned, run.n_samples, float(run.t_s[-1])


def run() -> Iterator[dict[str, Any]]:
    import tempfile

    plant = plant_config_for(dict(load_plant_config().unit), SimulationSection(plant=DRAG))
    with tempfile.TemporaryDirectory() as tmp, open_session(simulated=True, plant=plant) as s:
        store = Store(tmp)
        plan = hysteresis_plan(LOOP)
        wall, planned, rows, length = _timed(s, store, _without_settle(plan))
        yield {"name": "sequencer_overhead_pct", "value": round(100 * (wall - planned) / planned,
               2), "unit": "%", "planned_s": round(planned, 3), "wall_s": round(wall, 3),
               "target": "< 5 %"}
        yield {"name": "engine_rows_per_s", "value": round(rows / length, 1), "unit": "rows/s",
               "encoder": "SYNC every 4 ms (simulated rig)"}
        wall, planned, _, _ = _timed(s, store, plan)
        yield {"name": "sequencer_overhead_with_settle_pct",
               "value": round(100 * (wall - planned) / planned, 2), "unit": "%",
               "planned_s": round(planned, 3), "wall_s": round(wall, 3)}
