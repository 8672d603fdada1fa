"""Seed 002: compound cycloid profile, conjugate, modifications and the `cycloid` unit model.

Every comparison with the paper prints the paper's figure, ours and the difference
(``pytest -s`` shows them). Table 1 is missing from the paper: the assumed pair is
rig/examples/units/cycloid-seed002.json (docs/seed002.md says why). Where a claim fails for
every parameter in the paper's ranges, the test asserts that it fails, with the numbers.
"""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest

from analysis.errors import AnalysisError
from analysis.models.cycloid_nominal import CycloidNominalModel, cycloid_nominal_model
from analysis.models.mesh_stiffness import single_pair_stiffness_N_per_mm_um
from analysis.models.seed002_clearance import (
    PAPER_FINAL_SIDE_CLEARANCE_MM,
    PAPER_ROTATION_MM,
    PAPER_ROTATION_SIDE_CLEARANCE_MM,
    PAPER_SHIFT_MM,
    PAPER_SHIFT_SIDE_CLEARANCE_MM,
    FlankContacts,
    Modification,
    closed_form_clearance,
    flank_clearance,
    free_play,
    loaded_turn_rad,
    radial_gap_mm,
)
from analysis.models.seed002_cycloid import (
    CompoundCycloidPair,
    conjugate_profile,
    eq1_points,
    internal_tooth_thickness_mm,
    meshing_residual_mm2,
    profile_points,
)
from tests.support.paths import REPO

UNIT_FILE = REPO / "rig" / "examples" / "units" / "cycloid-seed002.json"
UNIT = json.loads(UNIT_FILE.read_text())
PAIR = CompoundCycloidPair(
    UNIT["module_mm"], UNIT["z_internal"], UNIT["z_external"], UNIT["height_coeff"],
    UNIT["shape_coeff"],
)
SHIFT = Modification(shift_mm=PAPER_SHIFT_MM)
ROTATION = Modification(rotation_mm=PAPER_ROTATION_MM)
BOTH = Modification(shift_mm=PAPER_SHIFT_MM, rotation_mm=PAPER_ROTATION_MM)
H1_RANGE = (0.20, 0.25, 0.30, 0.35, 0.40)  # Fig. 15(a), Table 5
F1_RANGE = (0.10, 0.15, 0.20, 0.25, 0.30)  # Fig. 15(b); Table 6 stops at 0.200


def _compare(label: str, paper: float, ours: float, unit: str = "um") -> float:
    diff = ours - paper
    rel = f"{100 * diff / paper:+7.1f} %" if paper else ""
    print(f"{label:58s} paper {paper:8.3f}  ours {ours:8.3f} {unit}  diff {diff:+8.3f} {rel}")
    return diff


def test_eq11_without_rotation_is_eq1() -> None:
    xi = np.linspace(0.0, 2 * math.pi, 50001)
    gap = np.abs(profile_points(PAIR, xi) - eq1_points(PAIR, xi)).max()
    print(f"max |eq.(11, Delta2=0) - eq.(1)| = {gap:.2e} mm")
    assert gap < 1e-10


def test_conjugate_solves_meshing_equation_and_touches_without_interference() -> None:
    """Eqs. (2)-(8): every generated point satisfies eq. (5); the unmodified pair, assembled
    at the eccentricity, touches on many flanks at once and has no free play."""
    xi = np.linspace(0.0, 2 * math.pi / PAIR.z_internal, 4001)
    conj = conjugate_profile(PAIR, xi)
    assert conj.points.size == xi.size
    residual = np.abs(meshing_residual_mm2(PAIR, conj.xi_rad, conj.beta_rad)).max()
    print(f"eq. (5) residual at the solved beta: {residual:.1e} mm^2")
    assert residual < 1e-8
    radii = np.abs(conj.points)
    r1, e1 = PAIR.pitch_radius_external_mm, PAIR.e1_mm
    print(f"gear 1 radii {radii.min():.4f}-{radii.max():.4f} mm, r1 = {r1} mm, 2 e1 = {2 * e1}")
    assert radii.min() == pytest.approx(r1 - 2 * e1, abs=1e-6)
    assert radii.max() == pytest.approx(r1 + 2 * e1, abs=1e-6)
    play = free_play(PAIR, Modification())
    print(f"unmodified, mesh phase 0: play {play.play_arcmin:.4f} arcmin")
    assert play.play_arcmin < 0.02  # the sampling floor of the numerics


