"""The spur gear pair element of seed 004 (Che et al. 2012), section 2, eqs. (8)-(15).

* Eqs. (8)-(11), mesh stiffness and damping of the *external* pair of Table 2, reusing
  :mod:`analysis.models.mesh_stiffness` (k' of eq. 8, eq. 10, eq. 11) with eq. (9) written here
  for an external pair (both terms positive). Eq. (8) with the face width b in mm gives N/um;
  x 1e6 -> N/m (with b in m, as Table 2 prints it, the seed's ``x 10^6`` would give a stiffness
  1000 x 1000 too small, 3.1e5 N/m: see :func:`literal_unit_mesh_stiffness_N_per_m`).
* Eqs. (12)-(13): the element on the line of action (frame p), coordinates
  ``[x1 y1 tx1 ty1 phi1 x2 y2 tx2 ty2 phi2]``; the mesh deflection is
  ``delta = y1 + rb1 phi1 - y2 + rb2 phi2`` (base radii), so ``K_G = k_m v v^T`` and
  ``C_G = c_m v v^T`` with ``v = [0 1 0 0 rb1 0 -1 0 0 rb2]`` (the matrices printed in the seed).
  The gears' masses, inertias and gyroscopic terms of M_G and C_G are carried by the rotor
  model's gear discs, so the element adds only the mesh.
* Eqs. (14)-(15): the transformations T (pressure angle, line of action -> center line) and
  D (azimuth beta, center line -> the rotor frame with Y vertical), as printed; the element in
  the rotor frame is ``D T K_G T^T D^T``.

The simplification of section 3 (the seed drops the higher-order terms of eqs. 8 and 11) is
taken as: k_m and c_m are constant, evaluated at the standard center distance.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Literal

import numpy as np

from analysis.errors import AnalysisError
from analysis.models.mesh_stiffness import (
    DEFAULT_DAMPING_RATIO,
    equivalent_mass_kg,
    mesh_damping_Ns_per_m,
    mesh_stiffness_N_per_um,
    single_pair_stiffness_N_per_mm_um,
    working_pressure_angle_rad,
)


@dataclass(frozen=True)
class SpurPair:
    """Seed 004 Table 2: an external spur pair (SI units; tooth data as printed)."""

    z1: int
    z2: int
    module_m: float
    face_width_m: float
    pressure_angle_deg: float
    addendum_coeff: float
    mass1_kg: float
    mass2_kg: float
    polar_inertia1_kgm2: float
    polar_inertia2_kgm2: float
    azimuth_deg: float

    def __post_init__(self) -> None:
        if self.z1 <= 0 or self.z2 <= 0:
            raise AnalysisError(f"tooth counts must be positive, got {self.z1}, {self.z2}")
        if min(self.module_m, self.face_width_m, self.mass1_kg, self.mass2_kg,
               self.polar_inertia1_kgm2, self.polar_inertia2_kgm2) <= 0:
            raise AnalysisError("module, face width, masses and inertias must be > 0")

    @property
    def pressure_angle_rad(self) -> float:
        return math.radians(self.pressure_angle_deg)

    @property
    def pitch_radii_m(self) -> tuple[float, float]:
        return self.module_m * self.z1 / 2.0, self.module_m * self.z2 / 2.0

    @property
    def base_radii_m(self) -> tuple[float, float]:
        c = math.cos(self.pressure_angle_rad)
        r1, r2 = self.pitch_radii_m
        return r1 * c, r2 * c

    @property
    def center_distance_m(self) -> float:
        """Standard center distance R = r1 + r2 (m)."""
        return sum(self.pitch_radii_m)

    @property
    def speed_ratio(self) -> float:
        """Omega2 / Omega1 = -z1 / z2 (external pair: the driven gear turns the other way)."""
        return -self.z1 / self.z2


def external_contact_ratio(
    z1: int, z2: int, pressure_angle_rad: float, addendum_coeff: float, working_angle_rad: float
) -> float:
    """Seed 004 eq. (9): eps = [z1 (tan a_a1 - tan a') + z2 (tan a_a2 - tan a')] / (2 pi)
    for an external pair, tip pressure angles cos a_a = z cos a / (z + 2 h_a) (dimensionless)."""
    tan_w = math.tan(working_angle_rad)
    total = 0.0
    for z in (z1, z2):
        cos_tip = z * math.cos(pressure_angle_rad) / (z + 2.0 * addendum_coeff)
        total += z * (math.tan(math.acos(cos_tip)) - tan_w)
    eps = total / (2.0 * math.pi)
    if eps <= 0.0:
        raise AnalysisError(f"contact ratio {eps:.3f} <= 0: the teeth do not mesh")
    return eps


@dataclass(frozen=True)
class MeshProperties:
    """Eqs. (8)-(11) for one pair: k' (N/(mm um)), eps, alpha' (deg), k_m (N/m), the
    equivalent mass of eq. (11) in both forms (kg) and c_m (N s/m) from the chosen form."""

    single_pair_N_per_mm_um: float
    contact_ratio: float
    working_pressure_angle_deg: float
    mesh_stiffness_N_per_m: float
    equivalent_mass_standard_kg: float
    equivalent_mass_paper_kg: float
    damping_ratio: float
    mesh_damping_Ns_per_m: float

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def mesh_properties(
    pair: SpurPair,
    *,
    center_distance_m: float | None = None,
    damping_ratio: float = DEFAULT_DAMPING_RATIO,
    form: Literal["standard", "paper"] = "standard",
) -> MeshProperties:
    """Seed 004 eqs. (8)-(11) for an external pair at a center distance (default standard)."""
    r_std = pair.center_distance_m
    r_act = r_std if center_distance_m is None else center_distance_m
    alpha_w = working_pressure_angle_rad(r_std, r_act, pair.pressure_angle_rad)
    k1 = single_pair_stiffness_N_per_mm_um(pair.z1, pair.z2)
    eps = external_contact_ratio(
        pair.z1, pair.z2, pair.pressure_angle_rad, pair.addendum_coeff, alpha_w
    )
    k_m = mesh_stiffness_N_per_um(pair.face_width_m * 1e3, eps, k1) * 1e6
    rb1, rb2 = pair.base_radii_m
    j1, j2 = pair.polar_inertia1_kgm2, pair.polar_inertia2_kgm2
    m_std = equivalent_mass_kg(j1, j2, rb1, rb2, "standard")
    m_pap = equivalent_mass_kg(j1, j2, rb1, rb2, "paper")
    c_m = mesh_damping_Ns_per_m(m_std if form == "standard" else m_pap, k_m, damping_ratio)
    return MeshProperties(
        single_pair_N_per_mm_um=k1,
        contact_ratio=eps,
        working_pressure_angle_deg=math.degrees(alpha_w),
        mesh_stiffness_N_per_m=k_m,
        equivalent_mass_standard_kg=m_std,
        equivalent_mass_paper_kg=m_pap,
        damping_ratio=damping_ratio,
        mesh_damping_Ns_per_m=c_m,
    )


def literal_unit_mesh_stiffness_N_per_m(pair: SpurPair) -> float:
    """Eq. (8) read literally: b in m (Table 2) times 1e6, k' in N/(mm um) (N/m, 1e-6 x ours)."""
    k1 = single_pair_stiffness_N_per_mm_um(pair.z1, pair.z2)
    eps = external_contact_ratio(
        pair.z1, pair.z2, pair.pressure_angle_rad, pair.addendum_coeff, pair.pressure_angle_rad
    )
    return pair.face_width_m * (0.75 * eps + 0.25) * k1 * 1e6


