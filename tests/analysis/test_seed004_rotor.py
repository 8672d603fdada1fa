"""Seed 004: geared rotor, coupled bending-torsion model and critical speeds.

The elements are checked against closed forms (simply supported Euler, Rayleigh and Timoshenko
shafts, free-free torsion, the Jeffcott rotor, a rigid gyroscopic rotor); the pair element
against the matrices printed in the seed, eqs. (9) and (11) against independent forms; Table 3
is printed paper vs ours with the difference for every value (``pytest -s``). The paper leaves
out the material and the positions of bearings, discs and gears: the comparison is made under
the assumptions of analysis/models/seed004_paper.py (docs/seed004.md) and comes out as it does.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from analysis.errors import AnalysisError
from analysis.models.seed004_gear_pair import (
    azimuth_transform,
    external_contact_ratio,
    gear_pair_element,
    line_of_action_direction,
    literal_unit_mesh_stiffness_N_per_m,
    mesh_properties,
    mesh_vector,
    pressure_angle_transform,
)
from analysis.models.seed004_modes import (
    RPM_PER_RAD_S,
    campbell,
    campbell_crossings_rpm,
    classify,
    critical_speeds,
    standstill_modes,
)
from analysis.models.seed004_paper import (
    PAPER_COUPLED_RPM,
    PAPER_ROTOR1_RPM,
    PAPER_ROTOR2_RPM,
    SHAFT_LENGTH_M,
    SHAFT_RADIUS_M,
    Assumptions,
    coupled_rotor,
    first_of_family,
    paper_pair,
    single_rotor,
    table3,
)
from analysis.models.seed004_rotor import Bearing, Disc, Rotor, assemble
from analysis.models.seed004_shaft import (
    PHI,
    STEEL,
    Material,
    Section,
    free_free_torsion_rad_s,
    shaft_element,
    simply_supported_bending_rad_s,
)

RIGID = 1e13  # N/m: a bearing far stiffer than any shaft here


def _compare(label: str, paper: float, ours: float, unit: str = "r/min") -> float:
    diff = ours - paper
    print(f"{label:40s} paper {paper:10.2f}  ours {ours:10.2f} {unit}  "
          f"diff {diff:+10.2f} ({100 * diff / paper:+6.1f} %)")
    return diff


def _pinned_shaft(length: float, radius: float, *, shear: bool, elements: int = 24,
                  material: Material = STEEL, discs: tuple[Disc, ...] = (),
                  k_bearing: float = RIGID) -> Rotor:
    bearings = (Bearing("A", 0.0, k_bearing, k_bearing), Bearing("B", length, k_bearing, k_bearing))
    return Rotor("shaft", length, radius, discs, bearings, material=material, elements=elements,
                 shear=shear)


def _bending_rpm(system) -> np.ndarray:
    """Distinct bending frequencies at standstill (each plane pair once), r/min."""
    rpm, shapes = standstill_modes(system)
    bend = [f for f, j in zip(rpm, range(rpm.size), strict=True)
            if classify(system, shapes[:, j]).torsion_share < 0.1]
    out: list[float] = []
    for f in bend:
        if not out or f - out[-1] > 1e-6 * f:
            out.append(f)
    return np.array(out)


# --- shaft elements against closed forms -------------------------------------------------


@pytest.mark.parametrize("shear,model", [(True, "timoshenko"), (False, "rayleigh")])
def test_beam_element_matches_simply_supported_closed_form(shear: bool, model: str) -> None:
    """A thick shaft (r = 0.075 m, L = 1 m) on rigid end supports: FE modes 1-3 vs the closed
    forms. Shear matters here (several %), so each element is told apart from the other."""
    length, radius = 1.0, 0.075
    fe = _bending_rpm(assemble([_pinned_shaft(length, radius, shear=shear, elements=48)]))
    section = Section(radius)
    for n in (1, 2, 3):
        exact = simply_supported_bending_rad_s(n, length, section, model=model) * RPM_PER_RAD_S
        other = simply_supported_bending_rad_s(
            n, length, section, model="rayleigh" if shear else "timoshenko") * RPM_PER_RAD_S
        err = fe[n - 1] / exact - 1
        print(f"{model:10s} mode {n}: FE {fe[n - 1]:10.2f}  closed {exact:10.2f} r/min  "
              f"err {err:+.1e}  (other model {other:10.2f})")
        assert abs(err) < 5e-4
        assert abs(other / exact - 1) > 10 * abs(err)


def test_timoshenko_matrices_are_the_galerkin_integrals_of_its_static_shape_functions() -> None:
    """Independent derivation: w cubic, psi = w' + (EI / kappa G A) w''' (static Timoshenko
    equilibrium), nodal values (w, psi) at both ends; K = int EI psi'^2 + kappa G A (w' - psi)^2,
    M = int rho A w^2 + rho I psi^2, by Gauss quadrature, against the element's x-z plane."""
    section, length = Section(0.075), 0.3
    el = shaft_element(length, section)
    ei = STEEL.youngs_modulus_Pa * section.second_moment_m4
    kga = STEEL.shear_coefficient * STEEL.shear_modulus_Pa * section.area_m2
    g = ei / kga
    rho = STEEL.density_kg_per_m3

    def w_row(z: float) -> np.ndarray:
        return np.array([1.0, z, z * z, z**3])

    def psi_row(z: float) -> np.ndarray:
        return np.array([0.0, 1.0, 2 * z, 3 * z * z + 6 * g])

    coef = np.linalg.inv(np.array([w_row(0), psi_row(0), w_row(length), psi_row(length)]))
    zs, ws = np.polynomial.legendre.leggauss(8)
    zs, ws = (zs + 1) * length / 2, ws * length / 2
    k = m = np.zeros((4, 4))
    for z, wt in zip(zs, ws, strict=True):
        nw, npsi = w_row(z) @ coef, psi_row(z) @ coef
        dnw = np.array([0.0, 1.0, 2 * z, 3 * z * z]) @ coef
        dnpsi = np.array([0.0, 0.0, 2.0, 6 * z]) @ coef
        k = k + wt * (ei * np.outer(dnpsi, dnpsi) + kga * np.outer(dnw - npsi, dnw - npsi))
        m = m + wt * rho * (section.area_m2 * np.outer(nw, nw)
                            + section.second_moment_m4 * np.outer(npsi, npsi))
    x_plane = [0, 3, 5, 8]  # x, theta_y of both nodes
    np.testing.assert_allclose(el.stiffness[np.ix_(x_plane, x_plane)], k, rtol=1e-10)
    np.testing.assert_allclose(el.mass[np.ix_(x_plane, x_plane)], m, rtol=1e-10)


