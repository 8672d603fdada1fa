"""The plant of each unit kind (issue 23 item 1): cycloid (seed 002) and beveloid (seed 001).

Offline (the same engine as the real-time rig, simulators/offline.py) every injected effect of
each kind is measured by the project's loop analysis: lost motion within 2 % of the plant's own
truth, and each effect moves the truth (it is not a no-op). A clean unit is within 2 % of the
kind's nominal model (analysis/models/by_kind.py). The simulated rig's end to end runs are in
tests/rig/plans/test_campaign_kinds.py.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from analysis.loop import analyse_loop
from analysis.models.by_kind import nominal_model_for_unit
from simulators.clock import ManualClock
from simulators.offline import simulate_run
from simulators.plant import GearPlant
from simulators.plant.config import PlantConfigError, load_plant_config
from simulators.plant.truth import generator_block
from tests.support.paths import REPO as ROOT

RATED_NM = 10.0
RESOLUTION = 360 * 60 / 2**23


def triangle(t: float, amplitude: float = RATED_NM, period: float = 20.0) -> float:
    p = (t % period) / period
    if p < 0.25:
        return 4 * amplitude * p
    return amplitude * (2 - 4 * p) if p < 0.75 else amplitude * (4 * p - 4)


@pytest.fixture(scope="module")
def cycloid():
    return load_plant_config(ROOT / "simulators" / "cycloid_plant.toml").nominal()


@pytest.fixture(scope="module")
def beveloid():
    return load_plant_config(ROOT / "simulators" / "beveloid_plant.toml").nominal()


def measured_and_true(config, angle: float) -> tuple[float, float, dict]:
    """Lost motion (arcmin) measured by the loop analysis on an offline run locked at
    ``angle`` (deg), and the plant's true lost motion and parameters there. A little drag
    (seals and oil, as the shipped campaigns) damps the flank impact after the free play."""
    config = config.with_effect("friction", model="lugre", coulomb_torque_Nm=0.02,
                                static_torque_Nm=0.03, viscous_Nms_per_arcmin=0.002)
    plant = GearPlant(config.with_changes(rig={"initial_input_angle_deg": angle}),
                      ManualClock())
    ratio = plant.true_parameters()["ratio"]
    run = simulate_run(config, triangle, duration_s=40.0, sample_rate_Hz=250,
                       input_angle_deg=angle)
    twist = (run["output_angle_deg"] + run["input_angle_deg"] / ratio) * 60.0
    result = analyse_loop(run["t_s"], run["torque_Nm"], twist, rated_torque_Nm=RATED_NM,
                          twist_resolution_arcmin=RESOLUTION)
    return (result.metrics["lost_motion_arcmin"].value,
            plant.true_lost_motion_arcmin(RATED_NM, 3.0), plant.true_parameters())


def common_effects(teeth_internal: int, teeth_external: int) -> dict:
    """The effects both kinds take the same way: runout, bearing clearance and a tooth
    thickness ramp of -5..5 um over each gear's teeth."""
    return {
        "runout": ("runout", {"beta_deg": 40.0}),
        "bearing_clearance": ("bearing_clearance", {}),
        "tooth_spacing_error": ("tooth_spacing_error", {
            "thickness_internal_um": np.linspace(-5.0, 5.0, teeth_internal).tolist(),
            "thickness_external_um": np.linspace(-5.0, 5.0, teeth_external).tolist()}),
    }


CYCLOID_EFFECTS = {
    "eccentricity_error": ("cycloid", {"eccentricity_error_um": -3.0}),
    "shift_error": ("cycloid", {"shift_error_mm": 0.004}),
    "rotation_error": ("cycloid", {"rotation_error_mm": -0.001}),
    "equidistant_modification": ("cycloid", {"equidistant_modification_mm": 0.003}),
    **common_effects(40, 39),
}
BEVELOID_EFFECTS = {
    "axial_shift_error": ("beveloid", {"axial_shift_error_mm": -0.03}),
    "center_distance_error": ("beveloid", {"center_distance_error_mm": 0.01}),
    "lateral_offset": ("beveloid", {"lateral_offset_mm": 0.5}),
    **common_effects(20, 20),
}


def injected(config, where: str, params: dict):
    if where in ("cycloid", "beveloid"):
        return config.with_changes(**{where: params})
    return config.with_effect(where, **params)


@pytest.mark.parametrize("kind, effect", [("cycloid", e) for e in CYCLOID_EFFECTS]
                         + [("beveloid", e) for e in BEVELOID_EFFECTS])
