"""The simulated plant: nominal loop against the closed forms, dynamics, determinism, API.

Closed forms: seed 000 eqs. (1)-(3) with Table 2 (pair 1) and run-format.md's reference
nominal model; seed 004 eq. (8) for the stiffness; Table 3 for the design maximum.
"""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq

from analysis.loop import analyse_loop
from analysis.models.nominal import reference_nominal_model
from simulators.clock import ManualClock, MonotonicClock
from simulators.offline import simulate_run
from simulators.plant import GearPlant
from simulators.plant.config import EFFECT_NAMES, load_plant_config

RATED_NM = 10.0


def triangle(amplitude_Nm: float, period_s: float):
    """0 -> +A -> -A -> 0 over one period (N*m as a function of s)."""

    def profile(t: float) -> float:
        p = (t % period_s) / period_s
        if p < 0.25:
            return 4.0 * amplitude_Nm * p
        if p < 0.75:
            return amplitude_Nm * (2.0 - 4.0 * p)
        return amplitude_Nm * (4.0 * p - 4.0)

    return profile


def twist_arcmin(run: dict, ratio: float = 8.0) -> np.ndarray:
    """Plant convention: output = offset - input / ratio + twist (deg)."""
    return (run["output_angle_deg"] + run["input_angle_deg"] / ratio) * 60.0


def flank_lines(run: dict, lo: float, hi: float) -> dict[str, tuple[float, float]]:
    """(stiffness N*m/arcmin, twist intercept arcmin) of each branch in |T| in [lo, hi]."""
    torque, twist = run["torque_Nm"], twist_arcmin(run)
    rising = np.gradient(run["torque_command_Nm"]) > 0
    out = {}
    for name, side, load in (("pos_load", 1, True), ("pos_unload", 1, False),
                             ("neg_load", -1, True), ("neg_unload", -1, False)):
        sel = (side * torque > lo) & (side * torque < hi) & (rising == load)
        slope, intercept = np.polyfit(torque[sel], twist[sel], 1)
        out[name] = (1.0 / slope, intercept)
    return out


def measured_play_and_stiffness(run: dict, lo: float = 2.0, hi: float = 9.0):
    lines = flank_lines(run, lo, hi)
    play = (0.5 * (lines["pos_load"][1] + lines["pos_unload"][1])
            - 0.5 * (lines["neg_load"][1] + lines["neg_unload"][1]))
    return play, float(np.mean([k for k, _ in lines.values()])), lines


@pytest.fixture(scope="module")
def base():
    return load_plant_config()


@pytest.fixture(scope="module")
def nominal(base):
    return base.nominal()


def closed_form_play_arcmin() -> float:
    """Seed 000 eqs. (2), (1) with Table 2 pair 1: E_M from min internal / max external."""
    e_m = (42.479 - 42.434) + (42.436 - 42.404)
    return 6.876 * 1000.0 * math.tan(math.radians(20.0)) * e_m / (1.0 * 45)


def closed_form_stiffness() -> float:
    """Seed 004 eq. (8) for the 45/40 pair, h_a = 0.55, b = 10 mm, as N*m/arcmin at r = 22.5."""
    alpha = math.radians(20.0)
    tan_a1 = math.tan(math.acos(45 * math.cos(alpha) / (45 - 1.1)))
    tan_a2 = math.tan(math.acos(40 * math.cos(alpha) / (40 + 1.1)))
    eps = (40 * (tan_a2 - math.tan(alpha)) - 45 * (tan_a1 - math.tan(alpha))) / (2 * math.pi)
    k1 = 1.0 / (0.04723 + 0.15551 / 45 + 0.25791 / 40)
    k_m = 10.0 * (0.75 * eps + 0.25) * k1 * 1e6  # N/m
    return k_m * 0.0225**2 * math.pi / 10800.0