def test_slender_paper_shafts_match_euler_bernoulli() -> None:
    """The paper's shafts (bare, rigid end supports): first critical speed vs (pi/L)^2
    sqrt(EI/rho A). This is also an upper bound for any mass placement on steel shafts
    supported at their ends: more mass and softer bearings only lower it."""
    for i in range(2):
        length, radius = SHAFT_LENGTH_M[i], SHAFT_RADIUS_M[i]
        fe = _bending_rpm(assemble([_pinned_shaft(length, radius, shear=True)]))[0]
        euler = simply_supported_bending_rad_s(1, length, Section(radius), model="euler")
        euler *= RPM_PER_RAD_S
        print(f"rotor {i + 1} bare shaft: FE {fe:.2f}, Euler-Bernoulli {euler:.2f} r/min")
        assert fe == pytest.approx(euler, rel=2e-3)


def test_torsion_element_is_eq4_and_converges_to_free_free_closed_form() -> None:
    length, radius = 4.6, 0.025
    section = Section(radius)
    el = shaft_element(0.5, section)
    t = [PHI, 5 + PHI]
    rho_ip_l = STEEL.density_kg_per_m3 * section.polar_moment_m4 * 0.5
    gip_l = STEEL.shear_modulus_Pa * section.polar_moment_m4 / 0.5
    np.testing.assert_allclose(el.mass[np.ix_(t, t)], rho_ip_l / 6 * np.array([[2, 1], [1, 2]]))
    np.testing.assert_allclose(el.stiffness[np.ix_(t, t)], gip_l * np.array([[1, -1], [-1, 1]]))
    system = assemble([_pinned_shaft(length, radius, shear=True)])
    rpm, shapes = standstill_modes(system)
    torsion = [f for j, f in enumerate(rpm) if classify(system, shapes[:, j]).kind == "torsion"]
    for n in (1, 2):
        exact = free_free_torsion_rad_s(n, length) * RPM_PER_RAD_S
        print(f"torsion mode {n}: FE {torsion[n - 1]:.1f}  closed {exact:.1f} r/min")
        assert torsion[n - 1] == pytest.approx(exact, rel=5e-3)