def test_each_injected_effect_is_measured_within_2_percent_of_the_truth(
        kind, effect, cycloid, beveloid):
    base = cycloid if kind == "cycloid" else beveloid
    where, params = (CYCLOID_EFFECTS if kind == "cycloid" else BEVELOID_EFFECTS)[effect]
    config = injected(base, where, params)
    angle = 123.0
    measured, truth, params_now = measured_and_true(config, angle)
    clean = GearPlant(base.with_changes(rig={"initial_input_angle_deg": angle}),
                      ManualClock()).true_lost_motion_arcmin(RATED_NM, 3.0)
    assert params_now["kind"] == kind
    assert abs(truth - clean) > 0.03 * clean, f"{effect} does not change the lost motion"
    assert measured == pytest.approx(truth, rel=0.02), (kind, effect, measured, truth, clean)
    # every injected value is in the run's generator block
    block = generator_block(config, input_angle_deg=angle, rated_torque_Nm=RATED_NM)
    assert block["kind"] == kind
    assert block["true_lost_motion_arcmin"] == pytest.approx(truth, rel=1e-9)
    recorded = block["injected"]
    if where in ("cycloid", "beveloid"):
        assert recorded[where] == params
    else:
        assert where in recorded["effects"]
        for key, value in params.items():
            assert recorded["effects"][where][key] == value
    json.dumps(block, allow_nan=False)


def test_cycloid_clean_unit_matches_its_nominal_model_over_the_mesh_cycle(cycloid):
    model, _ = nominal_model_for_unit(cycloid.unit, RATED_NM)
    predicted = model.lost_motion_arcmin(RATED_NM, 3.0)
    pitch = 360.0 / cycloid.unit["z_internal"]
    lms = []
    for k in range(6):  # the model's mesh phases over one tooth pitch
        measured, truth, _ = measured_and_true(cycloid, k * pitch / 6)
        assert measured == pytest.approx(truth, rel=0.02)
        lms.append(measured)
    print(f"\ncycloid clean: measured {np.round(lms, 4)} arcmin, mean {np.mean(lms):.4f}, "
          f"nominal model {predicted:.4f}")
    assert np.mean(lms) == pytest.approx(predicted, rel=0.02)
    # the play changes with the mesh phase (the assembled pair, seed 002), a few per cent
    assert max(lms) - min(lms) > 0.01


def test_beveloid_clean_unit_matches_its_nominal_model(beveloid):
    model, _ = nominal_model_for_unit(beveloid.unit, RATED_NM)
    measured, truth, params = measured_and_true(beveloid, 40.0)
    print(f"\nbeveloid clean: measured {measured:.4f}, truth {truth:.4f}, "
          f"model {model.lost_motion_arcmin(RATED_NM, 3.0):.4f} arcmin")
    assert truth == pytest.approx(model.lost_motion_arcmin(RATED_NM, 3.0), rel=1e-6)
    assert measured == pytest.approx(model.lost_motion_arcmin(RATED_NM, 3.0), rel=0.02)
    assert params["ratio"] == pytest.approx(1.0)


def test_beveloid_shaft_angle_gives_the_tca_transmission_error(beveloid):
    """Seed 001 eq. (11): a shaft angle error moves the loop's centre over each mesh cycle (a
    sawtooth, TCA), linear in the angle; the play stays (the drive flank's TE only)."""
    tilted = beveloid.with_changes(beveloid={"shaft_angle_horizontal_deg": 0.2})
    offsets = []
    for angle in np.linspace(0.0, 18.0, 9):
        plant = GearPlant(tilted.with_changes(rig={"initial_input_angle_deg": angle}),
                          ManualClock())
        offsets.append(plant.true_parameters()["twist_offset_arcmin"] * 60.0)
    te = GearPlant(tilted, ManualClock()).true_parameters()
    assert te["transmission_error_pp_arcsec"] == pytest.approx(0.4 * 50.1, rel=0.1)
    assert np.ptp(offsets) == pytest.approx(te["transmission_error_pp_arcsec"], rel=0.05)
    measured, truth, _ = measured_and_true(tilted, 5.0)
    assert measured == pytest.approx(truth, rel=0.02)


def test_cycloid_loaded_flank_contact_stiffens_with_load(cycloid):
    """More flanks take load as the torque grows (seed 002's multi-tooth contact)."""
    plant = GearPlant(cycloid, ManualClock())
    torque = np.linspace(0.0, 300.0, 301)
    twist = plant.true_twist_arcmin(torque, start_flank=-1)
    slope = np.diff(twist) / np.diff(torque)
    assert slope[-1] < 0.6 * slope[5]
    assert np.all(np.diff(slope[2:]) <= 1e-12)


def test_bad_kind_tables_name_the_key(cycloid):
    with pytest.raises(PlantConfigError, match="cycloid.equidistant_modification_mm"):
        cycloid.with_changes(cycloid={"equidistant_modification_mm": -0.01})
    with pytest.raises(PlantConfigError, match="unit.kind"):
        cycloid.with_changes(unit={"kind": "harmonic"})
