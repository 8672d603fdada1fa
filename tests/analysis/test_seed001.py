"""Seed 001: beveloid tooth surfaces, TCA, transmission error and backlash, against the paper
and against closed forms. ``pytest -s`` prints paper figure, ours and the difference;
docs/seed001.md explains the readings behind the numbers."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from analysis.errors import AnalysisError
from analysis.models.beveloid_nominal import beveloid_nominal_model
from analysis.models.seed001_beveloid import (
    ARCSEC_PER_RAD,
    COAST,
    DRIVE,
    PAPER_CASES,
    PAPER_CENTER_DISTANCE_MM,
    BeveloidPair,
    Installation,
    backlash,
    backlash_closed_form,
    paper_gears,
    paper_pair,
    tooth_pair_contact,
    touch_angles,
    transmission_error,
)
from analysis.models.seed001_surfaces import BeveloidGear, radial
from tests.support.paths import REPO

EXAMPLE = REPO / "rig" / "examples" / "units"
POINTS = 8  # per mesh cycle


def _compare(label: str, paper: str, ours: str, difference: str) -> None:
    print(f"{label:52s} paper {paper:>14s}  ours {ours:>14s}  difference {difference}")


@pytest.fixture(scope="module")
def pair() -> BeveloidPair:
    return paper_pair()


@pytest.fixture(scope="module")
def errors_te(pair: BeveloidPair) -> dict:
    names = ("horizontal_and_vertical", "horizontal", "vertical", "combined")
    return {name: transmission_error(pair, PAPER_CASES[name], POINTS) for name in names}


def test_table1_center_distance_does_not_fit(pair: BeveloidPair) -> None:
    standard = pair.standard_center_distance_mm
    _compare("Table 1 center distance (mm)", f"{PAPER_CENTER_DISTANCE_MM:.3f}",
             f"{standard:.3f}", f"{standard - PAPER_CENTER_DISTANCE_MM:+.3f} mm")
    assert standard == pytest.approx(20 * 3 / math.cos(math.radians(9)), rel=1e-12)
    # 109 mm would need 71.8 teeth in all at m_t = 3.037 mm: it cannot belong to 20 + 20
    assert PAPER_CENTER_DISTANCE_MM / standard > 1.7


def test_eqs_1_2_surfaces_are_involute_helicoids() -> None:
    pinion, _ = paper_gears()
    roll = np.linspace(-0.35, 0.35, 9)[:, None]
    z = np.linspace(-7.5, 7.5, 7)[None, :]
    for side in (DRIVE, COAST):
        points, normals = pinion.flank(side).surface(roll, z)
        assert np.allclose(np.linalg.norm(normals, axis=-1), 1.0)
        assert np.allclose(points[..., 2], z)
        # every normal line of an involute helicoid is tangent to the base cylinder
        moment = np.abs(points[..., 0] * normals[..., 1] - points[..., 1] * normals[..., 0])
        arm = moment / np.hypot(normals[..., 0], normals[..., 1])
        assert np.allclose(arm, pinion.base_radius_mm(side), atol=1e-9)
    print("transverse pressure angles (deg) drive/coast:",
          round(math.degrees(pinion.transverse_pressure_angle(DRIVE)), 4),
          round(math.degrees(pinion.transverse_pressure_angle(COAST)), 4))


def test_eq1_tooth_thickness_grows_along_the_cone() -> None:
    pinion, _ = paper_gears()
    r = pinion.pitch_radius_mm

    def thickness(z: float) -> float:
        angles = []
        for side in (COAST, DRIVE):
            flank = pinion.flank(side)
            p, _ = flank.surface(flank.roll_angle_at_radius(r, z), z)
            angles.append(math.atan2(p[1], p[0]))
        return r * (angles[0] - angles[1])

    a_n, beta, delta = pinion.alpha_n, pinion.beta, pinion.delta
    rate = 2 * math.tan(a_n) * math.sin(delta) / math.cos(beta)
    assert thickness(0.0) == pytest.approx(math.pi * 3.0 / (2 * math.cos(beta)), rel=1e-9)
    assert (thickness(7.5) - thickness(-7.5)) / 15.0 == pytest.approx(rate, rel=1e-6)


def test_standard_and_center_distance_error_give_zero_te(pair: BeveloidPair) -> None:
    for name in ("standard", "center_distance_error"):
        te = transmission_error(pair, PAPER_CASES[name], POINTS)
        worst = float(np.max(np.abs(te.te_arcsec)))
        _compare(f"TE, {name} (arcsec)", "0", f"{worst:.2e}", f"{worst:+.2e}")
        assert worst < 1e-4
        assert all(kind.startswith("pinion face+0") for kind in te.kind)  # line contact


def test_center_distance_error_moves_contact_along_the_profile(pair: BeveloidPair) -> None:
    phi1 = np.radians([-9.0, 0.0, 9.0])
    before = tooth_pair_contact(pair, PAPER_CASES["standard"], DRIVE, phi1)
    after = tooth_pair_contact(pair, PAPER_CASES["center_distance_error"], DRIVE, phi1)
    shift = after.pinion_radius_mm - before.pinion_radius_mm
    print("contact radius shift on the pinion (mm):", shift.round(4))
    assert np.all(np.abs(shift) > 0.05)  # "只是接触线的位置沿齿高方向移动"


@pytest.mark.parametrize("name", ["horizontal_and_vertical", "horizontal", "vertical",
                                  "combined"])
def test_axis_errors_give_edge_contact_and_periodic_te(errors_te: dict, name: str) -> None:
    te = errors_te[name]
    print(f"{name:24s} TE over one cycle (arcsec): {te.te_arcsec.round(1)}")
    _compare(f"TE peak-to-peak, {name} (arcsec)", "not printed",
             f"{te.peak_to_peak_arcsec:.1f}", "figure values not in the text")
    assert te.peak_to_peak_arcsec > 5.0
    # edge contact: every loaded contact involves a face edge
    assert all("face" in kind for kind in te.kind)
    # periodic with the mesh cycle and a jump where the next pair takes over
    assert te.te_arcsec[0] == pytest.approx(te.te_arcsec[-1], abs=1e-6)
    assert te.largest_jump_arcsec > 0.5 * te.peak_to_peak_arcsec
    assert len(set(te.pair_index.tolist())) == 2


def test_vertical_versus_horizontal_depends_on_the_reading(errors_te: dict) -> None:
    about_x0 = errors_te["horizontal"].peak_to_peak_arcsec  # eq. (8)'s dl_h: crossed axes
    about_y0 = errors_te["vertical"].peak_to_peak_arcsec  # eq. (8)'s dl_v: intersecting axes
    _compare("TE p-p, turn about x0 (crossed axes)", "-", f"{about_x0:.1f}", "")
    _compare("TE p-p, turn about y0 (intersecting axes)", "-", f"{about_y0:.1f}", "")
    print("paper: 'vertical matters more' holds if its vertical error tilts the gear axis out of"
          " the plane of the axes (turn about x0); with eq. (8) read literally it does not")
    assert about_x0 > 2 * about_y0


def test_tca_agrees_with_touch_angle_sampling(pair: BeveloidPair) -> None:
    """The contact equations (fsolve) against a brute-force grid of touch angles."""
    for name in ("horizontal", "standard"):
        inst = PAPER_CASES[name]
        phi1 = np.radians([-6.0, 3.0, 6.0])
        contact = tooth_pair_contact(pair, inst, DRIVE, phi1)
        for i, angle in enumerate(phi1):
            grid = float(np.nanmax(touch_angles(pair, inst, DRIVE, angle, 80, 81)))
            gap = (contact.phi2[i] - grid) * ARCSEC_PER_RAD
            print(f"{name:10s} phi1 {math.degrees(angle):+5.1f} deg {contact.kind[i]:34s} "
                  f"TCA - grid = {gap:+.3f} arcsec")
            assert gap > -0.01  # the grid can only touch later
            limit = 30.0 if "gear face" in contact.kind[i] else 1.5
            assert gap < limit


def test_backlash_against_closed_form(pair: BeveloidPair) -> None:
    for shift in (0.0, -0.2, -0.5, -1.0):
        exact = backlash(pair, shift)
        closed = backlash_closed_form(pair, shift)
        print(f"axial shift {shift:+.2f} mm: backlash TCA {exact.angle_arcmin:.6f}' "
              f"closed form {closed.angle_arcmin:.6f}'  j_t {exact.circumferential_um:.3f} um")
        assert exact.angle_arcmin == pytest.approx(closed.angle_arcmin, abs=1e-8)
    wider = BeveloidPair(pair.pinion, pair.gear, pair.center_distance_mm + 0.05)
    assert backlash(wider).angle_arcmin == pytest.approx(
        backlash_closed_form(wider).angle_arcmin, abs=1e-8
    )


def test_backlash_set_by_axial_shift_at_fixed_center_distance(pair: BeveloidPair) -> None:
    a_n, beta, delta = (math.radians(20), math.radians(9), math.radians(6))
    slope = 2 * math.tan(delta) * math.tan(a_n) * math.cos(delta) / math.cos(beta) * 1000
    shifts = np.linspace(-1.0, 0.0, 5)
    j_t = np.array([backlash_closed_form(pair, s).circumferential_um for s in shifts])
    fitted = np.polyfit(shifts, j_t, 1)[0]
    _compare("j_t per mm of axial shift (um/mm)", "not given", f"{-fitted:.3f}",
             f"first order {slope:.3f}")
    assert -fitted == pytest.approx(slope, rel=1e-9)
    assert backlash_closed_form(pair, 0.0).angle_arcmin == pytest.approx(0.0, abs=1e-9)
    assert backlash_closed_form(pair, 0.1).angle_arcmin < 0  # thicker: interference


def test_nominal_model_from_example_unit() -> None:
    unit = json.loads((EXAMPLE / "beveloid-seed001.json").read_text())
    model, assumptions = beveloid_nominal_model(unit)
    pair = paper_pair(unit["center_distance_mm"])
    assert model.play_arcmin == pytest.approx(
        backlash_closed_form(pair, unit["axial_shift_mm"]).angle_arcmin
    )
    assert 0.5 < model.play_arcmin < 1.5
    assert 10 < model.stiffness_Nm_per_arcmin < 500
    torque = np.array([0.0, 10.0, 0.0, -10.0, 0.0])
    twist = model.twist_arcmin(torque)
    assert twist[0] == pytest.approx(-model.play_arcmin / 2)
    assert twist[2] - twist[4] == pytest.approx(model.backlash_arcmin)
    assert model.lost_motion_arcmin(10.0, 100) == pytest.approx(twist[1] - twist[3])
    print("beveloid example: play", round(model.play_arcmin, 4), "arcmin, K",
          round(model.stiffness_Nm_per_arcmin, 2), "N m/arcmin;", assumptions)


def test_nominal_model_missing_keys_are_assumed_and_said() -> None:
    unit = json.loads((EXAMPLE / "beveloid-seed001.json").read_text())
    for key in ("axial_shift_mm", "center_distance_mm", "addendum_coeff"):
        unit.pop(key)
    model, assumptions = beveloid_nominal_model(unit)
    assert model.play_arcmin == pytest.approx(0.0, abs=1e-9)
    assert any("axial_shift_mm" in a for a in assumptions)
    assert any("center_distance_mm" in a for a in assumptions)


def test_bad_units_are_clear_errors() -> None:
    unit = json.loads((EXAMPLE / "beveloid-seed001.json").read_text())
    with pytest.raises(AnalysisError, match="interfere"):
        beveloid_nominal_model({**unit, "axial_shift_mm": 0.2})
    with pytest.raises(AnalysisError, match="face_width_mm"):
        beveloid_nominal_model({k: v for k, v in unit.items() if k != "face_width_mm"})
    with pytest.raises(AnalysisError, match="z_gear"):
        beveloid_nominal_model({**unit, "z_gear": 20.5})
    with pytest.raises(AnalysisError, match="module_mm"):
        beveloid_nominal_model({**unit, "module_mm": "3"})
    with pytest.raises(AnalysisError, match="not 'beveloid'"):
        beveloid_nominal_model({**unit, "kind": "cycloid"})
    pinion, gear = paper_gears()
    with pytest.raises(AnalysisError, match="opposite"):
        BeveloidPair(pinion, pinion, 60.75)
    with pytest.raises(AnalysisError, match="base circles"):
        BeveloidPair(pinion, gear, 50.0)
    with pytest.raises(AnalysisError, match="flank side"):
        pinion.flank(0)
    with pytest.raises(AnalysisError, match="module"):
        BeveloidGear(20, 0.0, 20.0, 9.0, 6.0, 15.0)
    with pytest.raises(AnalysisError, match="points_per_cycle"):
        transmission_error(paper_pair(), Installation(), 2)


def test_contact_points_lie_on_both_flanks(pair: BeveloidPair) -> None:
    contact = tooth_pair_contact(pair, PAPER_CASES["combined"], DRIVE, np.radians([0.0, 9.0]))
    assert np.all(contact.pinion_radius_mm <= pair.pinion.tip_radius_mm(contact.pinion_z_mm))
    assert np.all(contact.gear_radius_mm <= pair.gear.tip_radius_mm(contact.gear_z_mm))
    assert np.all(np.abs(contact.gear_z_mm) <= 7.5 + 1e-9)
    rho = radial(pair.pinion.flank(DRIVE).surface(0.0, contact.pinion_z_mm)[0])
    assert np.all(rho > pair.pinion.base_radius_mm(DRIVE))