def test_jeffcott_rotor_closed_form() -> None:
    """A 10.4 kg disc at midspan of a (nearly) massless shaft on Table 1's bearing 1:
    w = sqrt(k / m), 1/k = L^3 / (48 E I) + 1 / (2 k_b). The disc does not tilt, so the
    synchronous critical speed is the same."""
    length, radius, mass, kb = 4.6, 0.025, 10.4, 1.02e7
    light = Material(density_kg_per_m3=1e-2)
    disc = Disc("disc", length / 2, mass, 0.3, 0.15)
    system = assemble([_pinned_shaft(length, radius, shear=False, material=light,
                                     discs=(disc,), k_bearing=kb)])
    ei = STEEL.youngs_modulus_Pa * Section(radius).second_moment_m4
    k = 1.0 / (length**3 / (48 * ei) + 1 / (2 * kb))
    exact = math.sqrt(k / mass) * RPM_PER_RAD_S
    fe = standstill_modes(system)[0][0]
    crit = critical_speeds(system)[0]
    print(f"Jeffcott: FE {fe:.4f}, synchronous {crit.speed_rpm:.4f}, closed {exact:.4f} r/min")
    assert fe == pytest.approx(exact, rel=1e-5)
    assert crit.speed_rpm == pytest.approx(exact, rel=1e-5)
    assert crit.kind == "forward"


def test_gyroscopic_terms_match_rigid_rotor_closed_form() -> None:
    """A rigid rotor (stiff, light shaft) with a disc J_d = 2, J_p = 0.8 kg m^2 on two bearings
    1e6 N/m at +-0.5 m. Conical whirl: J_d w^2 -+ J_p Omega w - k_theta = 0 (Campbell);
    synchronous w^2 = k_theta / (J_d -+ J_p) (forward / backward critical speed)."""
    stiff = Material(youngs_modulus_Pa=206e13, density_kg_per_m3=1e-2)
    kb, m, jd, jp = 1e6, 50.0, 2.0, 0.8
    rotor = _pinned_shaft(1.0, 0.05, shear=True, elements=4, material=stiff,
                          discs=(Disc("disc", 0.5, m, jp, jd),), k_bearing=kb)
    system = assemble([rotor])
    k_theta = 2 * kb * 0.5**2
    omega = 3000.0 / RPM_PER_RAD_S
    fwd = (jp * omega + math.sqrt((jp * omega) ** 2 + 4 * jd * k_theta)) / (2 * jd)
    bwd = (-jp * omega + math.sqrt((jp * omega) ** 2 + 4 * jd * k_theta)) / (2 * jd)
    freqs, forward = campbell(system, np.array([3000.0]), max_rpm=1e5)[0]
    conical = freqs[2:4]
    print(f"Campbell at 3000 r/min: conical {conical} r/min, closed "
          f"{bwd * RPM_PER_RAD_S:.3f} / {fwd * RPM_PER_RAD_S:.3f}; forward fractions "
          f"{forward[2:4]}")
    np.testing.assert_allclose(conical, np.array([bwd, fwd]) * RPM_PER_RAD_S, rtol=1e-4)
    assert forward[2] < 0.01 and forward[3] > 0.99
    crits = critical_speeds(system, include_backward=True, max_rpm=1e5)
    by_kind = {c.kind: c.speed_rpm for c in crits if c.speed_rpm > 3000}
    exact_f = math.sqrt(k_theta / (jd - jp)) * RPM_PER_RAD_S
    exact_b = math.sqrt(k_theta / (jd + jp)) * RPM_PER_RAD_S
    print(f"synchronous: forward {by_kind['forward']:.3f} (closed {exact_f:.3f}), "
          f"backward {by_kind['backward']:.3f} (closed {exact_b:.3f}) r/min")
    assert by_kind["forward"] == pytest.approx(exact_f, rel=1e-4)
    assert by_kind["backward"] == pytest.approx(exact_b, rel=1e-4)
    assert all(c.kind != "backward" for c in critical_speeds(system, max_rpm=1e5))


