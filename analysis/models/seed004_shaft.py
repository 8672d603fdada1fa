"""Finite elements of a rotor shaft for seed 004 (Che et al. 2012), section 1.

Each node carries the seed's five coordinates, eq. (1): ``[x, y, theta_x, theta_y, phi]``
(m, m, rad, rad, rad): lateral translations, tilts about x and y, torsion about the axis z.

* Torsion: the seed's linear element, eqs. (2)-(4):
  ``M_s = rho I_p l / 6 [[2, 1], [1, 2]]``, ``K_s = G I_p / l [[1, -1], [-1, 1]]``.
* Bending (the seed refers to its ref. [6] for it): a Timoshenko beam element with
  translational and rotary inertia and the gyroscopic matrix of the spinning section, in the
  textbook form with the shear parameter ``Phi = 12 E I / (kappa G A l^2)``; ``Phi = 0`` is the
  Euler-Bernoulli (Rayleigh) element. In the x-z plane the slope is ``theta_y = dx/dz``; in the
  y-z plane it is ``-theta_x = dy/dz`` (right-handed tilts).
* Gyroscopic convention: ``M q'' + Omega G q' + K q = 0`` with the spin Omega (rad/s) about +z;
  for a rigid disc ``G[theta_x, theta_y] = +J_p``, ``G[theta_y, theta_x] = -J_p``.

Closed forms used to check the elements (simply supported uniform shaft) are here too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from analysis.errors import AnalysisError

DOF_PER_NODE = 5
X, Y, THETA_X, THETA_Y, PHI = range(DOF_PER_NODE)
# Element DOFs (10) of each bending plane as [w_A, slope_A, w_B, slope_B], with the sign that
# turns the node coordinate into the slope of that plane.
_X_PLANE = ((X, 1.0), (THETA_Y, 1.0), (DOF_PER_NODE + X, 1.0), (DOF_PER_NODE + THETA_Y, 1.0))
_Y_PLANE = ((Y, 1.0), (THETA_X, -1.0), (DOF_PER_NODE + Y, 1.0), (DOF_PER_NODE + THETA_X, -1.0))


@dataclass(frozen=True)
class Material:
    """Isotropic shaft material: Young's modulus (Pa), density (kg/m^3), Poisson's ratio."""

    youngs_modulus_Pa: float = 206e9
    density_kg_per_m3: float = 7850.0
    poisson_ratio: float = 0.3

    @property
    def shear_modulus_Pa(self) -> float:
        """G = E / (2 (1 + nu)) (Pa)."""
        return self.youngs_modulus_Pa / (2.0 * (1.0 + self.poisson_ratio))

    @property
    def shear_coefficient(self) -> float:
        """Cowper's shear coefficient of a solid circular section, 6 (1 + nu) / (7 + 6 nu)."""
        nu = self.poisson_ratio
        return 6.0 * (1.0 + nu) / (7.0 + 6.0 * nu)


STEEL = Material()


@dataclass(frozen=True)
class Section:
    """Solid circular section of radius ``radius_m``: area (m^2), I (m^4), I_p = 2 I (m^4)."""

    radius_m: float

    def __post_init__(self) -> None:
        if not self.radius_m > 0:
            raise AnalysisError(f"shaft radius must be > 0 m, got {self.radius_m}")

    @property
    def area_m2(self) -> float:
        return math.pi * self.radius_m**2

    @property
    def second_moment_m4(self) -> float:
        return math.pi * self.radius_m**4 / 4.0

    @property
    def polar_moment_m4(self) -> float:
        return math.pi * self.radius_m**4 / 2.0


def shear_parameter(material: Material, section: Section, length_m: float) -> float:
    """Phi = 12 E I / (kappa G A l^2) of a Timoshenko element of length l (dimensionless)."""
    return (
        12.0 * material.youngs_modulus_Pa * section.second_moment_m4
        / (material.shear_coefficient * material.shear_modulus_Pa * section.area_m2 * length_m**2)
    )


def _plane_stiffness(ei: float, length: float, phi: float) -> np.ndarray:
    L = length
    k = np.array([
        [12.0, 6 * L, -12.0, 6 * L],
        [6 * L, (4 + phi) * L**2, -6 * L, (2 - phi) * L**2],
        [-12.0, -6 * L, 12.0, -6 * L],
        [6 * L, (2 - phi) * L**2, -6 * L, (4 + phi) * L**2],
    ])
    return ei / ((1 + phi) * L**3) * k


def _plane_translational_mass(rho_a: float, length: float, phi: float) -> np.ndarray:
    L, p = length, phi
    m1 = 312 + 588 * p + 280 * p**2
    m2 = (44 + 77 * p + 35 * p**2) * L
    m3 = 108 + 252 * p + 140 * p**2
    m4 = -(26 + 63 * p + 35 * p**2) * L
    m5 = (8 + 14 * p + 7 * p**2) * L**2
    m6 = -(6 + 14 * p + 7 * p**2) * L**2
    m = np.array([[m1, m2, m3, m4], [m2, m5, -m4, m6], [m3, -m4, m1, -m2], [m4, m6, -m2, m5]])
    return rho_a * L / (840.0 * (1 + p) ** 2) * m