def test_closed_forms_of_the_seed_pair(base):
    assert closed_form_play_arcmin() == pytest.approx(4.2823, abs=1e-4)
    assert closed_form_stiffness() == pytest.approx(27.86, abs=0.01)
    plant = GearPlant(base.nominal(), ManualClock())
    p = plant.true_parameters()
    assert p["play_arcmin"] == pytest.approx(closed_form_play_arcmin(), rel=1e-9)
    assert p["stiffness_Nm_per_arcmin"] == pytest.approx(closed_form_stiffness(), rel=1e-6)
    ref = reference_nominal_model(base.unit)
    assert p["play_arcmin"] == pytest.approx(ref.play_arcmin, rel=1e-12)
    # Table 3, pair 1: theoretical lost motion 6'20" = nominal + worst-case runout term
    runout = GearPlant(base.nominal().with_effect("runout"), ManualClock())
    worst_um = runout._model.geometry.worst_case_runout_play_um()
    assert worst_um == pytest.approx(2 * math.tan(math.radians(20)) * (22 + 15) / 2, rel=1e-12)
    table3 = p["play_arcmin"] + 6.876 * worst_um / 45
    assert table3 * 60 == pytest.approx(6 * 60 + 20, abs=1.0)


def test_slow_cycle_matches_the_reference_nominal_model(nominal):
    run = simulate_run(nominal, triangle(RATED_NM, 20.0), duration_s=20.0, sample_rate_Hz=250)
    play, stiffness, lines = measured_play_and_stiffness(run)
    ref = reference_nominal_model(nominal.unit)
    assert play == pytest.approx(ref.play_arcmin, abs=0.002)
    assert stiffness == pytest.approx(ref.stiffness_Nm_per_arcmin, rel=0.003)
    # the loop is closed: loading and unloading lines coincide without friction
    assert lines["pos_load"][1] == pytest.approx(lines["pos_unload"][1], abs=0.001)
    # and every sample on a flank sits on the model's twist = s play / 2 + T / K
    plant = GearPlant(nominal, ManualClock())
    truth = plant.true_twist_arcmin(run["true_torque_Nm"])
    on_flank = np.abs(run["true_torque_Nm"]) > 0.5
    assert np.max(np.abs(twist_arcmin(run) - truth)[on_flank]) < 0.003
    expected = ref.twist_arcmin(run["true_torque_Nm"])
    assert np.max(np.abs(truth - expected)[on_flank]) < 1e-9


def test_project_loop_analysis_agrees_with_true_parameters(base):
    config = base.with_effect("shaft_compliance").with_effect("runout")
    run = simulate_run(config, triangle(RATED_NM, 20.0), duration_s=40.0, sample_rate_Hz=250,
                       input_angle_deg=30.0)
    result = analyse_loop(run["t_s"], run["torque_Nm"], twist_arcmin(run),
                          rated_torque_Nm=RATED_NM, twist_resolution_arcmin=360 * 60 / 2**23)
    plant = GearPlant(config.with_changes(rig={"initial_input_angle_deg": 30.0}), ManualClock())
    truth = plant.true_parameters()
    metrics = result.metrics
    assert metrics["backlash_arcmin"].value == pytest.approx(truth["play_arcmin"], abs=0.01)
    assert metrics["stiffness_Nm_per_arcmin"].value == pytest.approx(
        truth["stiffness_Nm_per_arcmin"], rel=0.01)
    assert metrics["lost_motion_arcmin"].value == pytest.approx(
        plant.true_lost_motion_arcmin(RATED_NM, 3.0), abs=0.01)


def test_true_lost_motion_of_the_nominal_loop(nominal):
    plant = GearPlant(nominal, ManualClock())
    ref = reference_nominal_model(nominal.unit)
    assert plant.true_lost_motion_arcmin(RATED_NM, 3.0) == pytest.approx(
        ref.lost_motion_arcmin(RATED_NM, 3.0), abs=1e-6)


def test_realtime_path_gives_the_same_loop(nominal):
    clock = ManualClock()
    plant = GearPlant(nominal, clock)
    profile = triangle(RATED_NM, 8.0)
    rows = []
    for k in range(8000):
        t = k * 0.001
        plant.command_torque(profile(t))
        clock.advance(0.001)
        s = plant.snapshot()
        rows.append((s.torque_Nm, s.output_angle_deg, s.input_angle_deg, profile(t)))
    arr = np.array(rows)
    run = {"torque_Nm": arr[:, 0], "output_angle_deg": arr[:, 1], "input_angle_deg": arr[:, 2],
           "torque_command_Nm": arr[:, 3]}
    play, stiffness, _ = measured_play_and_stiffness(run)
    assert play == pytest.approx(closed_form_play_arcmin(), abs=0.002)
    assert stiffness == pytest.approx(closed_form_stiffness(), rel=0.005)