def test_unmodified_pair_contact_ratio_and_phase_play() -> None:
    """Each flank of gear 2 is in conjugate contact for half a mesh cycle (beta spans half a
    pitch per flank): the paper's 'multi-tooth contact' is not geometric, it needs load. So even
    the unmodified pair has a one-sided free play at some mesh phases, and never interferes."""
    xi = np.linspace(-math.pi / PAIR.z_internal, math.pi / PAIR.z_internal, 20001)[1:-1]
    conj = conjugate_profile(PAIR, xi)
    pitch = 2 * math.pi / PAIR.z_internal
    spans = [np.ptp(conj.beta_rad[xi > 0]) / pitch, np.ptp(conj.beta_rad[xi < 0]) / pitch]
    print(f"contact ratio per flank (beta span / pitch): {spans[0]:.4f}, {spans[1]:.4f}")
    assert spans == pytest.approx([0.5, 0.5], abs=1e-3)
    quarter = free_play(PAIR, Modification(), pitch / 4)
    a, b = quarter.side_um(PAIR.pitch_radius_external_mm)
    print(f"unmodified pair at a quarter mesh cycle: {a:.3f} / {b:.3f} um per side at r1")
    assert max(a, b) > 5.0 and min(a, b) < 0.2
    teeth = conjugate_profile(PAIR, np.linspace(0, 2 * math.pi, 80001, endpoint=False)).points
    worst = min(radial_gap_mm(PAIR, teeth, ph).min() for ph in np.linspace(0, pitch, 9))
    print(f"worst interference over the mesh cycle: {-1000 * worst:.4f} um")
    assert worst > -1e-5  # mm: sampling noise only


def test_printed_normal_of_eq3_is_not_conjugate() -> None:
    """Eq. (3) prints N = (x', -y'); the gear it generates interferes with gear 2."""
    xi = np.linspace(0.0, 2 * math.pi, 80001)
    printed = conjugate_profile(PAIR, xi, normal="printed")
    residual = np.abs(meshing_residual_mm2(PAIR, printed.xi_rad, printed.beta_rad)).max()
    printed_gap = radial_gap_mm(PAIR, printed.points).min()
    corrected_gap = radial_gap_mm(PAIR, conjugate_profile(PAIR, xi).points).min()
    print(f"printed normal: eq. (5) residual {residual:.1f} mm^2, interference "
          f"{-1000 * printed_gap:.1f} um; corrected: {-1000 * corrected_gap:.4f} um")
    assert residual > 1.0
    assert printed_gap < -0.01 and corrected_gap > -1e-6


def test_shift_clearance_against_paper() -> None:
    """Fig. 6: a 0.016 mm shift gives 'about 0.008 mm' single-side clearance."""
    num = flank_clearance(PAIR, SHIFT)
    closed = closed_form_clearance(PAIR, SHIFT)
    paper = 1000 * PAPER_SHIFT_SIDE_CLEARANCE_MM
    _compare("shift 0.016: side clearance along pitch circle r1", paper, num.circumferential_um)
    _compare("shift 0.016: side clearance normal to the flank", paper, num.normal_um)
    _compare("shift 0.016: tip (radial) clearance, paper: = Delta1", 16.0, num.tip_reduction_um)
    assert num.circumferential_um == pytest.approx(closed.circumferential_um, rel=2e-3)
    assert num.normal_um == pytest.approx(closed.normal_um, rel=2e-3)
    assert num.tip_reduction_um == pytest.approx(16.0, abs=1e-3)


def test_shift_claim_over_paper_ranges() -> None:
    """The 0.008 mm claim against every (h1, f1) of the paper's ranges (first order, checked
    numerically at the extremes): along the pitch circle it never comes within 25 %."""
    circ, normal = {}, {}
    for h1, f1 in itertools.product(H1_RANGE, F1_RANGE):
        cf = closed_form_clearance(CompoundCycloidPair(2.0, 40, 39, h1, f1), SHIFT)
        circ[h1, f1], normal[h1, f1] = cf.circumferential_um, cf.normal_um
    lo_c, hi_c = min(circ, key=circ.get), max(circ, key=circ.get)
    lo_n = min(normal, key=normal.get)
    print(f"pitch-circle clearance over h1 0.2-0.4, f1 0.1-0.3: {circ[lo_c]:.2f} um at {lo_c} "
          f"to {circ[hi_c]:.2f} um at {hi_c}; normal: min {normal[lo_n]:.2f} um at {lo_n}")
    for (h1, f1), z2, z1, m in (((0.4, 0.3), 20, 19, 1.0), ((0.2, 0.1), 60, 58, 2.5)):
        num = flank_clearance(CompoundCycloidPair(m, z2, z1, h1, f1), SHIFT)
        assert num.circumferential_um == pytest.approx(circ[h1, f1], rel=3e-3)
        assert num.normal_um == pytest.approx(normal[h1, f1], rel=3e-3)
    _compare("shift: smallest pitch-circle clearance in ranges", 8.0, circ[lo_c])
    _compare("shift: smallest normal clearance in ranges", 8.0, normal[lo_n])
    assert circ[lo_c] > 1.25 * 8.0  # the claim fails along the pitch circle everywhere
    assert lo_n == (0.4, 0.3) and 8.0 < normal[lo_n] < 1.1 * 8.0