def _plane_rotary_mass(rho_i: float, length: float, phi: float) -> np.ndarray:
    L, p = length, phi
    m7 = 36.0
    m8 = (3 - 15 * p) * L
    m9 = (4 + 5 * p + 10 * p**2) * L**2
    m10 = (-1 - 5 * p + 5 * p**2) * L**2
    m = np.array([[m7, m8, -m7, m8], [m8, m9, -m8, m10], [-m7, -m8, m7, -m8],
                  [m8, m10, -m8, m9]])
    return rho_i / (30.0 * L * (1 + p) ** 2) * m


def _selector(plane: tuple[tuple[int, float], ...]) -> np.ndarray:
    s = np.zeros((4, 2 * DOF_PER_NODE))
    for row, (col, sign) in enumerate(plane):
        s[row, col] = sign
    return s


_SX = _selector(_X_PLANE)
_SY = _selector(_Y_PLANE)


@dataclass(frozen=True)
class ShaftElementMatrices:
    """10 x 10 matrices of one shaft element: mass (kg, kg m, kg m^2), stiffness (N/m, N,
    N m/rad) and the gyroscopic matrix per unit spin speed (kg m^2, multiply by Omega rad/s)."""

    mass: np.ndarray
    stiffness: np.ndarray
    gyroscopic: np.ndarray


def shaft_element(
    length_m: float,
    section: Section,
    material: Material = STEEL,
    *,
    shear: bool = True,
    rotary_inertia: bool = True,
) -> ShaftElementMatrices:
    """Element of a uniform circular shaft: Timoshenko bending in two planes (shear and rotary
    inertia switchable), gyroscopic coupling, and the seed's torsion element eq. (4)."""
    if not length_m > 0:
        raise AnalysisError(f"shaft element length must be > 0 m, got {length_m}")
    rho, e = material.density_kg_per_m3, material.youngs_modulus_Pa
    i, ip, a = section.second_moment_m4, section.polar_moment_m4, section.area_m2
    phi = shear_parameter(material, section, length_m) if shear else 0.0
    k_plane = _plane_stiffness(e * i, length_m, phi)
    m_plane = _plane_translational_mass(rho * a, length_m, phi)
    r_plane = _plane_rotary_mass(rho * i, length_m, phi)
    if rotary_inertia:
        m_plane = m_plane + r_plane
    mass = _SX.T @ m_plane @ _SX + _SY.T @ m_plane @ _SY
    stiffness = _SX.T @ k_plane @ _SX + _SY.T @ k_plane @ _SY
    # Spinning section: polar inertia rho I_p = 2 rho I on the slopes of both planes.
    g_plane = 2.0 * r_plane
    gyroscopic = _SX.T @ g_plane @ _SY - _SY.T @ g_plane @ _SX
    # Seed 004 eq. (4): torsion.
    t = [PHI, DOF_PER_NODE + PHI]
    mass[np.ix_(t, t)] += rho * ip * length_m / 6.0 * np.array([[2.0, 1.0], [1.0, 2.0]])
    g_mod = material.shear_modulus_Pa
    stiffness[np.ix_(t, t)] += g_mod * ip / length_m * np.array([[1.0, -1.0], [-1.0, 1.0]])
    return ShaftElementMatrices(mass=mass, stiffness=stiffness, gyroscopic=gyroscopic)


def simply_supported_bending_rad_s(
    mode: int, length_m: float, section: Section, material: Material = STEEL,
    *, model: str = "timoshenko",
) -> float:
    """Closed-form n-th bending natural frequency (rad/s) of a uniform simply supported shaft.

    ``euler``: (n pi / L)^2 sqrt(E I / (rho A)); ``rayleigh`` adds rotary inertia,
    w^2 = E I k^4 / (rho A + rho I k^2); ``timoshenko`` is the lower root of
    (rho^2 I / (kappa G)) w^4 - (rho A + rho I k^2 (1 + E / (kappa G))) w^2 + E I k^4 = 0,
    with k = n pi / L."""
    rho, e = material.density_kg_per_m3, material.youngs_modulus_Pa
    a, i = section.area_m2, section.second_moment_m4
    k = mode * math.pi / length_m
    if model == "euler":
        return k**2 * math.sqrt(e * i / (rho * a))
    if model == "rayleigh":
        return math.sqrt(e * i * k**4 / (rho * a + rho * i * k**2))
    if model != "timoshenko":
        raise AnalysisError(f"model must be euler, rayleigh or timoshenko, not {model!r}")
    kg = material.shear_coefficient * material.shear_modulus_Pa
    qa = rho**2 * i / kg
    qb = -(rho * a + rho * i * k**2 * (1.0 + e / kg))
    qc = e * i * k**4
    w2 = (-qb - math.sqrt(qb**2 - 4.0 * qa * qc)) / (2.0 * qa)
    return math.sqrt(w2)


def free_free_torsion_rad_s(
    mode: int, length_m: float, material: Material = STEEL
) -> float:
    """Closed-form n-th torsional natural frequency (rad/s) of a free-free uniform shaft,
    n pi / L sqrt(G / rho) (the continuum limit of the seed's eq. (4) elements)."""
    return mode * math.pi / length_m * math.sqrt(
        material.shear_modulus_Pa / material.density_kg_per_m3
    )