def mesh_vector(base_radius1_m: float, base_radius2_m: float) -> np.ndarray:
    """v of eq. (13) on the line of action: delta = v . u_G^p (m per m or per rad)."""
    return np.array([0.0, 1.0, 0.0, 0.0, base_radius1_m, 0.0, -1.0, 0.0, 0.0, base_radius2_m])


def _block(rot: np.ndarray) -> np.ndarray:
    out = np.zeros((10, 10))
    for start in (0, 2, 5, 7):
        out[start:start + 2, start:start + 2] = rot
    out[4, 4] = out[9, 9] = 1.0
    return out


def pressure_angle_transform(pressure_angle_rad: float) -> np.ndarray:
    """T of eq. (14) (s = sin a, c = cos a), as printed: u^p = T^T u^c."""
    s, c = math.sin(pressure_angle_rad), math.cos(pressure_angle_rad)
    return _block(np.array([[s, -c], [c, s]]))


def azimuth_transform(azimuth_rad: float) -> np.ndarray:
    """D of eq. (15) (S = sin beta, C = cos beta), as printed: u^c = D^T u^v."""
    s, c = math.sin(azimuth_rad), math.cos(azimuth_rad)
    return _block(np.array([[c, s], [-s, c]]))


def gear_pair_element(
    pair: SpurPair, mesh: MeshProperties, *, azimuth_deg: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Mesh stiffness (N/m) and damping (N s/m) matrices of eq. (15), 10 x 10, in the rotor
    frame: ``D T (k_m v v^T) T^T D^T`` and the same with c_m."""
    rb1, rb2 = pair.base_radii_m
    v = mesh_vector(rb1, rb2)
    beta = math.radians(pair.azimuth_deg if azimuth_deg is None else azimuth_deg)
    dt = azimuth_transform(beta) @ pressure_angle_transform(pair.pressure_angle_rad)
    w = dt @ v
    return mesh.mesh_stiffness_N_per_m * np.outer(w, w), mesh.mesh_damping_Ns_per_m * np.outer(w, w)


def line_of_action_direction(pressure_angle_rad: float, azimuth_rad: float) -> np.ndarray:
    """Unit vector (x, y) of the line of action in the rotor frame implied by eqs. (14)-(15):
    the center line points along (sin beta, cos beta); the line of action makes the angle
    90 deg - alpha with it."""
    s, c = math.sin(pressure_angle_rad), math.cos(pressure_angle_rad)
    n_c = np.array([-c, s])  # in the center-line frame
    sb, cb = math.sin(azimuth_rad), math.cos(azimuth_rad)
    x_c, y_c = np.array([cb, -sb]), np.array([sb, cb])
    return n_c[0] * x_c + n_c[1] * y_c
