"""Mesh stiffness and damping of a spur pair, seed 004 (Che et al. 2012) eqs. (8)-(11),
applied to the internal involute pair of seed 000.

Rules used here (the seed writes eqs. (8)-(10) for an external pair):

* eq. (8) single-pair stiffness ``k' = 1 / (0.04723 + 0.15551 / z1 + 0.25791 / z2)`` N/(mm um)
  with **both tooth counts positive**, ``z1 = z_internal`` and ``z2 = z_external`` (pinned by
  run-format.md). The seed prints 0.1551; ISO 6336-1 (and the seed's own source) has 0.15551,
  which is the default; ``paper_coefficient=True`` gives the printed value.
* eq. (9) contact ratio for the internal pair: the ring's term changes sign,
  ``eps = [z_ext (tan a_a,ext - tan a') - z_int (tan a_a,int - tan a')] / (2 pi)``,
  with the ring's tip circle *inside* (``d_a,int = m z_int - 2 h_a m``).
* eq. (10) working pressure angle ``a' = acos(R cos(a) / R')`` with R the standard and R' the
  actual center distance (for the internal pair R = m (z_int - z_ext) / 2).
* eq. (8) ``k_m = b (0.75 eps + 0.25) k'`` is N/um with b in mm (the seed's ``x 10^6`` turns
  this into N/m; its Table 2 gives b in m, which would need x 10^9).
* eq. (11) ``c_m = 2 xi sqrt(m_bar k_m)``. The seed prints
  ``m_bar = J1 J2 / (r1^2 J1 + r2^2 J2)``; the equivalent mass of two inertias on the line of
  action is ``1 / (r1^2 / J1 + r2^2 / J2) = J1 J2 / (r1^2 J2 + r2^2 J1)`` (J1 and J2 swapped
  in the print). The standard form is the default; ``form="paper"`` gives the printed one.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Literal

from analysis.errors import AnalysisError

ISO_C2 = 0.15551
PAPER_C2 = 0.1551
C1 = 0.04723
C3 = 0.25791
RAD_PER_ARCMIN = math.pi / (180.0 * 60.0)
DEFAULT_DAMPING_RATIO = 0.06
"""Seed 004: damping ratio xi = 0.06 used with eq. (11)."""


def single_pair_stiffness_N_per_mm_um(
    z_internal: int, z_external: int, *, paper_coefficient: bool = False
) -> float:
    """Seed 004 eq. (8): single tooth-pair stiffness k' (N per mm face width per um)."""
    if z_internal <= 0 or z_external <= 0:
        raise AnalysisError(f"tooth counts must be positive, got {z_internal}, {z_external}")
    c2 = PAPER_C2 if paper_coefficient else ISO_C2
    return 1.0 / (C1 + c2 / z_internal + C3 / z_external)


def working_pressure_angle_rad(
    standard_center_distance_mm: float, center_distance_mm: float, pressure_angle_rad: float
) -> float:
    """Seed 004 eq. (10): a' = acos(R cos(a) / R') (rad) for the actual center distance R'."""
    ratio = standard_center_distance_mm * math.cos(pressure_angle_rad) / center_distance_mm
    if not 0.0 < ratio <= 1.0:
        raise AnalysisError(
            f"center distance {center_distance_mm} mm is below the base-circle distance "
            f"{standard_center_distance_mm * math.cos(pressure_angle_rad):.4f} mm: no mesh"
        )
    return math.acos(ratio)


def internal_contact_ratio(
    z_internal: int,
    z_external: int,
    module_mm: float,
    pressure_angle_rad: float,
    addendum_coeff: float,
    working_angle_rad: float,
) -> float:
    """Seed 004 eq. (9) for the internal pair (ring term with the minus sign), dimensionless."""
    m = module_mm
    tip_int = m * z_internal - 2.0 * addendum_coeff * m
    tip_ext = m * z_external + 2.0 * addendum_coeff * m
    base_int = m * z_internal * math.cos(pressure_angle_rad)
    base_ext = m * z_external * math.cos(pressure_angle_rad)
    if tip_int <= base_int:
        raise AnalysisError(
            f"ring tip diameter {tip_int:.4f} mm is inside its base circle {base_int:.4f} mm: "
            f"addendum_coeff {addendum_coeff} too large for z_internal {z_internal}"
        )
    tan_tip_int = math.tan(math.acos(base_int / tip_int))
    tan_tip_ext = math.tan(math.acos(base_ext / tip_ext))
    tan_w = math.tan(working_angle_rad)
    eps = (z_external * (tan_tip_ext - tan_w) - z_internal * (tan_tip_int - tan_w)) / (2 * math.pi)
    if eps <= 0.0:
        raise AnalysisError(f"contact ratio {eps:.3f} <= 0: the teeth do not mesh")
    return eps


