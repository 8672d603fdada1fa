"""Seed 002: the 4th-order compound cycloid internal pair and its conjugate.

Gear 2 is the internal gear whose tooth profile is the compound cycloid of eq. (1); gear 1 is
the external gear (the planet of the few-tooth-difference drive) conjugate to it by eqs. (2)-(8).
The modifications (eqs. 9-14) treat gear 2 as the generating tool (the paper's grinding-wheel
picture): gear 1 is generated at the center distance ``e + shift`` (eq. 10) by a tool whose
link lengths are ``e1 -+ rotation`` (eq. 11); the gear 2 that gear 1 then meshes with is the
unmodified eq. (1). Lengths in mm, angles in rad; complex numbers hold plane points ``x + iy``.

Readings of the printed text (docs/seed002.md):

* eq. (3) prints the normal as ``N = (x', -y')``, which is not normal to the tangent
  ``(x', y')``; the normal ``(y', -x')`` is used (``normal="printed"`` keeps the print).
* eq. (9) prints ``sin(alpha_1)`` in one entry; eq. (10) has ``sin(alpha)``, used here.
* eq. (15) ``r0 = m z2`` is the pitch radius of gear 2, so ``e = m (z2 - z1)`` unless the
  unit gives another eccentricity (then the pitch radius is ``e z2 / (z2 - z1)``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from analysis.errors import AnalysisError


@dataclass(frozen=True)
class CompoundCycloidPair:
    """The design data of a compound cycloid pair, seed 002 eq. (15) (mm, counts, ratios).

    ``height_coeff`` is h1 (e1 = m h1), ``shape_coeff`` is f1 (e2 = f1 e1)."""

    module_mm: float
    z_internal: int
    z_external: int
    height_coeff: float
    shape_coeff: float
    eccentricity_mm: float | None = None

    def __post_init__(self) -> None:
        problems = []
        if not self.module_mm > 0:
            problems.append(f"module_mm must be > 0, got {self.module_mm}")
        if int(self.z_external) < 3 or int(self.z_internal) <= int(self.z_external):
            problems.append(
                f"need z_internal > z_external >= 3, got {self.z_internal}, {self.z_external}"
            )
        if not self.height_coeff > 0:
            problems.append(f"height_coeff (h1) must be > 0, got {self.height_coeff}")
        if not self.shape_coeff >= 0:
            problems.append(f"shape_coeff (f1) must be >= 0, got {self.shape_coeff}")
        if self.eccentricity_mm is not None and not self.eccentricity_mm > 0:
            problems.append(f"eccentricity_mm must be > 0, got {self.eccentricity_mm}")
        if problems:
            raise AnalysisError("compound cycloid pair: " + "; ".join(problems))

    @property
    def r0_mm(self) -> float:
        """Eq. (15): r0 = m z2 (mm)."""
        return self.module_mm * self.z_internal

    @property
    def e1_mm(self) -> float:
        """Eq. (15): e1 = m h1 (mm)."""
        return self.module_mm * self.height_coeff

    @property
    def e2_mm(self) -> float:
        """Eq. (15): e2 = f1 e1 (mm)."""
        return self.shape_coeff * self.e1_mm

    @property
    def e_mm(self) -> float:
        """Center distance O1O2 (mm): the unit's eccentricity or m (z2 - z1)."""
        if self.eccentricity_mm is not None:
            return float(self.eccentricity_mm)
        return self.module_mm * (self.z_internal - self.z_external)

    @property
    def pitch_radius_internal_mm(self) -> float:
        """r2 of eqs. (2) and (4): O2N with O2N / O1N = z2 / z1 and O2N - O1N = e (mm)."""
        return self.e_mm * self.z_internal / (self.z_internal - self.z_external)

    @property
    def pitch_radius_external_mm(self) -> float:
        """r1 = r2 - e (mm): the pitch radius of gear 1."""
        return self.pitch_radius_internal_mm - self.e_mm


def eq1_points(pair: CompoundCycloidPair, xi: np.ndarray) -> np.ndarray:
    """Eq. (1) exactly as printed: the compound cycloid of gear 2 at link angles xi (mm)."""
    z, r0, e1, e2 = pair.z_internal, pair.r0_mm, pair.e1_mm, pair.e2_mm
    xi = np.asarray(xi, dtype=float)
    x = r0 * np.cos(xi) - 2 * e1 * np.cos(z * xi) * np.cos(xi) - 2 * e2 * np.sin(2 * z * xi) * (
        np.sin(xi)
    )
    y = r0 * np.sin(xi) - 2 * e1 * np.cos(z * xi) * np.sin(xi) + 2 * e2 * np.sin(2 * z * xi) * (
        np.cos(xi)
    )
    return x + 1j * y


def _terms(pair: CompoundCycloidPair, rotation_mm: float) -> list[tuple[float, int]]:
    """Eq. (11) as a sum of ``c e^{i k xi}`` (coefficient mm, harmonic k)."""
    z, e1, e2 = pair.z_internal, pair.e1_mm, pair.e2_mm
    return [
        (pair.r0_mm, 1),
        (-(e1 - rotation_mm), -(z - 1)),
        (-(e1 + rotation_mm), z + 1),
        (-e2, -(2 * z - 1)),
        (e2, 2 * z + 1),
    ]


def profile_points(
    pair: CompoundCycloidPair, xi: np.ndarray, rotation_mm: float = 0.0
) -> np.ndarray:
    """Eq. (11)/(13): gear 2's profile with the rotation modification Delta2 (mm).

    With ``rotation_mm = 0`` it is eq. (1) rewritten in harmonics (the same curve)."""
    xi = np.asarray(xi, dtype=float)
    return sum(c * np.exp(1j * k * xi) for c, k in _terms(pair, rotation_mm))