def test_free_play_crossing_follows_newton_with_the_drive_lag(nominal):
    """Inside the play only the inertia resists: J x'' = T0 (1 - exp(-t / tau))."""
    clock = ManualClock()
    plant = GearPlant(nominal, clock)
    cfg = nominal.rig
    gap_deg = closed_form_play_arcmin() / 60.0
    start = plant.snapshot().output_angle_deg
    torque, tau, inertia = 0.01, cfg.drive_time_constant_s, cfg.inertia_kgm2
    plant.command_torque(torque)
    t_hit = None
    for k in range(1, 400):
        clock.advance(0.0005)
        if plant.snapshot().output_angle_deg - start >= gap_deg * (1 - 1e-6):
            t_hit = k * 0.0005
            break

    def travel_rad(t: float) -> float:
        return torque / inertia * (t * t / 2 - tau * t + tau * tau * (1 - math.exp(-t / tau)))

    expected = brentq(lambda t: travel_rad(t) - math.radians(gap_deg), 1e-6, 1.0)
    assert t_hit is not None
    assert t_hit == pytest.approx(expected, rel=0.05)


def test_drive_lag_and_torque_limit(nominal):
    clock = ManualClock()
    plant = GearPlant(nominal, clock)
    tau = nominal.rig.drive_time_constant_s
    plant.command_torque(-5.0)  # starts on the -1 flank: in contact at once
    clock.advance(tau)
    assert plant.snapshot().true_torque_Nm == pytest.approx(-5.0 * (1 - math.exp(-1)), rel=0.03)
    plant.command_torque(1000.0)
    peak = 0.0
    for _ in range(400):
        clock.advance(0.005)
        peak = max(peak, abs(plant.snapshot().true_torque_Nm))
    limit = nominal.rig.drive_torque_limit_Nm
    assert limit * 0.999 < peak <= limit + 1e-9
    with pytest.raises(ValueError, match="finite"):
        plant.command_torque(float("nan"))
    plant.enable_drive(False)
    clock.advance(20 * tau)
    snap = plant.snapshot()
    assert not snap.drive_enabled and abs(snap.true_torque_Nm) < 1e-6


def test_same_seed_same_arrays_and_other_seed_differs(base):
    config = base.with_effect("friction").with_effect("runout").with_effect("creep")
    kwargs = dict(duration_s=4.0, sample_rate_Hz=500, input_angle_deg=45.0)
    a = simulate_run(config, triangle(RATED_NM, 4.0), **kwargs)
    b = simulate_run(config, triangle(RATED_NM, 4.0), **kwargs)
    for key in a:
        assert np.array_equal(a[key], b[key]), key
    other = config.with_changes(noise={"seed": 2})
    c = simulate_run(other, triangle(RATED_NM, 4.0), **kwargs)
    assert not np.array_equal(a["torque_Nm"], c["torque_Nm"])
    assert np.array_equal(a["true_torque_Nm"], c["true_torque_Nm"])  # noise is sensors only


def test_realtime_plant_is_deterministic_under_a_manual_clock(base):
    def trace() -> list:
        clock = ManualClock()
        plant = GearPlant(base.with_effect("friction"), clock)
        out = []
        for k in range(300):
            plant.command_torque(3.0 * math.sin(k / 30.0))
            clock.advance(0.0007)
            out.append(plant.snapshot())
        return out

    assert trace() == trace()


