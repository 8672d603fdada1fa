"""Lost motion of a production batch of ``beveloid`` units (seed 001), and the axial position
to set, by Monte Carlo over seed 001's installation error budget.

Seed 001's point is that a beveloid pair's backlash is set by the gear's axial position and
that installation errors (eq. 8: dx, dy, dz and the two shaft angles) move the contact. The
batch draws, per unit (seed 003's method: eccentricities Rayleigh truncated at 2 sigma, the
rest uniform within their limits):

- the center distance error dx and lateral offset dy: ``A' = hypot(A + dx, dy)``;
- the axial position error dz of the gear;
- the runouts of pinion and gear (eccentricities ``F_r / 2``): at the worst position the
  center distance is ``A' + e_p + e_g``, at the tightest ``A' - e_p - e_g``;
- the shaft bearings' radial clearances, parting the gears by ``sum(u_r) / 2`` under load;

and takes each unit's play from the closed-form backlash of the pair
(:func:`analysis.models.seed001_beveloid.backlash_closed_form`, at ``A'`` and the axial shift
plus dz) with the runout and bearing terms at ``2 tan(a_n) cos(delta) / cos(beta)`` um of
play per um of center distance. The shaft angles change the transmission error (eq. 11), not
the play in this model: they are not drawn. Lengths mm (um for tolerances), angles arcmin at
the output (the gear).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from analysis.errors import AnalysisError
from analysis.models.beveloid_nominal import beveloid_nominal_model, beveloid_pair_from_unit
from analysis.models.kind_batch import KindBatch
from analysis.models.seed001_beveloid import BeveloidPair, backlash_closed_form

ARCMIN_PER_RAD = 10800.0 / math.pi
TRUNCATION_SIGMAS_ECCENTRICITY = 2.0


@dataclass(frozen=True)
class Seed001InstallationBudget:
    """Installation error limits (mm, um) of the batch: eq. (8)'s offsets, runouts, bearings."""

    axial_shift_mm: tuple[float, float] = (-0.02, 0.02)  # dz
    center_distance_mm: tuple[float, float] = (-0.01, 0.01)  # dx
    lateral_offset_mm: tuple[float, float] = (-0.02, 0.02)  # dy
    runout_pinion_max_um: float = 10.0
    runout_gear_max_um: float = 12.0
    bearing_clearance_max_um: tuple[float, ...] = (4.0, 4.0)


BeveloidBatch = KindBatch
"""The batch of this kind (analysis.models.kind_batch)."""


def _rayleigh(rng: np.random.Generator, limit: float, n: int) -> np.ndarray:
    if limit <= 0:
        return np.zeros(n)
    s = TRUNCATION_SIGMAS_ECCENTRICITY
    u = rng.uniform(0.0, 1.0 - math.exp(-0.5 * s**2), n)
    return limit / s * np.sqrt(-2.0 * np.log1p(-u))


def beveloid_batch(unit: Mapping[str, Any], budget: Seed001InstallationBudget | None = None,
                   *, rated_torque_Nm: float = 10.0, lost_motion_pct: float = 3.0,
                   samples: int = 5000, seed: int = 0,
                   axial_shift_mm: float | None = None) -> BeveloidBatch:
    """Monte Carlo lost motion of a batch of ``unit``'s design installed within ``budget``;
    ``axial_shift_mm`` replaces the unit's axial position (for :func:`beveloid_advice`)."""
    if samples < 2:
        raise AnalysisError(f"samples must be >= 2, got {samples}")
    b = budget or Seed001InstallationBudget()
    unit = dict(unit)
    if axial_shift_mm is not None:
        unit["axial_shift_mm"] = float(axial_shift_mm)
    pair, shift, _ = beveloid_pair_from_unit(unit)
    model, _ = beveloid_nominal_model({**unit, "axial_shift_mm": min(shift, 0.0)})
    p, g = pair.pinion, pair.gear
    r2 = g.pitch_radius_mm
    sens = 2.0 * math.tan(p.alpha_n) * math.cos(p.delta) / math.cos(p.beta)  # um per um
    rng = np.random.default_rng(seed)
    n = samples
    dx = rng.uniform(*b.center_distance_mm, n)
    dy = rng.uniform(*b.lateral_offset_mm, n)
    dz = rng.uniform(*b.axial_shift_mm, n)
    ecc = (_rayleigh(rng, b.runout_pinion_max_um / 2.0, n)
           + _rayleigh(rng, b.runout_gear_max_um / 2.0, n))
    bearing = sum(rng.uniform(0.0, u, n) for u in b.bearing_clearance_max_um)
    a = pair.center_distance_mm
    base = np.array([
        backlash_closed_form(BeveloidPair(p, g, math.hypot(a + x, y)), shift + z)
        .circumferential_um for x, y, z in zip(dx, dy, dz, strict=True)])
    to_um = 1000.0 * r2 / ARCMIN_PER_RAD
    worst_um = base + sens * (ecc + bearing / 2.0)
    least_um = base - sens * ecc + sens * bearing / 2.0
    elastic = 2.0 * lost_motion_pct / 100.0 * rated_torque_Nm / model.stiffness_Nm_per_arcmin
    return BeveloidBatch(np.clip(worst_um, 0.0, None) / to_um + elastic, least_um / to_um,
                         rated_torque_Nm, lost_motion_pct, samples)


def beveloid_advice(unit: Mapping[str, Any], budget: Seed001InstallationBudget | None = None,
                    *, rated_torque_Nm: float = 10.0, lost_motion_pct: float = 3.0,
                    samples: int = 5000, binding: float = 0.025) -> dict[str, Any]:
    """The gear's axial position (mm) that takes the batch's lost motion lowest while at most
    ``binding`` of the units bind at their tightest position (seed 001: the play falls by
    ``2 tan(a_n) sin(delta) / cos(beta)`` per mm toward the thick end), and its band."""
    pair, shift, _ = beveloid_pair_from_unit(unit)
    now = beveloid_batch(unit, budget, rated_torque_Nm=rated_torque_Nm,
                         lost_motion_pct=lost_motion_pct, samples=samples)
    to_um = 1000.0 * pair.gear.pitch_radius_mm / ARCMIN_PER_RAD
    margin_um = float(np.quantile(now.least_play_arcmin, binding)) * to_um
    step = 0.01
    slope = (backlash_closed_form(pair, shift + step).circumferential_um
             - backlash_closed_form(pair, shift).circumferential_um) / step  # um per mm (< 0)
    advised_shift = shift - margin_um / slope
    advised = beveloid_batch(unit, budget, rated_torque_Nm=rated_torque_Nm,
                             lost_motion_pct=lost_motion_pct, samples=samples,
                             axial_shift_mm=advised_shift)
    return advised.advice(
        f"axial position of the gear for at most {100 * binding:g} % of units binding at their "
        f"tightest position ({slope:.1f} um of play per mm, seed 001's closed-form backlash)",
        axial_shift_mm=advised_shift)
