"""The rig's dynamics and the measuring system's artefacts in the plant (docs/plant.md):
impacts that ring at the locked resonance and bounce, drive ripple, the torque sensor's lag,
its ADC grid and a torque zero re-tared at each drive enable that then random-walks.

Closed forms: a mass J hitting a linear flank of stiffness K at speed v rings with torque
amplitude ``v sqrt(J K)`` at ``omega = sqrt(K / J)`` (energy balance ``J v^2 / 2 = G^2 /
2K``); a first-order lag reaches ``1 - exp(-t / tau)`` of a step; a random walk of ``s`` per
sqrt(s) has a variance ``s^2 t``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from simulators.clock import ManualClock
from simulators.plant import GearPlant
from simulators.plant.config import PlantConfigError, load_plant_config
from simulators.plant.model import PlantModel


def _base(**rig):
    cfg = load_plant_config().nominal()
    return cfg.with_changes(rig={"drive_time_constant_s": 0.01, **rig})


def _inertia_for(f_Hz: float) -> float:
    k = 1.0 / PlantModel(_base()).compliance.c_lin
    return k / (2.0 * math.pi * f_Hz) ** 2


def _cross_the_play(model: PlantModel, torque_Nm: float = 1.0, dt: float = 1e-4,
                    steps: int = 3000):
    """From rest on the -1 flank, command +torque: (time, flange torque, chain torque,
    velocity just before the first contact)."""
    model.command_Nm = -1.0
    for _ in range(3000):
        model.step(1e-3)
    model.command_Nm = torque_Nm
    t, g, chain, v_hit = [], [], [], None
    for i in range(steps):
        v_before, free_before = model.velocity, model.chain_Nm <= 0.0
        model.step(dt)
        if v_hit is None and free_before and model.chain_Nm > 0.0:
            v_hit = v_before
        t.append(i * dt)
        g.append(model.flange_Nm)
        chain.append(model.chain_Nm)
    return np.array(t), np.array(g), np.array(chain), v_hit


def test_an_impact_rings_at_the_locked_resonance_with_the_energy_it_brought():
    f, zeta = 600.0, 0.05
    model = PlantModel(_base(inertia_kgm2=_inertia_for(f), contact_damping_ratio=zeta))
    t, g, chain, v_hit = _cross_the_play(model)
    assert v_hit is not None and v_hit > 0.0 and model.impacts >= 1
    k = 1.0 / model.compliance.c_lin
    peak = g.max()
    expected = v_hit * math.sqrt(model.inertia * k)  # energy balance, plus the drive's 1 N*m
    assert expected * 0.8 < peak < expected * 1.2 + 1.0
    # the first contact lasts half a period of the locked resonance (then it bounces off)
    first = np.flatnonzero(chain > 0.0)[0]
    leaves = first + np.flatnonzero(chain[first:] <= 0.0)[0]
    half_period = 0.5 / (f * math.sqrt(1.0 - zeta ** 2))
    assert t[leaves] - t[first] == pytest.approx(half_period, rel=0.25)
    # it settles on the flank at the drive's torque
    assert g[-1] == pytest.approx(1.0, abs=0.01)


def test_more_contact_damping_bounces_less():
    bounces = {}
    for zeta in (0.03, 0.15):
        model = PlantModel(_base(inertia_kgm2=_inertia_for(800.0), contact_damping_ratio=zeta))
        _, _, chain, _ = _cross_the_play(model)
        in_contact = chain > 0.0
        bounces[zeta] = int(np.sum(in_contact[1:] & ~in_contact[:-1]))
    assert bounces[0.03] > bounces[0.15] >= 1


def test_without_contact_damping_the_flank_is_the_implicit_step_as_before():
    model = PlantModel(_base())
    _, g, chain, _ = _cross_the_play(model, dt=1e-3, steps=300)
    assert model.impacts == 0
    assert g[-1] == pytest.approx(1.0, abs=0.01)


def test_drive_ripple_reaches_the_flange_at_its_frequency():
    cfg = _base(drive_ripple_Nm=0.02, drive_ripple_Hz=50.0)
    model = PlantModel(cfg)
    model.command_Nm = 5.0
    for _ in range(500):
        model.step(1e-3)
    g = []
    for _ in range(1000):
        model.step(1e-3)
        g.append(model.flange_Nm)
    g = np.array(g) - np.mean(g)
    spectrum = np.abs(np.fft.rfft(g))
    freqs = np.fft.rfftfreq(len(g), 1e-3)
    assert freqs[np.argmax(spectrum)] == pytest.approx(50.0, abs=1.0)
    # below the locked resonance the flange carries the ripple nearly whole
    assert 0.015 < 0.5 * (g.max() - g.min()) < 0.03


def _plant(**measurement) -> tuple[GearPlant, ManualClock]:
    cfg = load_plant_config().nominal().with_changes(measurement=measurement)
    clock = ManualClock()
    return GearPlant(cfg, clock), clock


def test_the_torque_sensor_lags_first_order_on_its_adc_grid():
    tau = 0.005
    plant, clock = _plant(torque_lag_s=tau, torque_adc_bits=16, torque_adc_full_scale_Nm=20.0)
    plant.command_torque(5.0)
    clock.advance(1.0)
    start = plant.snapshot()
    assert start.torque_Nm == pytest.approx(5.0, abs=1e-3)
    plant.command_torque(8.0)  # the flange follows the drive's 10 ms loop; the sensor lags it
    lsb = 40.0 / 2 ** 16
    lags = []
    for _ in range(60):
        clock.advance(0.001)
        s = plant.snapshot()
        assert s.torque_Nm / lsb == pytest.approx(round(s.torque_Nm / lsb), abs=1e-6)
        lags.append(s.true_torque_Nm - s.torque_Nm)
    assert max(lags) > 0.1  # the reading trails the flange by a visible amount ...
    clock.advance(0.2)
    s = plant.snapshot()
    assert abs(s.torque_Nm - s.true_torque_Nm) <= lsb  # ... and catches up with it


def test_the_torque_zero_is_retared_at_each_enable_and_then_walks():
    plant, clock = _plant(torque_zero_residual_Nm=0.01, torque_zero_walk_Nm_per_sqrt_s=0.002)
    zeros, drifts = [], []
    for _ in range(40):
        plant.enable_drive(False)
        clock.advance(0.5)
        plant.enable_drive(True)
        zeros.append(plant.snapshot().torque_Nm - plant.snapshot().true_torque_Nm)
        clock.advance(4.0)
        s = plant.snapshot()
        drifts.append(s.torque_Nm - s.true_torque_Nm - zeros[-1])
    zeros, drifts = np.array(zeros), np.array(drifts)
    assert 0.005 < zeros.std() < 0.02  # a new residual each time, 0.01 N*m rms
    assert 0.002 < drifts.std() < 0.008  # the walk: 0.002 * sqrt(4 s) = 0.004 N*m rms


def test_bad_dynamics_keys_name_the_key():
    with pytest.raises(PlantConfigError, match="rig.contact_damping_ratio"):
        load_plant_config().with_changes(rig={"contact_damping_ratio": 1.5})
    with pytest.raises(PlantConfigError, match="measurement.torque_adc_bits"):
        load_plant_config().with_changes(measurement={"torque_adc_bits": -3})