def test_rotation_clearance_is_twice_delta2() -> None:
    """Fig. 7: the side clearance changes by 2 Delta2 (0.004 mm for 0.002 mm)."""
    num = flank_clearance(PAIR, ROTATION)
    paper = 1000 * PAPER_ROTATION_SIDE_CLEARANCE_MM
    _compare("rotation 0.002: change along pitch circle r1", paper, -num.circumferential_um)
    _compare("rotation 0.002: change normal to the flank", paper, -num.normal_um)
    _compare("rotation 0.002: tip (radial) change", 0.0, num.tip_reduction_um)
    # the sign: Delta2 > 0 thins gear 2 (the tool), so gear 1 gets thicker: clearance shrinks
    assert -num.circumferential_um == pytest.approx(paper, rel=1e-3)
    assert abs(num.tip_reduction_um) < 1e-3
    for h1, f1 in ((0.2, 0.1), (0.4, 0.3)):
        other = flank_clearance(CompoundCycloidPair(1.0, 30, 29, h1, f1), ROTATION)
        assert -other.circumferential_um == pytest.approx(paper, rel=1e-3)


def test_combined_modification_against_paper() -> None:
    """Eqs. (13)-(14): the paper wants 0.008 - 0.004 = 0.004 mm single-side clearance."""
    both = flank_clearance(PAIR, BOTH)
    shift, rot = flank_clearance(PAIR, SHIFT), flank_clearance(PAIR, ROTATION)
    paper = 1000 * PAPER_FINAL_SIDE_CLEARANCE_MM
    _compare("shift + rotation: side clearance along r1", paper, both.circumferential_um)
    _compare("shift + rotation: side clearance normal", paper, both.normal_um)
    _compare("shift + rotation: radial clearance", 16.0, both.tip_reduction_um)
    additive = shift.circumferential_um + rot.circumferential_um
    assert both.circumferential_um == pytest.approx(additive, abs=0.01)
    play = free_play(PAIR, BOTH)
    a, b = play.side_um(PAIR.pitch_radius_external_mm)
    print(f"assembled pair, mesh phase 0: {a:.2f} / {b:.2f} um per side at r1, "
          f"play {play.play_arcmin:.3f} arcmin")
    assert a >= both.circumferential_um - 0.01 and b >= both.circumferential_um - 0.01


def test_play_over_mesh_cycle_touches_pitch_value() -> None:
    """Over a mesh cycle the first contact reaches the pitch-point clearance on each side."""
    pitch = flank_clearance(PAIR, BOTH).circumferential_um
    sides = []
    for phase in np.linspace(0, 2 * math.pi / PAIR.z_internal, 9)[:-1]:
        sides += list(free_play(PAIR, BOTH, phase).side_um(PAIR.pitch_radius_external_mm))
    print(f"per-side first contact over a mesh cycle: {min(sides):.3f}-{max(sides):.3f} um, "
          f"pitch-point clearance {pitch:.3f} um")
    assert min(sides) == pytest.approx(pitch, abs=0.02)


def test_rotation_without_shift_interferes() -> None:
    with pytest.raises(AnalysisError, match="interferes"):
        free_play(PAIR, ROTATION)


