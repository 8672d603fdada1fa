"""Effect terms of analysis.effects against closed forms and the seed numbers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from analysis.effects import (
    EFFECTS,
    LoopParams,
    bearing_play_arcmin,
    bearing_soft_twist_arcmin,
    chain_torque_Nm,
    flank_sign,
    model_lost_motion_arcmin,
    predict_twist_arcmin,
    runout_basis,
    runout_center_distance_change_um,
    runout_play_change_arcmin,
    stiffening_twist_arcmin,
    tooth_pair_index,
    um_to_arcmin,
    worst_case_runout_play_arcmin,
)
from analysis.errors import AnalysisError

P, K = 4.2823, 27.86


def test_vocabulary_matches_run_format() -> None:
    assert list(EFFECTS) == [
        "backlash", "mesh_stiffness", "friction", "stiffness_nonlinearity", "runout",
        "bearing_clearance", "thermal_expansion", "torque_sensor_offset", "shaft_compliance",
        "tooth_spacing_error"]
    assert all(e.params and e.where_in_loop for e in EFFECTS.values())


def test_eq1_conversion_and_seed_budget_terms() -> None:
    # seed 000 eq. (1): 6.876 j / (m z1); 45 teeth, m = 1
    assert float(um_to_arcmin(45.0, 1.0, 45)) == pytest.approx(6.876)
    # bearings 5 + 6 um: 2 tan20 (2.5 + 3) um = 4.004 um -> 0.6118 arcmin (docs/plant.md 0.612)
    assert bearing_play_arcmin([0.005, 0.006], 20.0, 1.0, 45) == pytest.approx(0.6118, abs=2e-4)
    # Table 3 runout term 2 tan20 (22 + 15) / 2 um = 13.468 um -> 2.058 arcmin
    assert worst_case_runout_play_arcmin(0.022, 0.015, 20.0, 1.0, 45) == pytest.approx(
        6.876 * 2 * math.tan(math.radians(20)) * 18.5 / 45, rel=1e-12)


def test_stop_operator_is_coulomb_friction() -> None:
    torque = np.concatenate([np.linspace(0, 5, 51), np.linspace(5, -5, 101)])
    g = chain_torque_Nm(torque, 0.5, start_flank=-1)
    assert g[0] == pytest.approx(-0.5)  # came up from -T: friction opposed the rise
    assert np.allclose(g[10:51], torque[10:51] - 0.5)  # sliding up: G = T - F
    stuck = (torque[51:] > 4.0) & (torque[51:] < 5.0)  # after the reversal, 2 F of sticking
    assert np.allclose(g[51:][stuck], 4.5)
    assert np.allclose(g[-20:], torque[-20:] + 0.5)  # sliding down: G = T + F
    with pytest.raises(AnalysisError):
        chain_torque_Nm(torque, -1.0)


def test_flank_rule_with_noise_band() -> None:
    g = np.array([0.0, 0.01, 0.2, 0.0, -0.01, -0.3, 0.0])
    assert flank_sign(g, 0.0).tolist() == [-1, 1, 1, 1, -1, -1, -1]
    assert flank_sign(g, 0.05).tolist() == [-1, -1, 1, 1, 1, -1, -1]


def test_stiffening_and_bearing_terms() -> None:
    tau = np.array([0.0, 1e-6, 2.0, 1e3])
    s = stiffening_twist_arcmin(tau, 0.15, 2.0)
    assert s[0] == 0 and s[1] / 1e-6 == pytest.approx(0.15 / 2.0, rel=1e-5)  # slope d_s/T_s
    assert s[2] == pytest.approx(0.15 * (1 - math.exp(-1))) and s[3] == pytest.approx(0.15)
    b = bearing_soft_twist_arcmin(np.array([0.5, 1.0, 3.0]), 5.0, 1.0)
    assert b.tolist() == pytest.approx([0.1, 0.2, 0.2])


def test_runout_eq4_and_its_first_order_form() -> None:
    theta = np.linspace(0, 720, 97)
    exact = runout_center_distance_change_um(
        theta, center_distance_mm=2.5, internal_um=11.0, internal_phase_deg=30.0,
        external_um=7.5, beta_deg=-40.0, z_internal=45, z_external=40)
    b = runout_basis(theta, 45, 40)
    psi, beta = math.radians(30.0), math.radians(-40.0)
    lin = 11.0 * (b[:, 0] * math.cos(psi) + b[:, 1] * math.sin(psi)) + 7.5 * (
        b[:, 2] * math.cos(beta) + b[:, 3] * math.sin(beta))
    assert np.max(np.abs(exact - lin)) <= 18.5**2 / (2 * 2500.0)  # second order (e1+e2)^2/2a
    # eq. (5)/(6): extremes of |AB| are a +- (e1 + e2) when the phases line up
    peak = runout_center_distance_change_um(
        0.0, center_distance_mm=2.5, internal_um=11.0, internal_phase_deg=0.0,
        external_um=7.5, beta_deg=0.0, z_internal=45, z_external=40)
    assert float(peak) == pytest.approx(18.5, abs=1e-9)
    play = runout_play_change_arcmin(0.0, pressure_angle_deg=20.0, module_mm=1.0,
                                     z_internal=45, center_distance_mm=2.5, internal_um=11.0,
                                     internal_phase_deg=0.0, external_um=7.5, beta_deg=0.0,
                                     z_external=40)
    assert float(play) == pytest.approx(-um_to_arcmin(2 * math.tan(math.radians(20)) * 18.5,
                                                      1.0, 45))


def test_tooth_pair_index_steps_every_8_deg() -> None:
    assert tooth_pair_index(np.array([0.0, 7.99, 8.0, 359.9, 360.0]), 45).tolist() == [
        0, 0, 1, 44, 45]


def test_composed_loop_closed_forms() -> None:
    nominal = LoopParams(P, K)
    torque = np.array([0.0, 5.0, 10.0, 0.0, -10.0])
    twist = predict_twist_arcmin(nominal, torque)
    assert twist.tolist() == pytest.approx([-P / 2, P / 2 + 5 / K, P / 2 + 10 / K, P / 2,
                                            -P / 2 - 10 / K])
    # lost motion at +-3 % of 10 N*m: play + 2 (0.3) / K, with or without Coulomb friction
    assert model_lost_motion_arcmin(nominal, 10.0) == pytest.approx(P + 0.6 / K)
    assert model_lost_motion_arcmin(nominal.with_(friction_Nm=0.1), 10.0) == pytest.approx(
        P + 0.6 / K, rel=1e-9)
    # shaft compliance in series: 1/K + 1/K_s
    shaft = nominal.with_(shaft_stiffness_Nm_per_arcmin=60.0)
    assert shaft.compliance_arcmin_per_Nm == pytest.approx(1 / K + 1 / 60)
    # thermal: play + c (T - T_ref)
    warm = nominal.with_(thermal_arcmin_per_K=0.04, thermal_reference_C=20.0)
    assert model_lost_motion_arcmin(warm, 10.0, temperature_C=45.0) == pytest.approx(
        P + 1.0 + 0.6 / K)
    # a sensor offset moves the flank change to T = offset
    off = predict_twist_arcmin(nominal.with_(torque_offset_Nm=0.2), np.array([0.0, 0.1, 0.3]))
    assert off.tolist() == pytest.approx([-P / 2 - 0.2 / K, -P / 2 - 0.1 / K, P / 2 + 0.1 / K])