def test_campbell_crossings_agree_with_synchronous_eigenproblem() -> None:
    """The two ways to critical speeds agree (paper's rotor 1 and the coupled rotor, coarse
    mesh to keep the Campbell sweep short)."""
    a = Assumptions(elements=6)
    for name, system in (("rotor 1", single_rotor(0, a)), ("coupled", coupled_rotor(a))):
        sync = [c.speed_rpm for c in critical_speeds(system, max_rpm=1500.0)]
        grid = np.linspace(0.0, 1500.0, 31)
        camp = campbell_crossings_rpm(system, grid)
        print(f"{name}: synchronous {np.round(sync, 2)}  Campbell {np.round(camp, 2)} r/min")
        assert len(camp) == len(sync)
        np.testing.assert_allclose(camp, sync, rtol=2e-3)


# --- the gear pair element (eqs. 8-15) -----------------------------------------------------


def test_mesh_stiffness_contact_ratio_and_units() -> None:
    pair = paper_pair()
    mesh = mesh_properties(pair)
    # Eq. (9) against path of contact / base pitch.
    m, a = pair.module_m, pair.pressure_angle_rad
    (r1, r2), (rb1, rb2) = pair.pitch_radii_m, pair.base_radii_m
    path = (math.sqrt((r1 + m) ** 2 - rb1**2) + math.sqrt((r2 + m) ** 2 - rb2**2)
            - pair.center_distance_m * math.sin(a))
    eps_path = path / (math.pi * m * math.cos(a))
    print(f"k' = {mesh.single_pair_N_per_mm_um:.4f} N/(mm um), eps = {mesh.contact_ratio:.5f} "
          f"(path/pitch {eps_path:.5f}), k_m = {mesh.mesh_stiffness_N_per_m:.4e} N/m, "
          f"literal b[m] x 1e6: {literal_unit_mesh_stiffness_N_per_m(pair):.4e} N/m")
    assert mesh.contact_ratio == pytest.approx(eps_path, rel=1e-12)
    assert mesh.contact_ratio == pytest.approx(
        external_contact_ratio(38, 228, a, 1.0, a), rel=1e-15)
    k1 = 1 / (0.04723 + 0.15551 / 38 + 0.25791 / 228)
    assert mesh.single_pair_N_per_mm_um == pytest.approx(k1, rel=1e-12)
    expected = 100.0 * (0.75 * eps_path + 0.25) * k1 * 1e6  # b = 100 mm, N/um -> N/m
    assert mesh.mesh_stiffness_N_per_m == pytest.approx(expected, rel=1e-12)
    assert literal_unit_mesh_stiffness_N_per_m(pair) == pytest.approx(expected * 1e-9 * 1e6)


