"""The other loading modes and a temperature step, end to end on the simulated rig."""

from __future__ import annotations

import pytest

from rig.engine import EngineOptions
from rig.measurement.service import measure_plan, open_session, plant_config_for, run_meta
from rig.plans import CampaignAxes, LoopParams, campaign_plan, hysteresis_plan
from rig.plans.campaign_file import SimulationSection
from rig.store import Store
from simulators.clock import ManualClock
from simulators.plant import GearPlant
from simulators.plant.config import load_plant_config

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

DRAG = {"effects": {"friction": {"enabled": True, "model": "lugre", "coulomb_torque_Nm": 0.02,
                                 "static_torque_Nm": 0.03, "viscous_Nms_per_arcmin": 0.002}}}
UNIT = dict(load_plant_config().unit, serial="modes-unit")
PLANT = plant_config_for(UNIT, SimulationSection(plant=DRAG))
BASE = LoopParams(rated_torque_Nm=10.0, extra_levels_pct=[3.0], dwell_s=0.0, pre_cycles=0,
                  zero_band_Nm=0.3, zero_rate_Nm_per_s=0.6, rate_Nm_per_s=10.0,
                  twist_step_arcmin=1.0)


@pytest.fixture(scope="module")
def session():
    with open_session(simulated=True, plant=PLANT) as s:
        yield s


@pytest.mark.parametrize("mode", ["equal_position", "constant_rate"])
def test_loading_modes_measure_the_true_lost_motion(session, tmp_path, mode) -> None:
    plan = hysteresis_plan(BASE.model_copy(update={"mode": mode}))
    engine, (outcome,) = measure_plan(
        session, Store(tmp_path), plan, run_meta(UNIT, session),
        options=EngineOptions(stale_timeout_s=session.stale_timeout_s))
    assert engine.state == "completed"
    out = outcome.to_dict()
    truth = GearPlant(PLANT, clock=ManualClock()).true_lost_motion_arcmin(10.0, 3.0)
    u = out["uncertainty"]["lost_motion_arcmin"]
    print(f"\n{mode}: lost motion {out['lost_motion_arcmin']:.4f} +- {u:.4f}, true {truth:.4f}")
    assert abs(out["lost_motion_arcmin"] - truth) <= 3 * u + 0.02
    assert outcome.test["loading"]["mode"] == mode


def test_a_temperature_step_waits_for_the_housing(session, tmp_path) -> None:
    axes = CampaignAxes(positions_deg=[30.0], temperatures_C=[20.0],
                        temperature_tolerance_C=1.0, temperature_timeout_s=30.0)
    plan = campaign_plan(BASE.model_copy(update={"mode": "constant_rate", "amplitude_pct": 30}),
                         axes)
    engine, (outcome,) = measure_plan(
        session, Store(tmp_path), plan, run_meta(UNIT, session),
        options=EngineOptions(stale_timeout_s=session.stale_timeout_s))
    assert engine.state == "completed"
    assert outcome.test["temperature_setpoint_C"] == 20.0
    assert abs(outcome.test["temperature_C"] - 20.0) <= 1.0
    assert outcome.test["input_angle_deg"] == 30.0
    assert session.io.devices.input_motor.state().angle_deg == pytest.approx(30.0, abs=0.01)
