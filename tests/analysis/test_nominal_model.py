"""The reference nominal model (run-format.md, version 1) and seed 004 eqs. (8)-(11), checked
against closed forms and the figures in the brief for the run-format.md example unit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from analysis.errors import AnalysisError
from analysis.models import mesh_stiffness as ms
from analysis.models.nominal import (
    NominalModel,
    reference_nominal_model,
    standard_m_values_mm,
)
from analysis.models.seed000_unit import InternalPairUnit

# The `unit` object of the run.json example in run-format.md (seed 000 pair 1).
EXAMPLE_UNIT = {
    "kind": "internal_involute",
    "z_internal": 45, "z_external": 40,
    "module_mm": 1.0, "pressure_angle_deg": 20.0,
    "addendum_coeff": 0.55, "clearance_coeff": 0.25,
    "face_width_mm": 10.0,
    "center_distance_mm": 2.5,
    "pin_diameter_mm": 1.732,
    "m_value_internal_mm": [42.485, 42.481, 42.481, 42.480, 42.483, 42.479],
    "m_value_external_mm": [42.401, 42.398, 42.402, 42.404, 42.402, 42.404],
    "runout_internal_mm": 0.022, "runout_external_mm": 0.015,
    "bearing_clearance_mm": [0.005, 0.006],
}
ALPHA = math.radians(20.0)


@pytest.fixture(scope="module")
def model() -> NominalModel:
    return reference_nominal_model(EXAMPLE_UNIT)


def test_free_play_of_the_example_unit(model):
    """E_M = (42.479 - 42.434) + (42.436 - 42.404) = 0.077 mm; j_t = 1000 tan20 E_M;
    play = 6.876 j_t / 45 (eqs. 1-3 as pinned)."""
    j_t = 1000.0 * math.tan(ALPHA) * 0.077
    assert model.m_value_deviation_mm == pytest.approx(0.077, abs=1e-12)
    assert model.play_um == pytest.approx(j_t, rel=1e-12)
    assert model.play_um == pytest.approx(28.03, abs=0.005)
    assert model.play_arcmin == pytest.approx(6.876 * j_t / 45.0, rel=1e-12)
    assert model.play_arcmin == pytest.approx(4.283, abs=0.001)
    assert model.backlash_arcmin == model.play_arcmin
    assert model.assumptions == ()


def test_m0_is_rounded_as_the_paper_does():
    unit, _ = InternalPairUnit.from_mapping(EXAMPLE_UNIT)
    assert standard_m_values_mm(unit) == (42.434, 42.436)


def test_center_distance_term_of_eq3():
    """Each um of center distance above a0 takes 2 tan(alpha) um of play away (internal pair)."""
    wider = reference_nominal_model({**EXAMPLE_UNIT, "center_distance_mm": 2.51})
    base = reference_nominal_model(EXAMPLE_UNIT)
    assert base.play_um - wider.play_um == pytest.approx(2 * math.tan(ALPHA) * 10.0, rel=1e-9)
    with pytest.raises(AnalysisError, match="interfere"):
        reference_nominal_model({**EXAMPLE_UNIT, "center_distance_mm": 2.572})


def test_stiffness_of_the_example_unit(model):
    """k' ~ 17.50 N/(mm um), eps ~ 1.108, k_m ~ 189 N/um, K ~ 27.9 N m/arcmin (brief)."""
    k1 = 1.0 / (0.04723 + 0.15551 / 45 + 0.25791 / 40)
    assert ms.single_pair_stiffness_N_per_mm_um(45, 40) == pytest.approx(k1, rel=1e-12)
    assert k1 == pytest.approx(17.50, abs=0.01)
    assert model.contact_ratio == pytest.approx(1.108, abs=0.001)
    k_m = 10.0 * (0.75 * model.contact_ratio + 0.25) * k1
    assert model.mesh_stiffness_N_per_um == pytest.approx(k_m, rel=1e-12)
    assert k_m == pytest.approx(189.2, abs=0.1)
    k_rad = k_m * 1e6 * 0.0225**2  # N m / rad, r = m z_int / 2 = 22.5 mm
    assert model.stiffness_Nm_per_arcmin == pytest.approx(k_rad * math.pi / 10800, rel=1e-12)
    assert model.stiffness_Nm_per_arcmin == pytest.approx(27.86, abs=0.01)
    assert model.working_pressure_angle_deg == pytest.approx(20.0, abs=1e-9)


@pytest.mark.parametrize("center_distance", [2.5, 2.52, 2.55])
def test_contact_ratio_equals_path_of_contact_over_base_pitch(center_distance):
    """Eq. (9) (internal form) against the path of contact of the internal pair:
    g = sqrt(ra2^2 - rb2^2) - sqrt(ra1^2 - rb1^2) + a sin(alpha'), eps = g / (pi m cos alpha)."""
    ra1, rb1 = (45 - 1.1) / 2, 45 * math.cos(ALPHA) / 2
    ra2, rb2 = (40 + 1.1) / 2, 40 * math.cos(ALPHA) / 2
    alpha_w = math.acos(2.5 * math.cos(ALPHA) / center_distance)
    g = math.sqrt(ra2**2 - rb2**2) - math.sqrt(ra1**2 - rb1**2) + center_distance * math.sin(
        alpha_w
    )
    eps = ms.internal_contact_ratio(45, 40, 1.0, ALPHA, 0.55, alpha_w)
    assert eps == pytest.approx(g / (math.pi * math.cos(ALPHA)), rel=1e-12)