def test_array_profile_and_column_shapes(nominal):
    commands = np.linspace(-3.0, 3.0, 500)
    run = simulate_run(nominal, commands, duration_s=1.0, sample_rate_Hz=500,
                       temperature_C=35.0)
    assert set(run) >= {"t_s", "torque_Nm", "output_angle_deg", "input_angle_deg",
                        "temperature_C"}
    assert all(v.shape == (500,) for v in run.values())
    assert np.all(run["temperature_C"] == 35.0)
    counts = nominal.rig.encoder_counts_per_rev
    steps = run["output_angle_deg"] / (360.0 / counts)
    assert np.allclose(steps, np.round(steps), atol=1e-6)
    with pytest.raises(ValueError, match="one command per sample"):
        simulate_run(nominal, commands[:10], duration_s=1.0, sample_rate_Hz=500)


def test_housing_temperature_and_long_waits(nominal):
    clock = ManualClock()
    plant = GearPlant(nominal, clock)
    plant.command_torque(-2.0)
    clock.advance(1.0)
    plant.set_ambient_temperature(40.0)
    tau = nominal.housing.time_constant_s
    clock.advance(tau)
    assert plant.snapshot().temperature_C == pytest.approx(40.0 - 20.0 * math.exp(-1), abs=1e-6)
    clock.advance(10 * tau)  # crossed in long implicit steps while at rest
    snap = plant.snapshot()
    assert snap.temperature_C == pytest.approx(40.0, abs=1e-3)
    assert snap.true_torque_Nm == pytest.approx(-2.0, abs=1e-9)


def test_lock_input_turns_at_the_configured_speed(nominal):
    clock = ManualClock()
    plant = GearPlant(nominal, clock)
    twist0 = plant.snapshot().output_angle_deg
    plant.lock_input_at(270.0)
    clock.advance(0.5)
    s = plant.snapshot()
    assert s.input_angle_deg == pytest.approx(180.0, abs=0.5)
    clock.advance(1.0)
    s = plant.snapshot()
    assert s.input_angle_deg == 270.0
    assert s.output_angle_deg == pytest.approx(twist0 - 270.0 / 8.0, abs=1e-6)
    assert plant.true_parameters()["input_angle_deg"] == 270.0


def test_snapshot_from_several_threads(base):
    plant = GearPlant(base, MonotonicClock())
    errors: list[BaseException] = []

    def reader() -> None:
        try:
            last = -1.0
            for k in range(300):
                s = plant.snapshot()
                assert s.t_s >= last and math.isfinite(s.output_angle_deg)
                last = s.t_s
                if k % 50 == 0:
                    plant.command_torque(2.0 if k % 100 else -2.0)
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    threads = [threading.Thread(target=reader) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    assert not errors
    assert all(not t.is_alive() for t in threads)


def test_quasi_static_loop_does_not_depend_on_the_step(base):
    config = base.nominal().with_effect("friction").with_effect("stiffness_nonlinearity")
    results = []
    for step in (0.0005, 0.002):
        run = simulate_run(config.with_changes(rig={"step_s": step}), triangle(RATED_NM, 20.0),
                           duration_s=20.0, sample_rate_Hz=250)
        results.append(measured_play_and_stiffness(run)[:2])
    assert results[0][0] == pytest.approx(results[1][0], abs=0.001)
    assert results[0][1] == pytest.approx(results[1][1], rel=0.002)


@settings(max_examples=25, deadline=None)
@given(st.lists(st.tuples(st.floats(-200.0, 200.0), st.floats(1e-5, 0.2),
                          st.floats(-400.0, 400.0)), min_size=1, max_size=40),
       st.sampled_from(["dahl", "lugre"]))
def test_any_command_sequence_stays_finite_and_limited(steps, friction_model):
    config = load_plant_config()
    for name in EFFECT_NAMES:
        config = config.with_effect(name)
    config = config.with_effect("friction", model=friction_model)
    clock = ManualClock()
    plant = GearPlant(config, clock)
    limit = config.rig.drive_torque_limit_Nm
    for command, dt, angle in steps:
        plant.command_torque(command)
        plant.lock_input_at(angle)
        clock.advance(dt)
        snap = plant.snapshot()
        assert all(math.isfinite(v) for v in (snap.output_angle_deg, snap.torque_Nm,
                                              snap.true_torque_Nm, snap.input_angle_deg))
        assert abs(plant.true_parameters()["drive_torque_Nm"]) <= limit