def test_eq11_equivalent_mass_printed_form_swaps_j1_and_j2() -> None:
    """Two gears on locked centers (torsion only): the mesh mode has w^2 = k_m (rb1^2/J1 +
    rb2^2/J2) = k_m / m_bar with the standard m_bar, and with c_m = 2 xi sqrt(m_bar k_m) its
    damping ratio is xi. The printed form gives a mass 36 x smaller and xi / 6."""
    pair = paper_pair()
    mesh = mesh_properties(pair)
    rb1, rb2 = pair.base_radii_m
    j1, j2 = pair.polar_inertia1_kgm2, pair.polar_inertia2_kgm2
    k_g, c_g = gear_pair_element(pair, mesh)
    phi = [4, 9]
    kt, ct = k_g[np.ix_(phi, phi)], c_g[np.ix_(phi, phi)]
    mt = np.diag([j1, j2])
    w2 = max(np.linalg.eigvals(np.linalg.solve(mt, kt)).real)
    m_std, m_pap = mesh.equivalent_mass_standard_kg, mesh.equivalent_mass_paper_kg
    print(f"m_bar standard {m_std:.5f} kg, printed {m_pap:.5f} kg (J1/rb2^2 = {j1 / rb2**2:.5f});"
          f" k_m/w^2 = {mesh.mesh_stiffness_N_per_m / w2:.5f} kg")
    assert mesh.mesh_stiffness_N_per_m / w2 == pytest.approx(m_std, rel=1e-9)
    assert m_std == pytest.approx(1 / (rb1**2 / j1 + rb2**2 / j2), rel=1e-12)
    assert m_pap == pytest.approx(j1 * j2 / (rb1**2 * j1 + rb2**2 * j2), rel=1e-12)
    assert m_std / m_pap > 30
    # Damping ratio of the mesh mode from the quadratic eigenproblem.
    for label, m_bar in (("standard", m_std), ("printed", m_pap)):
        c = ct * 2 * mesh.damping_ratio * math.sqrt(m_bar * mesh.mesh_stiffness_N_per_m) / (
            mesh.mesh_damping_Ns_per_m)
        a_mat = np.block([[np.zeros((2, 2)), np.eye(2)],
                          [-np.linalg.solve(mt, kt), -np.linalg.solve(mt, c)]])
        s = np.linalg.eigvals(a_mat)
        s = s[np.abs(s) > 1.0][0]
        zeta = -s.real / abs(s)
        print(f"{label:8s} m_bar: damping ratio of the mesh mode {zeta:.4f} (xi = 0.06)")
        if label == "standard":
            assert zeta == pytest.approx(0.06, rel=1e-6)
        else:
            assert zeta == pytest.approx(0.06 * math.sqrt(m_pap / m_std), rel=1e-6)


def test_pair_element_is_the_printed_matrix_in_the_rotor_frame() -> None:
    """K_G^p of eq. (13) has k_m (1, r1, -1, r2) on rows/columns y1, phi1, y2, phi2; T and D
    are rotations; D T v = [n, rb1, -n, rb2] with n the line of action, at 90 deg - alpha
    from the center line (sin beta, cos beta)."""
    pair = paper_pair()
    mesh = mesh_properties(pair)
    rb1, rb2 = pair.base_radii_m
    km = mesh.mesh_stiffness_N_per_m
    kp = km * np.outer(mesh_vector(rb1, rb2), mesh_vector(rb1, rb2))
    printed = {(1, 1): km, (1, 4): km * rb1, (1, 6): -km, (1, 9): km * rb2,
               (4, 4): km * rb1**2, (4, 6): -km * rb1, (4, 9): km * rb1 * rb2,
               (6, 6): km, (6, 9): -km * rb2, (9, 9): km * rb2**2}
    for (i, j), value in printed.items():
        assert kp[i, j] == pytest.approx(value) and kp[j, i] == pytest.approx(value)
    assert np.count_nonzero(kp) == 16
    for beta in (0.0, 45.0, 110.0):
        t = pressure_angle_transform(pair.pressure_angle_rad)
        d = azimuth_transform(math.radians(beta))
        np.testing.assert_allclose(t @ t.T, np.eye(10), atol=1e-15)
        np.testing.assert_allclose(d @ d.T, np.eye(10), atol=1e-15)
        k_g, _ = gear_pair_element(pair, mesh, azimuth_deg=beta)
        n = line_of_action_direction(pair.pressure_angle_rad, math.radians(beta))
        w = np.array([n[0], n[1], 0, 0, rb1, -n[0], -n[1], 0, 0, rb2])
        np.testing.assert_allclose(k_g, km * np.outer(w, w), rtol=1e-12, atol=1e-3)
        center = np.array([math.sin(math.radians(beta)), math.cos(math.radians(beta))])
        angle = math.degrees(math.acos(abs(n @ center)))
        assert angle == pytest.approx(90.0 - pair.pressure_angle_deg)


