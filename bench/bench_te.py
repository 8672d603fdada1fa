"""``python -m bench te``: the transmission error test (issue 22).

Analysis (``analysis_*``): 1,000,000 samples (a forward and a reverse output revolution of the
seed 000 pair) through :func:`analysis.transmission.analyse_te` (curves, figures, orders,
uncertainties; target 5 s), and the seed 000 model's Monte Carlo band of 1,000 units beside
it. The data are tests' synthetic TE (analysis.transmission.synthetic): the model's own curve
of a unit inside seed 000 Table 1, 2^23 / 2^17-count encoders, 0.2 arcsec noise.
``pp_error_arcsec``: measured minus true peak-to-peak. ``cpu_s`` and the load average before
the run tell a slow machine from a slow program.

Acquisition (``acquisition_*``): a whole TE run (seed 000 pair 1, 120 rpm of the input, one
output revolution each way, 3 N*m brake) through the real stack (the simulated rig in its own
process, CANopen over SLCAN, Modbus TCP, the serial transducer) at several SYNC periods. Per
period: the sample rate sustained while the input turns (rows with ``direction`` != 0 per
second), the samples lost (rows the SYNCs of that time should have given and the run does not
have: driver queues, merge drops, input samples of another SYNC), and the run's state.
``te_acquisition_max_rate_Hz`` is the highest rate with 0 samples lost.
``BENCH_TE_PERIODS`` (ms, comma-separated; default ``4,2,1``).
"""

from __future__ import annotations

import os
import resource
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from analysis.transmission import analyse_te
from analysis.transmission import model_internal as mi
from analysis.transmission.model import internal_prediction
from analysis.transmission.synthetic import synthetic_te
from bench.timing import timed
from rig.engine.devices import DevicesIO
from rig.hardware.config import load_rig_config
from rig.hardware.devices import open_rig
from rig.hardware.simrig import SimulatedRig
from rig.measurement.service import (
    RigSession,
    measure_plan,
    plant_config_for,
    relaxed_heartbeats,
    run_meta,
    write_plant_toml,
)
from rig.plans import TEParams, te_plan
from rig.plans.campaign_file import SimulationSection
from rig.runformat import read_run
from rig.store import Store
from simulators.plant.config import load_plant_config

UNIT = {"kind": "internal_involute", "z_internal": 45, "z_external": 40, "module_mm": 1.0,
        "runout_internal_mm": 0.018, "runout_external_mm": 0.012, "runout_phase_deg": 35.0}
TARGET_S = 5.0
MODEL_TARGET_S = 5.0


def analysis_speed() -> Iterator[dict]:
    """The analysis of 1M samples and the model band of 1,000 units (the analysis side)."""
    geo = mi.geometry_from_unit(UNIT)
    errors = mi.unit_errors(geo, UNIT)

    def te(out, inp, d):
        return mi.unit_curves(geo, errors, inp)[d][0]

    n_per_rev = 500_000
    s = synthetic_te(te, ratio=geo.ratio, revolutions=1.0, margin=0.0,
                     samples_per_output_rev=n_per_rev, noise_arcsec=0.2, turn_samples=0)
    truth = max(float(np.ptp(c)) for c in mi.unit_curves(
        geo, errors, mi.input_angles_deg(geo, per_mesh=16)).values())
    kin = geo.kinematics()
    w = synthetic_te(te, ratio=geo.ratio, samples_per_output_rev=5_000)
    analyse_te(w.output_angle_deg, w.input_angle_deg, w.direction, kin)  # warm up
    t = timed(lambda: analyse_te(s.output_angle_deg, s.input_angle_deg, s.direction, kin,
                                 output_counts_per_rev=2**23, input_counts_per_rev=2**17))
    result = t.result
    yield {"name": "te_analysis_1M_samples", **t.fields(),
           "target": TARGET_S, "ok": t.wall_s < TARGET_S, "samples": int(s.t_s.size),
           "pp_arcsec": round(result.metrics["te_pp_arcsec"], 2),
           "pp_error_arcsec": round(result.metrics["te_pp_arcsec"] - truth, 3),
           "peak_rss_MiB": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)}
    start = time.perf_counter()
    pred = internal_prediction(UNIT, samples=1000)
    elapsed = time.perf_counter() - start
    yield {"name": "te_model_band_1000_units", "value": round(elapsed, 3), "unit": "s",
           "target": MODEL_TARGET_S, "ok": elapsed < MODEL_TARGET_S,
           "band_pp_arcsec": [round(v, 1) for v in (pred.band or {})["te_pp_arcsec"]]}


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
