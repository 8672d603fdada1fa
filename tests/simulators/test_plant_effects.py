"""Each switchable effect of the plant, alone, changes the loop as its signature says.

Loops are simulated offline (noise off, 23-bit quantisation on) with a slow triangle
0 -> +10 -> -10 -> 0 N*m and measured by straight-line fits of the branches; the expected
numbers come from closed forms (seed 000 eqs. 1, 3, 4, 7; series springs; first-order lags).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from analysis.models.seed000_geometry import runout_center_distance_mm
from simulators.clock import ManualClock
from simulators.offline import simulate_run
from simulators.plant import GearPlant
from simulators.plant.config import load_plant_config
from simulators.plant.geometry import MeshGeometry

TAN_A = math.tan(math.radians(20.0))
K_MESH = 27.85975  # N*m/arcmin, seed 004 eq. (8) for the seed pair (test_plant checks it)
PLAY = 4.2823282  # arcmin, reference nominal model for Table 2 pair 1


def arcmin(j_t_um: float) -> float:
    """Seed 000 eq. (1) for m = 1, z_internal = 45."""
    return 6.876 * j_t_um / 45.0


def triangle(t: float, amplitude: float = 10.0, period: float = 20.0) -> float:
    p = (t % period) / period
    if p < 0.25:
        return 4 * amplitude * p
    return amplitude * (2 - 4 * p) if p < 0.75 else amplitude * (4 * p - 4)


def run_loop(config, **kwargs) -> dict:
    kwargs.setdefault("duration_s", 20.0)
    return simulate_run(config, triangle, sample_rate_Hz=250, **kwargs)


def twist(run: dict) -> np.ndarray:
    return (run["output_angle_deg"] + run["input_angle_deg"] / 8.0) * 60.0


def line(run: dict, side: int, lo: float, hi: float, loading: bool | None = None):
    """(stiffness, intercept) of the samples with side * T in (lo, hi) on one branch."""
    torque = run["torque_Nm"]
    sel = (side * torque > lo) & (side * torque < hi)
    if loading is not None:
        sel &= (np.gradient(run["torque_command_Nm"]) > 0) == loading
    slope, intercept = np.polyfit(torque[sel], twist(run)[sel], 1)
    return 1.0 / slope, intercept


def play_of(run: dict, lo: float = 2.0, hi: float = 9.0) -> float:
    return line(run, 1, lo, hi)[1] - line(run, -1, lo, hi)[1]


@pytest.fixture(scope="module")
def nominal():
    return load_plant_config().nominal()


@pytest.mark.parametrize("params", [
    {"model": "dahl", "coulomb_torque_Nm": 0.5},
    {"model": "lugre", "coulomb_torque_Nm": 0.4, "static_torque_Nm": 0.5},
])
def test_friction_separates_the_branches_at_every_torque(nominal, params):
    level = 0.5  # slow sliding: Dahl's Coulomb level, LuGre's static level
    config = nominal.with_effect("friction", **params)
    run = run_loop(config)
    expected = 2 * level / K_MESH  # unloading lies above loading by 2 F / K
    for side in (1, -1):
        for lo, hi in ((2.0, 4.0), (4.0, 6.0), (6.0, 8.5)):
            _, up = line(run, side, lo, hi, loading=True)
            _, down = line(run, side, lo, hi, loading=False)
            assert down - up == pytest.approx(expected, rel=0.05), (side, lo)
    plant = GearPlant(config, ManualClock())
    assert plant.true_parameters()["friction_torque_Nm"] == level


def test_runout_ring_alone_changes_play_once_per_revolution(nominal):
    config = nominal.with_effect("runout", internal_mm=0.022, external_mm=0.0)
    geo = MeshGeometry.from_config(config)
    angles = np.linspace(0.0, 720.0, 721)
    plays = np.array([geo.runout_play_um(a) for a in angles])
    # one cycle per revolution: the fit by cos/sin of theta explains everything
    basis = np.column_stack([np.ones_like(angles), np.cos(np.radians(angles)),
                             np.sin(np.radians(angles))])
    coef, *_ = np.linalg.lstsq(basis, plays, rcond=None)
    assert np.max(np.abs(basis @ coef - plays)) < 0.01
    assert math.hypot(coef[1], coef[2]) == pytest.approx(2 * TAN_A * 22.0 / 2, rel=0.001)
    # measured loops at the largest (0 deg) and smallest (180 deg) center distance
    low = play_of(run_loop(config, input_angle_deg=0.0))
    high = play_of(run_loop(config, input_angle_deg=180.0))
    assert high - low == pytest.approx(arcmin(2 * TAN_A * 22.0), abs=0.003)
    assert low == pytest.approx(PLAY - arcmin(TAN_A * 22.0), abs=0.003)


def test_runout_both_gears_over_the_period_of_eq4(nominal):
    config = nominal.with_effect("runout")  # unit: F_r = 0.022 and 0.015 mm
    geo = MeshGeometry.from_config(config)
    angles = np.linspace(0.0, 8 * 360.0, 50001)  # period of eq. (4): 8 crank turns for 45/40
    plays = np.array([geo.runout_play_um(a) for a in angles])
    bound = 2 * TAN_A * (22.0 + 15.0)  # peak to peak of 2 tan(a) (de1 + de2) sin(phi), eq. 7
    assert 0.98 * bound < plays.max() - plays.min() <= bound
    # the plant's |AB| is seed 000 eq. (4) as implemented in analysis.models.seed000_geometry
    theta = np.radians(angles[:500])
    ab = runout_center_distance_mm(theta, eccentric_distance_mm=2.5,
                                   eccentricity_internal_mm=0.011,
                                   eccentricity_external_mm=0.0075, z_internal=45, z_external=40)
    mine = np.array([geo.center_distance_mm(a) for a in angles[:500]])
    assert np.max(np.abs(ab - mine)) < 1e-12
    measured = play_of(run_loop(config, input_angle_deg=500.0))
    plant = GearPlant(config.with_changes(rig={"initial_input_angle_deg": 500.0}), ManualClock())
    assert measured == pytest.approx(plant.true_parameters()["play_arcmin"], abs=0.003)


def test_thermal_expansion_changes_play_linearly(nominal):
    config = nominal.with_effect("thermal_expansion", coefficient_um_per_K=0.25)
    plays = [play_of(run_loop(config, temperature_C=t)) for t in (20.0, 40.0, 60.0)]
    step = arcmin(0.25 * 20.0)
    assert plays[0] == pytest.approx(PLAY, abs=0.003)
    assert plays[1] - plays[0] == pytest.approx(step, abs=0.003)
    assert plays[2] - plays[1] == pytest.approx(step, abs=0.003)
    # and through the housing's first-order response in real time
    clock = ManualClock()
    plant = GearPlant(config.with_changes(housing={"time_constant_s": 60.0}), clock)
    plant.set_ambient_temperature(60.0)
    clock.advance(60.0)
    p = plant.true_parameters()
    assert p["temperature_C"] == pytest.approx(60.0 - 40.0 / math.e, abs=1e-6)
    assert p["play_arcmin"] == pytest.approx(PLAY + arcmin(0.25 * (p["temperature_C"] - 20)),
                                             abs=1e-4)


def test_torque_sensor_offset_shifts_the_loop_in_torque(nominal):
    offset = 1.0
    base = run_loop(nominal)
    shifted = run_loop(nominal.with_effect("torque_sensor_offset", offset_Nm=offset))
    assert play_of(shifted) == pytest.approx(play_of(base), abs=0.002)
    for side in (1, -1):
        k, b0 = line(base, side, 2.0, 8.5)
        _, b1 = line(shifted, side, 2.5, 8.5)
        assert b1 - b0 == pytest.approx(-offset / K_MESH, abs=0.002)
    assert np.allclose(shifted["torque_Nm"] - shifted["true_torque_Nm"], offset)


def test_shaft_compliance_lowers_stiffness_by_the_series_formula(nominal):
    run = run_loop(nominal.with_effect("shaft_compliance", stiffness_Nm_per_arcmin=60.0))
    series = 1.0 / (1.0 / K_MESH + 1.0 / 60.0)
    for side in (1, -1):
        assert line(run, side, 2.0, 9.0)[0] == pytest.approx(series, rel=0.005)
    assert play_of(run) == pytest.approx(PLAY, abs=0.003)


def test_bearing_clearance_adds_play_with_a_softer_stage(nominal):
    config = nominal.with_effect("bearing_clearance", soft_stiffness_Nm_per_arcmin=5.0,
                                 soft_stage_torque_Nm=1.0)
    run = run_loop(config)
    extra = arcmin(2 * TAN_A * (5.0 + 6.0) / 2)  # eq. (7): de = u_r / 2 for each bearing
    plant = GearPlant(config, ManualClock())
    p = plant.true_parameters()
    assert p["play_arcmin"] == pytest.approx(PLAY + extra, rel=1e-7)
    soft = 1.0 / (1.0 / K_MESH + 1.0 / 5.0)
    for side in (1, -1):
        assert line(run, side, 0.15, 0.9)[0] == pytest.approx(soft, rel=0.03)
        assert line(run, side, 2.0, 9.0)[0] == pytest.approx(K_MESH, rel=0.005)
    # flanks extrapolated from high torque: play plus both soft stages
    assert play_of(run) == pytest.approx(PLAY + extra + 2 * 1.0 / 5.0, abs=0.003)
    assert p["apparent_play_arcmin"] == pytest.approx(play_of(run), abs=0.003)
    # the dead zone itself: low-torque lines extrapolated to zero
    dead = line(run, 1, 0.15, 0.9)[1] - line(run, -1, 0.15, 0.9)[1]
    assert dead == pytest.approx(PLAY + extra, abs=0.01)


def test_tooth_spacing_error_changes_play_from_tooth_to_tooth(nominal):
    thick_int = [0.0] * 45
    thick_int[1], thick_int[2] = 3.0, -2.0
    thick_ext = [0.0] * 40
    thick_ext[1] = 1.0
    pitch_int = [0.0] * 45
    pitch_int[2] = 2.0
    config = nominal.with_effect(
        "tooth_spacing_error", thickness_internal_um=thick_int, thickness_external_um=thick_ext,
        pitch_internal_um=pitch_int, pitch_external_um=[0.0] * 40)
    pitch_deg = 360.0 / 45
    runs = [run_loop(config, input_angle_deg=(n + 0.5) * pitch_deg) for n in range(3)]
    plays = [play_of(r) for r in runs]
    assert plays[0] == pytest.approx(PLAY, abs=0.003)
    assert plays[1] - plays[0] == pytest.approx(arcmin(4.0), abs=0.003)
    assert plays[2] - plays[0] == pytest.approx(arcmin(-2.0), abs=0.003)

    def centre(run: dict) -> float:
        return 0.5 * (line(run, 1, 2.0, 9.0)[1] + line(run, -1, 2.0, 9.0)[1])

    assert centre(runs[2]) - centre(runs[0]) == pytest.approx(arcmin(2.0), abs=0.003)
    assert centre(runs[1]) == pytest.approx(centre(runs[0]), abs=0.003)


def test_random_spacing_error_is_seeded(nominal):
    a = MeshGeometry.from_config(nominal.with_effect("tooth_spacing_error", seed=3))
    b = MeshGeometry.from_config(nominal.with_effect("tooth_spacing_error", seed=3))
    c = MeshGeometry.from_config(nominal.with_effect("tooth_spacing_error", seed=4))
    assert np.array_equal(a.thickness_internal_um, b.thickness_internal_um)
    assert not np.array_equal(a.thickness_internal_um, c.thickness_internal_um)
    assert np.std(a.thickness_internal_um) == pytest.approx(2.0, rel=0.4)


def test_stiffening_curves_the_flanks(nominal):
    soft, scale = 0.15, 2.0
    run = run_loop(nominal.with_effect("stiffness_nonlinearity", soft_twist_arcmin=soft,
                                       torque_scale_Nm=scale))
    torque = run["true_torque_Nm"]
    sel = np.abs(torque) > 0.05
    s = np.sign(torque[sel])
    mag = np.abs(torque[sel])
    expected = s * (PLAY / 2 + mag / K_MESH + soft * (1 - np.exp(-mag / scale)))
    assert np.max(np.abs(twist(run)[sel] - expected)) < 0.003
    k_low = line(run, 1, 0.1, 0.6)[0]
    k_high = line(run, 1, 7.0, 9.5)[0]
    assert k_low < 0.5 * k_high  # soft near the play, stiff at load


def test_creep_grows_under_dwell_with_its_time_constant(nominal):
    stiffness, tau = 400.0, 3.0
    config = nominal.with_effect("creep", stiffness_Nm_per_arcmin=stiffness, time_constant_s=tau)
    run = simulate_run(config, lambda t: -10.0, duration_s=20.0, sample_rate_Hz=100)
    tw = twist(run)
    t = run["t_s"]
    start = np.searchsorted(t, 0.3)  # drive settled (30 time constants)
    rise = tw[start] - tw  # negative torque: the twist grows negative
    creep = 10.0 / stiffness * (1 - np.exp(-t / tau))  # Kelvin element loaded at t = 0
    expected = creep - creep[start]
    assert np.max(np.abs(rise[start:] - expected[start:])) < 0.002
    final = 10.0 / stiffness * (math.exp(-t[start] / tau) - math.exp(-t[-1] / tau))
    assert tw[start] - tw[-1] == pytest.approx(final, rel=0.05)


def test_direction_gain_scales_the_negative_torques(nominal):
    run = run_loop(nominal.with_effect("direction_gain", gain_positive=1.0, gain_negative=0.9))
    assert line(run, 1, 2.0, 9.0)[0] == pytest.approx(K_MESH, rel=0.005)
    assert line(run, -1, 2.0, 8.5)[0] == pytest.approx(0.9 * K_MESH, rel=0.005)


def test_effects_are_listed_and_off_by_default(nominal):
    plant = GearPlant(nominal, ManualClock())
    assert plant.true_parameters()["effects"] == []
    config = nominal.with_effect("creep").with_effect("friction")
    assert GearPlant(config, ManualClock()).true_parameters()["effects"] == ["friction", "creep"]


@pytest.mark.parametrize("name,params,angle,temperature", [
    ("runout", {"beta_deg": 40.0, "internal_phase_deg": 10.0}, 77.0, None),
    ("thermal_expansion", {}, 0.0, 35.0),
    ("tooth_spacing_error", {"seed": 11}, 100.0, None),
    ("bearing_clearance", {}, 0.0, None),
    ("shaft_compliance", {"stiffness_Nm_per_arcmin": 90.0}, 0.0, None),
])
def test_true_parameters_agree_with_the_measured_loop(nominal, name, params, angle, temperature):
    config = nominal.with_effect(name, **params)
    run = run_loop(config, input_angle_deg=angle, temperature_C=temperature)
    changes = {"rig": {"initial_input_angle_deg": angle}}
    if temperature is not None:
        changes["housing"] = {"initial_C": temperature, "ambient_C": temperature}
    truth = GearPlant(config.with_changes(**changes), ManualClock()).true_parameters()
    assert play_of(run) == pytest.approx(truth["apparent_play_arcmin"], abs=0.003)
    for side in (1, -1):
        assert line(run, side, 2.0, 9.0)[0] == pytest.approx(truth["stiffness_Nm_per_arcmin"],
                                                             rel=0.005)
