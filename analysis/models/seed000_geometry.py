"""Seed 000 (Li et al. 2012, internal involute pair): the closed-form relations, eqs. (1)-(16).

Pure functions; lengths in mm unless the name says otherwise, angles in rad unless the name
says ``_deg``. "Internal" is gear 1 of the seed (Z1, the ring), "external" is gear 2 (Z2).
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np

from analysis.errors import AnalysisError

EQ1_EXACT_FACTOR = 180.0 * 60.0 / (1000.0 * math.pi) * 2.0
"""Seed 000 eq. (1) unrounded: ``180 * 60 / (1000 pi) * 2`` = 6.8755 arcmin mm / um."""

EQ1_PRINTED_FACTOR = 6.876
"""Seed 000 eq. (1) as printed (and as pinned by run-format.md): 6.876 arcmin mm / um."""

Form = Literal["standard", "paper"]


def involute(angle_rad: float) -> float:
    """inv(a) = tan(a) - a (rad)."""
    return math.tan(angle_rad) - angle_rad


def inverse_involute(value: float) -> float:
    """The angle (rad, in (0, 1.5)) whose involute is ``value`` (> 0)."""
    if not value > 0.0 or value >= involute(1.5):
        raise AnalysisError(
            f"involute value {value!r} outside (0, inv(1.5 rad)): no pressure angle"
        )
    # Newton's method on inv(t) - value (inv' = tan^2 t), kept inside a shrinking bracket by
    # bisection: inv is increasing and convex on (0, 1.5), so this converges in a few steps
    # to the last bit. Not scipy.optimize.brentq: importing scipy.optimize cost every
    # simulated rig's start and every `rig measure` 1.2-2.4 s of CPU, for one root.
    lo, hi = 0.0, 1.5
    t = min((3.0 * value) ** (1.0 / 3.0), 1.4)  # inv(t) ~ t^3 / 3 for small t
    for _ in range(200):
        f = involute(t) - value
        if f > 0.0:
            hi = t
        else:
            lo = t
        slope = math.tan(t) ** 2
        t_next = t - f / slope if slope > 0.0 else 0.5 * (lo + hi)
        if not lo < t_next < hi:
            t_next = 0.5 * (lo + hi)
        if abs(t_next - t) <= 4.0 * math.ulp(t):
            return t_next
        t = t_next
    return t


def backlash_arcmin_from_um(j_t_um: float, module_mm: float, z_internal: int) -> float:
    """Seed 000 eq. (1): lost-motion angle (arcmin) of a circumferential backlash ``j_t`` (um)
    on the reference circle of the internal gear, ``6.876 j_t / (m Z1)`` (the printed factor)."""
    return EQ1_PRINTED_FACTOR * j_t_um / (module_mm * z_internal)


def tooth_thickness_backlash_um(m_deviation_mm: float, pressure_angle_rad: float) -> float:
    """Seed 000 eq. (2): ``j_t(E_M) = E_M tan(alpha)``, with E_M in mm and the result in um."""
    return 1000.0 * m_deviation_mm * math.tan(pressure_angle_rad)


def center_distance_backlash_um(delta_e_mm: float, pressure_angle_rad: float) -> float:
    """Seed 000 eq. (3): ``j_t(de) = 2 de tan(alpha)`` (de in mm, result in um).

    For the internal pair a positive ``de`` is a center distance *smaller* than the one it is
    measured from (the seed: a larger eccentric distance gives less backlash)."""
    return 1000.0 * 2.0 * delta_e_mm * math.tan(pressure_angle_rad)


def eccentricity_backlash_um(
    eccentricities_mm: tuple[float, ...] | list[float], pressure_angle_rad: float
) -> float:
    """Seed 000 eq. (7) at its worst phase (sin(phi) = 1): ``2 tan(alpha) sum(de_i)`` (um).

    ``de_i`` is the center-distance error of each eccentricity: half the radial runout
    (``de_Fr = Fr / 2``) or half the bearing radial clearance (``de_ur = u_r / 2``)."""
    return 1000.0 * 2.0 * math.tan(pressure_angle_rad) * float(sum(eccentricities_mm))


def runout_center_distance_mm(
    theta_rad: np.ndarray | float,
    *,
    eccentric_distance_mm: float,
    eccentricity_internal_mm: float,
    eccentricity_external_mm: float,
    z_internal: int,
    z_external: int,
    beta_rad: float = 0.0,
) -> np.ndarray:
    """Seed 000 eq. (4): the center distance |AB| (mm) over the eccentric-shaft angle theta.

    ``eccentric_distance_mm`` = |O1O2|, ``eccentricity_internal_mm`` = |AO1| (ring base-circle
    center off its axis, Fr1 / 2 from runout), ``eccentricity_external_mm`` = |BO2| (Fr2 / 2),
    ``beta_rad`` the initial phase of B. Implemented as printed; its period in theta is
    :func:`center_distance_period_rev` crank revolutions.
    """
    theta = np.asarray(theta_rad, dtype=float)
    phase = (z_internal - z_external) * theta / z_external + beta_rad
    x = (
        eccentric_distance_mm * np.cos(theta)
        + eccentricity_external_mm * np.cos(phase)
        + eccentricity_internal_mm
    )
    y = eccentric_distance_mm * np.sin(theta) + eccentricity_external_mm * np.sin(phase)
    return np.hypot(x, y)


def center_distance_max_mm(
    eccentric_distance_mm: float, eccentricity_internal_mm: float, eccentricity_external_mm: float
) -> float:
    """Seed 000 eq. (5): |AB|max = |AO1| + |O1O2| + |BO2| (mm)."""
    return eccentricity_internal_mm + eccentric_distance_mm + eccentricity_external_mm


def center_distance_min_mm(
    eccentric_distance_mm: float, eccentricity_internal_mm: float, eccentricity_external_mm: float
) -> float:
    """Seed 000 eq. (6): |AB|min = |O1O2| - (|AO1| + |BO2|) (mm)."""
    return eccentric_distance_mm - (eccentricity_internal_mm + eccentricity_external_mm)


def center_distance_period_rev(z_internal: int, z_external: int) -> int:
    """Period of eq. (4) in crank (eccentric-shaft) revolutions.

    The phase of B turns (Z1 - Z2) / Z2 times per crank turn, so the pattern repeats after
    ``Z2 / gcd(Z2, Z1 - Z2)`` turns: Z2 / (Z1 - Z2) = 8 for 45/40 (the seed prints "20 r")."""
    return z_external // math.gcd(z_external, z_internal - z_external)


def _pin_factor(z: int) -> float:
    """cos(90 deg / z) for odd z (eq. 13), 1 for even z (eq. 12)."""
    return math.cos(math.pi / (2 * z)) if z % 2 else 1.0


def m_value_mm(
    z: int,
    module_mm: float,
    pressure_angle_rad: float,
    pin_diameter_mm: float,
    shift_coeff: float,
    *,
    internal: bool,
) -> float:
    """Seed 000 eqs. (12)-(14): the M value over two pins (mm) of a gear with profile shift x.

    Even z: eq. (12); odd z: eq. (13). Upper signs for the external gear, lower for the internal.
    """
    sign = -1.0 if internal else 1.0
    d_b = module_mm * z * math.cos(pressure_angle_rad)
    inv_m = (
        involute(pressure_angle_rad)
        + sign * pin_diameter_mm / d_b
        - sign * math.pi / (2 * z)
        + 2.0 * shift_coeff * math.tan(pressure_angle_rad) / z
    )
    alpha_m = inverse_involute(inv_m)
    return d_b / math.cos(alpha_m) * _pin_factor(z) + sign * pin_diameter_mm


def pin_pressure_angle_rad(
    m_value: float,
    z: int,
    module_mm: float,
    pressure_angle_rad: float,
    pin_diameter_mm: float,
    *,
    internal: bool,
) -> float:
    """Seed 000 eq. (12)/(13) solved for alpha_M, the pressure angle at the pin centre (rad)."""
    sign = -1.0 if internal else 1.0
    d_b = module_mm * z * math.cos(pressure_angle_rad)
    pin_circle = m_value - sign * pin_diameter_mm
    cos_alpha_m = d_b * _pin_factor(z) / pin_circle if pin_circle > 0 else 2.0
    if not 0.0 < cos_alpha_m < 1.0:
        raise AnalysisError(
            f"M value {m_value} mm with pin {pin_diameter_mm} mm puts the pin centre inside the "
            f"base circle of the z={z} gear: not a valid measurement"
        )
    return math.acos(cos_alpha_m)


def shift_coeff_from_pin_angle(
    alpha_m_rad: float, z: int, module_mm: float, pressure_angle_rad: float,
    pin_diameter_mm: float, *, internal: bool,
) -> float:
    """Seed 000 eq. (14) solved for x, the (equivalent) profile shift coefficient."""
    sign = -1.0 if internal else 1.0
    d_b = module_mm * z * math.cos(pressure_angle_rad)
    rest = (
        involute(alpha_m_rad)
        - involute(pressure_angle_rad)
        - sign * pin_diameter_mm / d_b
        + sign * math.pi / (2 * z)
    )
    return rest * z / (2.0 * math.tan(pressure_angle_rad))


def working_pressure_angle_rad(
    shift_internal: float, shift_external: float, z_internal: int, z_external: int,
    pressure_angle_rad: float, form: Form = "standard",
) -> float:
    """Seed 000 eq. (15): working pressure angle alpha' of the zero-backlash internal mesh (rad).

    ``standard``: inv(a') = inv(a) + 2 tan(a) (x1 - x2) / (z1 - z2), the involute relation
    (gear handbooks, ISO 21771). ``paper``: eq. (15) as printed, without the tan(a)."""
    if form not in ("standard", "paper"):
        raise AnalysisError(f"eq. (15) form must be 'standard' or 'paper', not {form!r}")
    factor = math.tan(pressure_angle_rad) if form == "standard" else 1.0
    value = involute(pressure_angle_rad) + 2.0 * factor * (shift_internal - shift_external) / (
        z_internal - z_external
    )
    return inverse_involute(value)


def zero_backlash_center_distance_mm(
    standard_center_distance_mm: float, pressure_angle_rad: float, working_angle_rad: float
) -> float:
    """Seed 000 eq. (16): a' = a cos(alpha) / cos(alpha') (mm)."""
    return standard_center_distance_mm * math.cos(pressure_angle_rad) / math.cos(working_angle_rad)


def recommended_eccentric_distance_mm(
    zero_backlash_mm: float,
    runout_internal_mm: float,
    runout_external_mm: float,
    bearing_clearances_mm: tuple[float, ...] | list[float],
) -> float:
    """Seed 000 eq. (9): a'' = a' - (Fr1 + Fr2) / 2 + sum(u_ri / 2) (mm): the eccentric distance
    that puts the largest center distance over the shaft angle at the zero-backlash one."""
    return (
        zero_backlash_mm
        - (runout_internal_mm + runout_external_mm) / 2.0
        + float(sum(bearing_clearances_mm)) / 2.0
    )


def format_arcmin(value_arcmin: float) -> str:
    """An angle in arcmin as the seed writes it, e.g. 6.341 -> 6'20\" (rounded to 1\")."""
    sign = "-" if value_arcmin < 0 else ""
    total_arcsec = round(abs(value_arcmin) * 60.0)
    return f"{sign}{total_arcsec // 60}'{total_arcsec % 60}\""