def test_paper_coefficient_and_bad_geometry():
    iso = ms.single_pair_stiffness_N_per_mm_um(45, 40)
    printed = ms.single_pair_stiffness_N_per_mm_um(45, 40, paper_coefficient=True)
    delta = (0.15551 - 0.1551) / 45  # the dropped digit, per unit of 1 / k'
    assert printed > iso
    assert printed / iso - 1 == pytest.approx(delta * iso, rel=1e-3)
    with pytest.raises(AnalysisError):
        ms.single_pair_stiffness_N_per_mm_um(-45, 40)
    with pytest.raises(AnalysisError, match="base-circle"):
        ms.working_pressure_angle_rad(2.5, 2.3, ALPHA)
    with pytest.raises(AnalysisError, match="addendum"):
        ms.internal_contact_ratio(45, 40, 1.0, ALPHA, 2.0, ALPHA)


def test_eq11_equivalent_mass_and_damping():
    """Seed 004 Table 2 gears (m 9, z 38/228, J 0.02/115.72 kg m^2): the standard equivalent mass
    1 / (r1^2/J1 + r2^2/J2) is below both gears' own; the printed form (J1, J2 swapped) is not."""
    rb1 = 9 * 38 * math.cos(ALPHA) / 2 / 1000
    rb2 = 9 * 228 * math.cos(ALPHA) / 2 / 1000
    m_std = ms.equivalent_mass_kg(0.02, 115.72, rb1, rb2)
    assert m_std == pytest.approx(1.0 / (rb1**2 / 0.02 + rb2**2 / 115.72), rel=1e-12)
    assert m_std < min(0.02 / rb1**2, 115.72 / rb2**2)
    m_paper = ms.equivalent_mass_kg(0.02, 115.72, rb1, rb2, form="paper")
    assert m_paper == pytest.approx(0.02 * 115.72 / (rb1**2 * 0.02 + rb2**2 * 115.72))
    assert m_paper < 0.05 * m_std
    # equal gears: both forms agree
    assert ms.equivalent_mass_kg(1.0, 1.0, 0.1, 0.1) == ms.equivalent_mass_kg(
        1.0, 1.0, 0.1, 0.1, form="paper"
    )
    c = ms.mesh_damping_Ns_per_m(m_std, 1e9)
    assert c == pytest.approx(2 * 0.06 * math.sqrt(m_std * 1e9), rel=1e-12)


def test_flank_rule(model):
    play, k = model.play_arcmin, model.stiffness_Nm_per_arcmin
    torque = np.array([0.0, 0.0, 1.0, 0.0, 0.0, -2.0, 0.0, 3.0])
    twist = model.twist_arcmin(torque)
    flank = np.array([-1, -1, 1, 1, 1, -1, -1, 1], dtype=float)
    assert np.allclose(twist, flank * play / 2 + torque / k, rtol=0, atol=1e-15)
    started_up = model.twist_arcmin(torque, start_flank=1)
    assert started_up[0] == pytest.approx(play / 2) and started_up[1] == pytest.approx(play / 2)
    assert np.allclose(started_up[2:], twist[2:])
    assert model.twist_arcmin(np.array([])).size == 0
    with pytest.raises(AnalysisError):
        model.twist_arcmin(torque, start_flank=0)
    with pytest.raises(AnalysisError):
        model.twist_arcmin(np.array([0.0, np.nan]))


def test_loop_width_and_lost_motion(model):
    """Over a 0 -> +T -> 0 -> -T -> 0 cycle the loop's width at zero torque is the play and
    its width at +-pct % of T is play + 2 (pct/100 T) / K."""
    t = np.concatenate([np.linspace(0, 10, 51), np.linspace(10, -10, 101), np.linspace(-10, 0, 51)])
    twist = model.twist_arcmin(t)
    assert twist.max() - twist.min() == pytest.approx(model.play_arcmin + 20.0 / model.
                                                      stiffness_Nm_per_arcmin)
    at_zero = twist[np.isclose(t, 0.0)]
    assert at_zero.max() - at_zero.min() == pytest.approx(model.backlash_arcmin)
    expected = model.play_arcmin + 2 * 0.3 / model.stiffness_Nm_per_arcmin
    assert model.lost_motion_arcmin(10.0, 3.0) == pytest.approx(expected)
    assert model.lost_motion_arcmin(10.0, 0.0) == pytest.approx(model.play_arcmin)
    with pytest.raises(AnalysisError):
        model.lost_motion_arcmin(-1.0, 3.0)


def test_missing_data_is_assumed_openly():
    bare = {k: v for k, v in EXAMPLE_UNIT.items()
            if k not in ("face_width_mm", "m_value_internal_mm", "m_value_external_mm")}
    m = reference_nominal_model(bare)
    text = "\n".join(m.assumptions)
    assert "face_width_mm missing" in text and "E_M = 0" in text
    assert math.isinf(m.stiffness_Nm_per_arcmin) and m.to_dict()["stiffness_Nm_per_arcmin"] is None
    assert m.play_um == 0.0  # nominal teeth at the standard center distance: no free play
    one_side = {k: v for k, v in EXAMPLE_UNIT.items() if k != "m_value_external_mm"}
    m1 = reference_nominal_model(one_side)
    assert m1.m_value_deviation_mm == pytest.approx(0.045)
    assert any("m_value_external_mm missing" in a for a in m1.assumptions)
    no_pin = {k: v for k, v in EXAMPLE_UNIT.items() if k != "pin_diameter_mm"}
    with pytest.raises(AnalysisError, match="pin_diameter_mm"):
        reference_nominal_model(no_pin)


def test_unit_object_and_mapping_give_the_same_model(model):
    unit, _ = InternalPairUnit.from_mapping(EXAMPLE_UNIT)
    assert reference_nominal_model(unit) == model