def test_azimuth_changes_nothing_with_isotropic_bearings_but_does_with_anisotropic() -> None:
    """Table 1 gives one stiffness per bearing: every rotor is isotropic, so turning the pair
    (beta) turns the whole problem and leaves every frequency. Anisotropic bearings feel it."""
    a = Assumptions(elements=8)
    spread = {}
    for aniso in (1.0, 0.5):
        sets = [standstill_modes(coupled_rotor(replace(a, azimuth_deg=b, anisotropy=aniso)))[0][:12]
                for b in (0.0, 45.0, 90.0, 137.0)]
        spread[aniso] = max(np.max(np.abs(s / sets[0] - 1)) for s in sets)
        print(f"k_yy/k_xx = {aniso}: largest change of the first 12 frequencies over beta "
              f"{spread[aniso]:.1e}")
    assert spread[1.0] < 1e-9
    assert spread[0.5] > 1e-4


# --- the paper's geared rotor, Table 3 -----------------------------------------------------


@pytest.fixture(scope="module")
def result():
    return table3()


def test_table3_paper_vs_ours(result) -> None:
    """Every Table 3 value beside ours (n-th beside n-th) and the paper's described modes
    beside ours of the same rotor and wave count. The differences are what they are: no
    placement of the masses on steel shafts supported at their ends reaches the paper's first
    single-rotor critical speeds (the bare shafts already stay below them)."""
    print("\nTable 3 (r/min), ours under the assumptions of docs/seed004.md:")
    for label, paper, ours in result.rows + result.family_rows:
        _compare(label, paper, ours)
    print("coupled, driven rotor's 1X line:",
          np.round([c.speed_rpm for c in result.coupled_rotor2_line[:10]], 2))
    print("coupled, standstill frequencies:", np.round(result.coupled_standstill_rpm[:12], 2))
    assert len(result.rows) == len(PAPER_ROTOR1_RPM) + len(PAPER_ROTOR2_RPM) + len(
        PAPER_COUPLED_RPM)
    assert all(math.isfinite(ours) for _, _, ours in result.rows + result.family_rows)
    for i, paper_first in enumerate((PAPER_ROTOR1_RPM[0], PAPER_ROTOR2_RPM[0])):
        bare = simply_supported_bending_rad_s(1, SHAFT_LENGTH_M[i], Section(SHAFT_RADIUS_M[i]))
        bare *= RPM_PER_RAD_S
        ours = (result.rotor1, result.rotor2)[i][0].speed_rpm
        print(f"rotor {i + 1}: ours {ours:.2f} <= bare steel shaft {bare:.2f} < paper "
              f"{paper_first:.2f} r/min (span for the bare shaft to reach it: "
              f"{SHAFT_LENGTH_M[i] * math.sqrt(bare / paper_first):.2f} m)")
        assert ours <= bare < paper_first


def test_coupled_first_critical_speed_is_below_single_rotors(result) -> None:
    """As the paper finds (335.33 < 336.18 r/min): the coupled first critical speed is below
    the single rotor's first."""
    ours = result.coupled[0].speed_rpm
    single = min(result.rotor1[0].speed_rpm, result.rotor2[0].speed_rpm)
    _compare("coupled 1st / single first (ours)", single, ours)
    _compare("coupled 1st / single first (paper)", PAPER_ROTOR1_RPM[0], PAPER_COUPLED_RPM[0])
    assert ours < single
    assert PAPER_COUPLED_RPM[0] < PAPER_ROTOR1_RPM[0]
    for rotor, waves, single_list in ((0, 0.5, result.rotor1), (1, 0.5, result.rotor2),
                                      (0, 1.0, result.rotor1), (1, 1.0, result.rotor2)):
        coupled = first_of_family(result.coupled, rotor, waves)
        alone = first_of_family(single_list, 0, waves)
        print(f"rotor {rotor + 1}, {waves:g} wave: coupled {coupled.speed_rpm:.2f} < single "
              f"{alone.speed_rpm:.2f} r/min")
        assert coupled.speed_rpm < alone.speed_rpm