def mesh_stiffness_N_per_um(
    face_width_mm: float, contact_ratio: float, single_pair_N_per_mm_um: float
) -> float:
    """Seed 004 eq. (8): mean mesh stiffness k_m = b (0.75 eps + 0.25) k' (N/um, b in mm)."""
    return face_width_mm * (0.75 * contact_ratio + 0.25) * single_pair_N_per_mm_um


def torsional_stiffness_Nm_per_arcmin(mesh_N_per_um: float, radius_mm: float) -> float:
    """K = k_m r^2 at the output, converted to N*m per arcmin (k_m in N/um, r in mm)."""
    n_m_per_rad = mesh_N_per_um * 1e6 * (radius_mm / 1000.0) ** 2
    return n_m_per_rad * RAD_PER_ARCMIN


def equivalent_mass_kg(
    inertia_1_kgm2: float,
    inertia_2_kgm2: float,
    base_radius_1_m: float,
    base_radius_2_m: float,
    form: Literal["standard", "paper"] = "standard",
) -> float:
    """Seed 004 eq. (11) equivalent mass m_bar (kg) of the pair on the line of action.

    standard: J1 J2 / (r1^2 J2 + r2^2 J1); paper (as printed): J1 J2 / (r1^2 J1 + r2^2 J2)."""
    j1, j2, r1, r2 = inertia_1_kgm2, inertia_2_kgm2, base_radius_1_m, base_radius_2_m
    if min(j1, j2, r1, r2) <= 0:
        raise AnalysisError("inertias and base radii must be > 0")
    if form == "standard":
        return j1 * j2 / (r1**2 * j2 + r2**2 * j1)
    if form == "paper":
        return j1 * j2 / (r1**2 * j1 + r2**2 * j2)
    raise AnalysisError(f"eq. (11) form must be 'standard' or 'paper', not {form!r}")


def mesh_damping_Ns_per_m(
    equivalent_mass: float, mesh_N_per_m: float, damping_ratio: float = DEFAULT_DAMPING_RATIO
) -> float:
    """Seed 004 eq. (11): c_m = 2 xi sqrt(m_bar k_m) (N*s/m; m_bar in kg, k_m in N/m)."""
    return 2.0 * damping_ratio * math.sqrt(equivalent_mass * mesh_N_per_m)


@dataclass(frozen=True)
class MeshStiffness:
    """Seed 004 eqs. (8)-(10) evaluated for one internal pair at one center distance."""

    single_pair_N_per_mm_um: float
    contact_ratio: float
    working_pressure_angle_deg: float
    mesh_stiffness_N_per_um: float
    torsional_stiffness_Nm_per_arcmin: float

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def internal_pair_stiffness(
    *,
    z_internal: int,
    z_external: int,
    module_mm: float,
    pressure_angle_rad: float,
    addendum_coeff: float,
    face_width_mm: float,
    center_distance_mm: float,
    paper_coefficient: bool = False,
) -> MeshStiffness:
    """k', eps, alpha', k_m and the torsional stiffness K = k_m r^2 (r = m z_internal / 2)
    of the internal pair, as pinned by run-format.md's reference nominal model."""
    if face_width_mm <= 0:
        raise AnalysisError(f"face width must be > 0 mm, got {face_width_mm}")
    a0 = module_mm * (z_internal - z_external) / 2.0
    alpha_w = working_pressure_angle_rad(a0, center_distance_mm, pressure_angle_rad)
    k1 = single_pair_stiffness_N_per_mm_um(
        z_internal, z_external, paper_coefficient=paper_coefficient
    )
    eps = internal_contact_ratio(
        z_internal, z_external, module_mm, pressure_angle_rad, addendum_coeff, alpha_w
    )
    k_m = mesh_stiffness_N_per_um(face_width_mm, eps, k1)
    radius = module_mm * z_internal / 2.0
    return MeshStiffness(
        single_pair_N_per_mm_um=k1,
        contact_ratio=eps,
        working_pressure_angle_deg=math.degrees(alpha_w),
        mesh_stiffness_N_per_um=k_m,
        torsional_stiffness_Nm_per_arcmin=torsional_stiffness_Nm_per_arcmin(k_m, radius),
    )
