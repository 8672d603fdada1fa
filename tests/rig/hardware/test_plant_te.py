"""The plant in a transmission error run: the input turned at constant speed, the unit's
kinematic error (seed 000 eq. 4 eccentricities, tooth pitch deviations), the output encoder's
mounting eccentricity, and the truth (``GearPlant.true_transmission_error``) checked against
closed forms and against the time-domain plant itself. The input motor's constant-speed mode
over Modbus (simulated motor, the real driver)."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from drivers.errors import DeviceFault, DeviceOutOfRange
from rig.hardware.config import load_rig_config
from rig.hardware.devices import open_rig
from rig.hardware.simrig import SimulatedRig
from simulators.clock import ManualClock
from simulators.plant import GearPlant
from simulators.plant.config import PlantConfigError, load_plant_config

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

ARCSEC_PER_DEG = 3600.0


def _eq1_arcsec(um: float) -> float:
    """Seed 000 eq. (1) for pair 1 (m = 1, z_internal = 45): um -> arcsec."""
    return 60.0 * 6.876 * um / 45.0


def test_eccentricities_give_orders_ratio_and_ratio_plus_one_with_their_sizes():
    config = load_plant_config().nominal().with_effect("kinematic_error", beta_deg=30.0,
                                                       internal_phase_deg=-50.0)
    truth = GearPlant(config, ManualClock()).true_transmission_error(5.0)
    fwd = {o["order"]: o for o in truth["te_orders"] if o["direction"] == "forward"}
    # ring |AO1| = F_r,int / 2 = 11 um at order 8, pinion |BO2| = 7.5 um at order 9
    assert fwd[8]["amplitude_arcsec"] == pytest.approx(_eq1_arcsec(11.0), rel=1e-6)
    assert fwd[9]["amplitude_arcsec"] == pytest.approx(_eq1_arcsec(7.5), rel=1e-6)
    # e sin(k theta_out + phase) = e cos(k theta_out + phase - 90 deg)
    assert fwd[8]["phase_deg"] == pytest.approx(-50.0 - 90.0, abs=1e-6)
    assert fwd[9]["phase_deg"] == pytest.approx(30.0 - 90.0, abs=1e-6)
    # two sines of different orders: peak-to-peak at most twice the sum of the amplitudes
    assert truth["te_pp_arcsec"] <= 2 * (_eq1_arcsec(11.0) + _eq1_arcsec(7.5)) + 1e-6
    assert truth["te_pp_arcsec"] > 2 * _eq1_arcsec(11.0)


def test_hysteresis_truth_is_the_play_plus_twice_the_elastic_twist():
    config = load_plant_config().nominal()
    plant = GearPlant(config, ManualClock())
    params = plant.true_parameters()
    truth = plant.true_transmission_error(4.0)
    expected = params["play_arcmin"] + 2 * 4.0 / params["stiffness_Nm_per_arcmin"]
    assert truth["te_hysteresis_arcmin"] == pytest.approx(expected, rel=1e-9)
    assert truth["te_pp_arcsec"] == pytest.approx(0.0, abs=1e-9)  # a perfect unit


def _turn_and_record(plant: GearPlant, clock: ManualClock, speed_deg_s: float,
                     seconds: float, dt: float = 0.001) -> tuple[np.ndarray, np.ndarray]:
    plant.turn_input(speed_deg_s)
    inp, out = [], []
    for _ in range(int(round(seconds / dt))):
        clock.advance(dt)
        snap = plant.snapshot()
        inp.append(snap.input_angle_deg)
        out.append(snap.output_angle_deg)
    plant.stop_input()
    return np.array(inp), np.array(out)


def test_the_turning_plant_follows_its_truth_under_a_brake_torque():
    config = (load_plant_config().with_effect("kinematic_error")
              .with_effect("tooth_spacing_error", transition_fraction=0.5)
              .with_changes(noise={"twist_arcsec_rms": 0.0, "torque_Nm_rms": 0.0}))
    clock = ManualClock()
    plant = GearPlant(config, clock)
    truth = plant.true_transmission_error(3.0)
    plant.command_torque(3.0)  # forward: the output turns negative, the brake pushes it +
    clock.advance(0.2)
    plant.snapshot()
    speed = 720.0  # deg/s: one output revolution (8 input turns) in 4 s
    inp, out = _turn_and_record(plant, clock, speed, 4.2)
    assert np.diff(inp) == pytest.approx(speed * 0.001)
    te = ARCSEC_PER_DEG * (out + inp / 8.0)  # run-format: ratio -8
    keep = (inp >= 20.0) & (inp < 2880.0)  # one output revolution, after the start
    te = te[keep]
    measured_pp = te.max() - te.min()
    assert measured_pp == pytest.approx(truth["te_pp_forward_arcsec"], rel=0.03)
    # a step at each pitch boundary instead: the output leaves the flank (the brake's 3 N*m
    # cannot pull the inertia after the step) and hits it again, far beyond the truth
    stepped = config.with_effect("tooth_spacing_error", transition_fraction=0.0)
    clock = ManualClock()
    plant = GearPlant(stepped, clock)
    plant.command_torque(3.0)
    clock.advance(0.2)
    inp, out = _turn_and_record(plant, clock, speed, 4.2)
    te = ARCSEC_PER_DEG * (out + inp / 8.0)
    keep = (inp >= 20.0) & (inp < 2880.0)
    assert te[keep].max() - te[keep].min() > 1.1 * truth["te_pp_forward_arcsec"]


def test_encoder_eccentricity_is_a_reading_error_once_per_output_turn():
    config = load_plant_config().nominal().with_changes(
        rig={"encoder_eccentricity_arcsec": 20.0, "encoder_eccentricity_phase_deg": 40.0})
    clock = ManualClock()
    plant = GearPlant(config, clock)
    inp, out = _turn_and_record(plant, clock, 1440.0, 2.0)
    nominal = -inp / 8.0
    twist = out - nominal
    err = ARCSEC_PER_DEG * (twist - np.median(twist))
    expected = 20.0 * np.sin(np.radians(nominal) + math.radians(40.0))
    expected -= np.median(expected)
    assert np.max(np.abs(err - expected)) < 1.5
    truth = plant.true_transmission_error(1.0)
    assert truth["encoder_eccentricity"]["amplitude_arcsec"] == 20.0
    assert truth["te_pp_arcsec"] == pytest.approx(0.0, abs=1e-9)  # not the unit's TE


def test_plant_config_keys_are_checked():
    config = load_plant_config()
    with pytest.raises(PlantConfigError, match="rig.encoder_eccentricity_arcsec"):
        config.with_changes(rig={"encoder_eccentricity_arcsec": -1.0})
    with pytest.raises(PlantConfigError, match="effects.kinematic_error.internal_um"):
        config.with_effect("kinematic_error", internal_um=-3.0)


@pytest.fixture(scope="module")
def sim():
    with SimulatedRig(None, in_process=True) as rig:
        yield rig


def test_input_motor_turns_at_speed_and_stops_over_modbus(sim):
    with open_rig(load_rig_config(sim.rig_config_path)) as devices:
        motor = devices.input_motor
        start = motor.state().angle_deg
        motor.turn_at(30.0)  # 180 deg/s
        time.sleep(0.5)
        st = motor.state()
        assert st.turning and not st.locked
        assert st.speed_rpm == pytest.approx(30.0)
        assert st.angle_deg - start > 45.0
        motor.stop()
        time.sleep(0.1)
        st = motor.state()
        assert st.locked and not st.turning and st.speed_rpm == 0.0
        held = st.angle_deg
        time.sleep(0.2)
        assert motor.state().angle_deg == pytest.approx(held)
        # reverse
        motor.turn_at(-30.0)
        time.sleep(0.3)
        assert motor.state().angle_deg < held
        motor.stop()


def test_input_motor_refuses_speeds_beyond_its_range(sim):
    with open_rig(load_rig_config(sim.rig_config_path)) as devices:
        motor = devices.input_motor
        with pytest.raises(DeviceOutOfRange, match="3000 rpm"):
            motor.turn_at(5000.0)
        # another master writing it anyway gets a Modbus exception from the device
        motor.config = motor.config.model_copy(update={"max_speed_rpm": 1e6})
        with pytest.raises(DeviceFault, match="ILLEGAL_VALUE"):
            motor.turn_at(5000.0)
        assert not motor.state().turning


def test_stall_backdoor_stops_the_shaft_while_the_motor_reports_turning(sim):
    with open_rig(load_rig_config(sim.rig_config_path)) as devices:
        motor = devices.input_motor
        motor.turn_at(20.0)
        sim.modbus_server.input_motor.stall()
        try:
            time.sleep(0.1)
            a = motor.state()
            time.sleep(0.2)
            b = motor.state()
            assert b.turning and b.angle_deg == pytest.approx(a.angle_deg)
            assert b.speed_rpm == 0.0
        finally:
            sim.modbus_server.input_motor.stall(False)
            motor.stop()