def profile_tangent(
    pair: CompoundCycloidPair, xi: np.ndarray, rotation_mm: float = 0.0
) -> np.ndarray:
    """d/dxi of :func:`profile_points` (mm per rad): the ``x'2, y'2`` of eq. (3)."""
    xi = np.asarray(xi, dtype=float)
    return sum(1j * k * c * np.exp(1j * k * xi) for c, k in _terms(pair, rotation_mm))


@dataclass(frozen=True)
class ConjugateProfile:
    """Gear 1 points (in gear 1's frame, mm) with the motion parameters that made them."""

    points: np.ndarray
    xi_rad: np.ndarray
    beta_rad: np.ndarray
    alpha_rad: np.ndarray


def conjugate_profile(
    pair: CompoundCycloidPair,
    xi: np.ndarray,
    shift_mm: float = 0.0,
    rotation_mm: float = 0.0,
    normal: Literal["corrected", "printed"] = "corrected",
) -> ConjugateProfile:
    """Gear 1's profile from gear 2's by eqs. (2)-(8), modified by eqs. (10)-(14).

    For each point of gear 2 (eq. 11 with ``rotation_mm``) the meshing condition eq. (5) is
    solved in closed form: the normal line meets the pitch circle r2 at N (eq. 4), nearer root;
    beta follows from N, alpha = beta z2 / z1 (eq. 8), and the point is carried to gear 1's frame
    by eq. (7) with the center distance ``e + shift_mm`` (eq. 9/10). The meshing condition is
    that of the tool itself, as eq. (10) lists no new one. Points whose normal misses the pitch
    circle have no conjugate and are dropped."""
    xi = np.asarray(xi, dtype=float)
    p = profile_points(pair, xi, rotation_mm)
    d = profile_tangent(pair, xi, rotation_mm)
    if normal == "corrected":
        direction = -1j * d  # (y', -x')
    elif normal == "printed":
        direction = np.conj(d)  # (x', -y') as eq. (3) prints it
    else:
        raise AnalysisError(f"normal must be 'corrected' or 'printed', got {normal!r}")
    n = direction / np.abs(direction)
    pn = p.real * n.real + p.imag * n.imag
    r2 = pair.pitch_radius_internal_mm
    disc = pn**2 - np.abs(p) ** 2 + r2**2
    ok = disc >= 0.0
    root = np.sqrt(np.where(ok, disc, 0.0))
    t_plus, t_minus = -pn + root, -pn - root
    t = np.where(np.abs(t_plus) < np.abs(t_minus), t_plus, t_minus)
    n_point = p + t * n
    beta = np.arctan2(-n_point.real, n_point.imag)  # eq. (4): N = r2 (-sin b, cos b)
    alpha = beta * pair.z_internal / pair.z_external
    centre = (pair.e_mm + shift_mm) * (np.sin(alpha) - 1j * np.cos(alpha))
    x1 = p * np.exp(1j * (alpha - beta)) + centre  # eq. (7)/(10)
    return ConjugateProfile(points=x1[ok], xi_rad=xi[ok], beta_rad=beta[ok], alpha_rad=alpha[ok])


def meshing_residual_mm2(
    pair: CompoundCycloidPair, xi: np.ndarray, beta: np.ndarray, rotation_mm: float = 0.0
) -> np.ndarray:
    """Eq. (5) with the corrected normal: ``(X_N - x2) x2' + (Y_N - y2) y2'`` (mm^2), zero
    where the normal at gear 2's point passes through the pitch point N(beta) of eq. (4)."""
    p = profile_points(pair, xi, rotation_mm)
    d = profile_tangent(pair, xi, rotation_mm)
    r2 = pair.pitch_radius_internal_mm
    n_point = r2 * (-np.sin(beta) + 1j * np.cos(beta))
    v = n_point - p
    return v.real * d.real + v.imag * d.imag


def flank_angle_rad(pair: CompoundCycloidPair) -> float:
    """Angle between gear 2's flank and its circumferential direction where the flank crosses
    the pitch circle r0 (z xi = pi/2 in eq. 1): ``tan chi = 2 h1 / (1 - 4 f1 h1)`` (rad).

    It sets the clearance a radial shift makes (see :mod:`analysis.models.seed002_clearance`);
    only defined for the pitch radius r2 = r0 (the default eccentricity)."""
    h1, f1 = pair.height_coeff, pair.shape_coeff
    return math.atan2(2.0 * h1, 1.0 - 4.0 * f1 * h1)


def internal_tooth_thickness_mm(
    pair: CompoundCycloidPair, band: Literal["addendum", "dedendum"], samples: int = 100001
) -> tuple[float, float]:
    """Arc thickness (mm) of one tooth of gear 2 (eq. 1) halfway between the pitch circle r0
    and its tip circle (``addendum``: the inner band, the internal tooth's tip side) or its root
    circle (``dedendum``), and the tooth height (mm): the quantities of seed 002 Fig. 15."""
    half = math.pi / pair.z_internal
    p = profile_points(pair, np.linspace(-half, half, samples))
    r, phi = np.abs(p), np.angle(p)
    r0 = pair.r0_mm
    if band == "addendum":
        radius = 0.5 * (r0 + r.min())
    elif band == "dedendum":
        radius = 0.5 * (r0 + r.max())
    else:
        raise AnalysisError(f"band must be 'addendum' or 'dedendum', got {band!r}")
    material = r < radius  # the internal tooth (centred on xi = 0) lies inside this circle
    return float((phi[material].max() - phi[material].min()) * radius), float(r.max() - r.min())
