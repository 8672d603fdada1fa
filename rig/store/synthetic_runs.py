"""Synthetic campaigns written into a store: a stand-in rig for tests, benchmarks and demos.

Each run is the run format's reference loop (:func:`analysis.loop.synthetic.dead_zone_twist`:
free play plus a linear spring) over a triangle torque profile, so its metrics are known in
closed form: backlash = ``play_arcmin``, stiffness = ``stiffness_Nm_per_arcmin``, lost motion
= play + 2 p T_r / K at the ±p % band (p = 3 %, the "nabtesco" profile). These are made-up
data written through the ordinary :class:`rig.store.Store` API, never a measurement.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from analysis.loop.synthetic import dead_zone_twist, triangle_profile
from rig.results.outcome import LIMIT_KEYS, campaign_outcome, run_outcome
from rig.store import Store

COLUMNS = ["t_s", "torque_Nm", "output_angle_deg"]
LOST_MOTION_PCT = 3.0


def closed_form_metrics(play_arcmin: float, stiffness_Nm_per_arcmin: float,
                        rated_torque_Nm: float, pct: float = LOST_MOTION_PCT) -> dict[str, float]:
    """Lost motion, backlash (arcmin) and stiffness (N·m/arcmin) of the dead-zone loop."""
    return {
        "lost_motion_arcmin": play_arcmin + 2.0 * pct / 100.0 * rated_torque_Nm
        / stiffness_Nm_per_arcmin,
        "backlash_arcmin": play_arcmin,
        "stiffness_Nm_per_arcmin": stiffness_Nm_per_arcmin,
    }


def loop_samples(play_arcmin: float, stiffness_Nm_per_arcmin: float, rated_torque_Nm: float,
                 n_quarter: int = 1000, dt_s: float = 0.001) -> np.ndarray:
    """Rows (t_s, torque_Nm, output_angle_deg) of one cycle, no sample at exactly 0 N·m.
    With the default 1000 steps per quarter the loop analysis recovers every closed-form
    metric; fewer steps give lost motion only (down to about 100)."""
    torque = triangle_profile(rated_torque_Nm, n_quarter, cycles=1, phase=0.5)
    twist = dead_zone_twist(torque, play_arcmin, stiffness_Nm_per_arcmin)
    t = np.arange(torque.size) * dt_s
    return np.column_stack([t, torque, twist / 60.0])


def write_campaign(
    store: Store,
    serial: str,
    *,
    play_arcmin: float | list[float] = 2.0,
    stiffness_Nm_per_arcmin: float = 30.0,
    rated_torque_Nm: float = 10.0,
    positions_deg: tuple[float, ...] = (0.0, 180.0),
    n_quarter: int = 1000,
    design: str = "SYN-1",
    limits: dict[str, float] | None = None,
    unit_data: dict[str, Any] | None = None,
    run_seconds: float = 0.0,
    on_run: Any = None,
) -> str:
    """Write one campaign of ``len(positions_deg)`` runs for unit ``serial``; its id.

    ``play_arcmin``: one value, or one per position. ``run_seconds``: about how long each
    run takes (rows paced like a rig's, in 20 bursts). ``on_run(run_id)`` is called after
    each finished run. ``unit_data``: design data of the unit (a run.json ``unit``, e.g.
    rig/examples/units/seed000-pair1.json) kept with serial and design in the metadata.
    Each run's result holds the closed-form metrics; the campaign's meta and every run.json
    the ``limits`` (every key, None = not checked), and each run.json, campaign.json and the
    campaign's summary the ``outcome`` against them (rig/results/outcome.py), as a measured campaign
    records them.
    """
    plays = play_arcmin if isinstance(play_arcmin, list) else [play_arcmin] * len(positions_deg)
    unit = {**(unit_data or {}), "serial": serial, "design": design}
    in_force = {key: (limits or {}).get(key) for key in LIMIT_KEYS}
    campaign_id = store.create_campaign(
        f"{design}-{serial}",
        {"unit": unit, "limits": limits or {}, "profile": "nabtesco",
         "synthetic": "rig.store.synthetic_runs: dead-zone loop, not a measurement"})
    outcomes, failures = [], []
    for angle, play in zip(positions_deg, plays, strict=True):
        meta = {"unit": unit, "operator": "synthetic", "rig_id": f"rig-{serial}",
                "test": {"rated_torque_Nm": rated_torque_Nm, "input_angle_deg": angle},
                "profile": "nabtesco", "limits": in_force}
        with store.begin_run(meta, COLUMNS, campaign_id=campaign_id) as rec:
            rows = loop_samples(play, stiffness_Nm_per_arcmin, rated_torque_Nm, n_quarter)
            burst = max(1, len(rows) // 20)
            for i, row in enumerate(rows.tolist()):
                rec.append(row)
                if run_seconds and i % burst == burst - 1:
                    time.sleep(run_seconds / 20)
            result = closed_form_metrics(play, stiffness_Nm_per_arcmin, rated_torque_Nm)
            outcome, causes, _ = run_outcome(
                {"status": "completed", "label": f"pos{angle:03.0f}", "test": meta["test"],
                 "result": result}, in_force)
            outcomes.append(outcome)
            failures += causes
            rec.finish(result=result, extra={"outcome": outcome})
        if on_run is not None:
            on_run(rec.run_id)
    outcome = campaign_outcome(outcomes, "completed")
    store.finish_campaign(campaign_id, "completed",
                          {"n_runs": len(positions_deg), "limits": in_force,
                           "outcome": outcome, "failures": failures,
                           "passed": outcome in ("ok", "no_limits")},
                          extra={"outcome": outcome})
    return campaign_id