@pytest.mark.parametrize("coeff", ["h1", "f1"])
def test_fig15_profile_trends(coeff: str) -> None:
    """Fig. 15: raising h1 makes the tooth taller; raising h1 or f1 thickens the tooth between
    pitch and tip circle and thins it between pitch and root circle."""
    values = H1_RANGE if coeff == "h1" else F1_RANGE
    rows = []
    for v in values:
        pair = CompoundCycloidPair(2.0, 40, 39, v if coeff == "h1" else 0.3,
                                   v if coeff == "f1" else 0.2)
        add, height = internal_tooth_thickness_mm(pair, "addendum")
        ded, _ = internal_tooth_thickness_mm(pair, "dedendum")
        rows.append((add, ded, height))
        print(f"{coeff} = {v:.2f}: height {height:.3f} mm, thickness tip side {add:.4f} mm, "
              f"root side {ded:.4f} mm")
    add, ded, height = np.array(rows).T
    assert np.all(np.diff(add) > 0) and np.all(np.diff(ded) < 0)
    if coeff == "h1":
        assert np.allclose(height, 4 * 2.0 * np.array(values))  # 4 e1 = 4 m h1
        assert np.all(np.diff(height) > 0)


def test_loaded_turn_matches_spring_closed_form() -> None:
    contacts = FlankContacts(side=1, angle_rad=np.array([1e-4, 3e-4]),
                             arm_mm=np.array([50.0, 40.0]), reach_rad=1e-2)
    k = 80.0  # N/um
    one = 80e3 * 50.0**2  # N mm / rad
    t_small = 0.5 * one * 2e-4 / 1000.0  # N m, before the second flank engages
    turn = loaded_turn_rad(contacts, np.array([t_small, -t_small]), k)
    assert turn[0] == pytest.approx(1e-4 + 0.5 * 2e-4, rel=1e-12)
    t_big = (one * 2e-4 + (one + 80e3 * 40.0**2) * 1e-4) / 1000.0
    assert loaded_turn_rad(contacts, np.array([t_big]), k)[0] == pytest.approx(4e-4)


def test_cycloid_nominal_model_from_unit_file() -> None:
    model, assumptions = cycloid_nominal_model(UNIT)
    assert isinstance(model, CycloidNominalModel)
    k_pair = UNIT["face_width_mm"] * single_pair_stiffness_N_per_mm_um(40, 39)
    print(f"play {model.play_arcmin:.3f} arcmin ({model.play_min_arcmin:.3f}-"
          f"{model.play_max_arcmin:.3f} over the mesh cycle), K {model.stiffness_Nm_per_arcmin:.1f}"
          f" N*m/arcmin, {model.flanks_loaded_at_reference:.1f} flanks loaded at 200 N*m")
    assert model.contact_stiffness_N_per_um == pytest.approx(k_pair)
    # play between the pitch-point value (both sides at 16.27 um on r1) and the phase-0 value
    r1 = PAIR.pitch_radius_external_mm
    pitch_arcmin = math.degrees(2 * model.side_clearance_pitch_um / 1000 / r1) * 60
    assert pitch_arcmin < model.play_min_arcmin <= model.play_arcmin <= model.play_max_arcmin
    # stiffness bounded by one flank (softest) and all loaded flanks at the pitch arm
    arm = r1 * math.sin(math.atan2(2 * 0.3, 1 - 4 * 0.2 * 0.3))
    one_flank = k_pair * 1e3 * arm**2 / 1e3 * math.radians(1 / 60)
    assert one_flank < model.stiffness_Nm_per_arcmin < 4 * one_flank
    torque = np.array([0.0, 100.0, 200.0, 0.0, -200.0, 0.0])
    twist = model.twist_arcmin(torque)
    assert twist[0] == pytest.approx(-model.play_arcmin / 2)
    assert twist[2] - twist[4] == pytest.approx(model.lost_motion_arcmin(200.0, 100.0))
    assert model.backlash_arcmin == model.play_arcmin
    assert not any("missing" in a for a in assumptions)
    assert json.dumps(model.to_dict())


def test_cycloid_nominal_model_errors_and_assumptions() -> None:
    bare = {k: UNIT[k] for k in ("kind", "z_internal", "z_external", "module_mm")}
    with pytest.raises(AnalysisError, match="'height_coeff', 'shape_coeff'"):
        cycloid_nominal_model(bare)
    with pytest.raises(AnalysisError, match="module_mm"):
        cycloid_nominal_model({**UNIT, "module_mm": "two"})
    with pytest.raises(AnalysisError, match="interferes"):
        cycloid_nominal_model({**UNIT, "shift_modification_mm": 0.0})
    rigid, notes = cycloid_nominal_model(
        {k: v for k, v in UNIT.items() if k not in ("face_width_mm", "reference_torque_Nm")}
    )
    assert math.isinf(rigid.stiffness_Nm_per_arcmin)
    assert any("face_width_mm" in n for n in notes)
    assert any("reference_torque_Nm" in n for n in notes)
    assert rigid.to_dict()["stiffness_Nm_per_arcmin"] is None