def test_coupling_lowers_every_order_interlacing() -> None:
    """Why: the mesh adds a rank-one stiffness and turns one of the two free shaft rotations
    into a vibration mode, so (standstill) the k-th coupled frequency lies between the (k-1)-th
    and k-th of the two single rotors together."""
    singles = np.sort(np.concatenate([standstill_modes(single_rotor(i))[0] for i in range(2)]))
    coupled = standstill_modes(coupled_rotor())[0]
    print("single rotors:", np.round(singles[:10], 2))
    print("coupled:      ", np.round(coupled[:10], 2))
    n = 40
    assert np.all(coupled[:n] <= singles[:n] * (1 + 1e-9))
    assert np.all(coupled[1:n] >= singles[:n - 1] * (1 - 1e-9))


def test_mode_pattern_matches_paper(result) -> None:
    """Single rotors: the first three bending shapes are 0.5, 1, 1.5 waves. Coupled: the modes
    come in the paper's order rotor 1 (0.5), rotor 2 (0.5), rotor 1 (1), and rotor 2's
    1-wave mode after them; rotor 1's low modes in the line of action carry torsion
    (bending-torsion), like the paper's 4th."""
    for name, items in (("rotor 1", result.rotor1), ("rotor 2", result.rotor2)):
        waves = [c.waves for c in items if c.kind != "torsion"][:3]
        print(f"{name}: waves of the first bending modes {waves}")
        assert waves == [0.5, 1.0, 1.5]
    families: list[tuple[int, float]] = []
    for c in result.coupled:
        key = (c.dominant_rotor, c.waves)
        if c.kind != "torsion" and key not in families:
            families.append(key)
    print("coupled families in order (rotor index, waves):", families[:5])
    assert families[:3] == [(0, 0.5), (1, 0.5), (0, 1.0)]
    assert families.index((1, 1.0)) < families.index((0, 1.5))
    low = [c for c in result.coupled if c.speed_rpm < result.rotor1[1].speed_rpm]
    assert any(c.kind == "bending-torsion" and c.dominant_rotor == 0 for c in low)


def test_results_converge_with_mesh_refinement() -> None:
    coarse = standstill_modes(coupled_rotor(Assumptions(elements=12)))[0][:10]
    fine = standstill_modes(coupled_rotor(Assumptions(elements=36)))[0][:10]
    default = standstill_modes(coupled_rotor())[0][:10]
    print("12 / 24 / 36 elements:", np.round(coarse, 2), np.round(default, 2), np.round(fine, 2))
    np.testing.assert_allclose(default, fine, rtol=2e-3)


def test_bad_input_names_the_problem() -> None:
    brg = (Bearing("A", 0.0, 1e7, 1e7), Bearing("B", 1.0, 1e7, 1e7))
    with pytest.raises(AnalysisError, match="disc 9 at 2.0 m is off the shaft"):
        Rotor("r", 1.0, 0.05, (Disc("disc 9", 2.0, 1, 1, 1),), brg)
    with pytest.raises(AnalysisError, match="needs two bearings"):
        Rotor("r", 1.0, 0.05, (), brg[:1])
    with pytest.raises(AnalysisError, match="radius must be > 0"):
        Section(-0.1)
    with pytest.raises(AnalysisError, match="tooth counts"):
        replace(paper_pair(), z1=0)


def test_rig_rotor_command_writes_json(tmp_path) -> None:
    out = tmp_path / "crit.json"
    proc = subprocess.run(
        [sys.executable, "-m", "rig", "rotor", "--elements", "8", "--json", str(out)],
        capture_output=True, text=True, timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert "Table 3" in proc.stdout
    data = json.loads(out.read_text())
    assert data["format"] == "seed004-critical-speeds/1"
    assert [row["paper_rpm"] for row in data["table3"][:5]] == list(PAPER_ROTOR1_RPM)
    assert data["coupled"][0]["speed_rpm"] < data["rotor1"][0]["speed_rpm"]
    bad = subprocess.run([sys.executable, "-m", "rig", "rotor", "--gear-at", "1.5"],
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2
    assert ("Invalid value for '--gear-at': expected from 0 to 1 of the shaft's length "
            "(got 1.5)") in bad.stderr
