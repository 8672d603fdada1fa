"""Lost motion of a production batch of ``cycloid`` units (seed 002), and the modification
to choose, by Monte Carlo over seed 002's modification budget.

Seed 002 sizes its "negative shift + rotation" modification from two JB/T 10419 grade-5
tolerances of the cycloid gear (Table 2): the shift Delta1 from the radial runout Delta_frt
(0.016 mm), the rotation Delta2 from the single pitch deviation Delta_fpt (0.008 mm, read as
0.004 mm of single-side clearance). The batch draws, per unit, the errors that budget is for
(seed 003's method: tooth errors truncated normal within ±1.6 sigma, eccentricities Rayleigh
truncated at 2 sigma, the rest uniform):

- runout of gear 1 and gear 2, eccentricities ``F_r / 2``: they swing the center distance
  O1O2 over the crank angle; at the worst position it is ``e - (e_1 + e_2)`` (seed 000 eq. 6's
  reading for a few-tooth-difference pair);
- the crank's eccentricity error (uniform) and the crank bearings' radial clearances (uniform,
  they shorten O1O2 by ``sum(u_r) / 2``);
- the as-ground shift and rotation (uniform about the design's Delta1, Delta2);
- each tooth's thickness deviation within ``±Delta_fpt / 2`` (truncated normal), the worst
  tooth pair adding the sum of two;

and converts them with seed 002's first-order clearances at the pitch circle (eqs. 9-12,
:func:`analysis.models.seed002_clearance.closed_form_clearance`): ``2 cot(chi)`` um of play per
um of shift (a center distance change is a shift of the other sign), ``-4`` per um of rotation.
The assembled pair's own play over the mesh phases comes from the nominal model
(:func:`analysis.models.cycloid_nominal.cycloid_nominal_model`: ``play_min`` / ``play_max``).
Lengths um, angles arcmin at the output (gear 1), ``arcmin = 3437.75 j / (1000 r1)``.

**Nominal and band are different quantities** (issue 33 item 17). The nominal model is a
perfect unit, its play averaged over the mesh phases (example unit: 1.664 arcmin at 3 % of
10 N*m). The batch band (``band_arcmin``, what campaigns, certificates and the page print) is
each unit's lost motion at its *worst* crank position, where three terms only add: the runouts
(``2 cot(chi) (e_1 + e_2) >= 0``), the crank bearings' clearances (``>= 0``) and the thinnest
tooth pair in mesh. So the band lies *above* the nominal by their size (example unit 2.403 ..
3.831 arcmin; about +1' of runout alone with Delta_frt = 16 um per gear); the nominal
is not wrong and neither is the band. The centred terms alone (eccentricity error, shift and
rotation as ground; no runout, bearing or tooth errors) give a worst-position band that
brackets the nominal, and so does ``position_arcmin``, the lost motion at one random position
(uniform runout phases, a random mesh phase and tooth pair in mesh; example unit 0.77 ..
3.00 arcmin), whose centre lies above the nominal only by the bearings'
``2 cot(chi) E[sum u_r] / 2`` (+0.22').
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from analysis.errors import AnalysisError
from analysis.models.cycloid_nominal import cycloid_nominal_model
from analysis.models.kind_batch import KindBatch
from analysis.models.seed002_cycloid import CompoundCycloidPair, flank_angle_rad

ARCMIN_PER_RAD = 10800.0 / math.pi
TRUNCATION_SIGMAS_TOOTH = 1.6
TRUNCATION_SIGMAS_ECCENTRICITY = 2.0


@dataclass(frozen=True)
class Seed002Tolerances:
    """The modification budget (um): seed 002 Table 2 (JB/T 10419 grade 5) and the assembly."""

    runout_gear1_max_um: float = 16.0  # Delta_frt
    runout_gear2_max_um: float = 16.0
    pitch_deviation_um: float = 8.0  # Delta_fpt: thickness within +-Delta_fpt / 2 per tooth
    eccentricity_um: tuple[float, float] = (-2.0, 2.0)
    crank_bearing_clearance_max_um: tuple[float, ...] = (4.0, 4.0)
    shift_um: tuple[float, float] = (-2.0, 2.0)  # grinding: as-made minus design Delta1
    rotation_um: tuple[float, float] = (-0.5, 0.5)


CycloidBatch = KindBatch
"""The batch of this kind (analysis.models.kind_batch)."""


def _pair(unit: Mapping[str, Any]) -> CompoundCycloidPair:
    """The unit's pair from its seed 002 eq. (15) data (m, z2, z1, h1, f1; e)."""
    ecc = unit.get("eccentricity_mm")
    return CompoundCycloidPair(
        module_mm=float(unit["module_mm"]), z_internal=int(unit["z_internal"]),
        z_external=int(unit["z_external"]), height_coeff=float(unit["height_coeff"]),
        shape_coeff=float(unit["shape_coeff"]),
        eccentricity_mm=None if ecc is None else float(ecc))


def _truncated_normal(rng: np.random.Generator, half: float, shape: tuple[int, ...],
                      sigmas: float) -> np.ndarray:
    x = rng.standard_normal(shape)
    bad = np.abs(x) > sigmas
    while bad.any():
        x[bad] = rng.standard_normal(int(bad.sum()))
        bad = np.abs(x) > sigmas
    return x * half / sigmas


def _rayleigh(rng: np.random.Generator, limit: float, n: int, sigmas: float) -> np.ndarray:
    if limit <= 0:
        return np.zeros(n)
    u = rng.uniform(0.0, 1.0 - math.exp(-0.5 * sigmas**2), n)
    return limit / sigmas * np.sqrt(-2.0 * np.log1p(-u))


def cycloid_batch(unit: Mapping[str, Any], tolerances: Seed002Tolerances | None = None, *,
                  rated_torque_Nm: float = 10.0, lost_motion_pct: float = 3.0,
                  samples: int = 5000, seed: int = 0,
                  rotation_mm: float | None = None) -> CycloidBatch:
    """Monte Carlo lost motion (arcmin) of a batch built to ``unit``'s design (see the module
    doc): per unit at its worst crank position (``worst_arcmin``) and at one random position
    (``position_arcmin``). Errors become play by seed 002's first-order clearances at the pitch
    circle (eqs. 9-10: ``2 cot chi`` per um of shift or of O1O2 shortening; eqs. 11-12: ``-4``
    per um of Delta2). ``rotation_mm`` replaces the unit's Delta2 (for
    :func:`cycloid_advice`)."""
    if samples < 2:
        raise AnalysisError(f"samples must be >= 2, got {samples}")
    tol = tolerances or Seed002Tolerances()
    unit = dict(unit)
    if rotation_mm is not None:
        unit["rotation_modification_mm"] = 0.0
    model, _ = cycloid_nominal_model(unit, reference_torque_Nm=rated_torque_Nm)
    pair = _pair(unit)
    r1 = pair.pitch_radius_external_mm
    cot_chi = 1.0 / math.tan(flank_angle_rad(pair))
    to_um = 1000.0 * r1 / ARCMIN_PER_RAD
    extra_rot = 0.0 if rotation_mm is None else -4000.0 * rotation_mm
    play_max_um = model.play_max_arcmin * to_um + extra_rot
    play_min_um = model.play_min_arcmin * to_um + extra_rot
    phase_um = np.asarray(model.play_phases_arcmin or (model.play_arcmin,)) * to_um + extra_rot
    elastic = 2.0 * lost_motion_pct / 100.0 * rated_torque_Nm / model.stiffness_Nm_per_arcmin
    rng = np.random.default_rng(seed)
    n = samples
    e1 = _rayleigh(rng, tol.runout_gear1_max_um / 2.0, n, TRUNCATION_SIGMAS_ECCENTRICITY)
    e2 = _rayleigh(rng, tol.runout_gear2_max_um / 2.0, n, TRUNCATION_SIGMAS_ECCENTRICITY)
    d_e = rng.uniform(*tol.eccentricity_um, n)
    bearing = sum(rng.uniform(0.0, u, n) for u in tol.crank_bearing_clearance_max_um)
    shift = rng.uniform(*tol.shift_um, n)
    rotation = rng.uniform(*tol.rotation_um, n)
    teeth = pair.z_internal + pair.z_external
    thickness = _truncated_normal(rng, tol.pitch_deviation_um / 2.0, (n, teeth),
                                  TRUNCATION_SIGMAS_TOOTH)
    pair_sums = thickness[:, :pair.z_internal][:, :pair.z_external] + thickness[
        :, pair.z_internal:]
    common = 2.0 * cot_chi * (shift - d_e + bearing / 2.0) - 4.0 * rotation
    worst_um = play_max_um + common + 2.0 * cot_chi * (e1 + e2) + pair_sums.max(axis=1)
    least_um = play_min_um + common - 2.0 * cot_chi * (e1 + e2) + pair_sums.min(axis=1)
    worst = np.clip(worst_um, 0.0, None) / to_um + elastic
    # one random position: the runout phases, the mesh phase and the tooth pair in mesh drawn
    # (a stream of its own, so the worst-position draws above stay as they were)
    at = np.random.default_rng([seed, 1])
    swing = e1 * np.cos(at.uniform(0.0, 2.0 * math.pi, n)) + e2 * np.cos(
        at.uniform(0.0, 2.0 * math.pi, n))
    in_mesh = pair_sums[np.arange(n), at.integers(0, pair_sums.shape[1], n)]
    position_um = (phase_um[at.integers(0, phase_um.size, n)] + common
                   + 2.0 * cot_chi * swing + in_mesh)
    position = np.clip(position_um, 0.0, None) / to_um + elastic
    return CycloidBatch(worst, least_um / to_um, rated_torque_Nm, lost_motion_pct, samples,
                        position_arcmin=position)


def cycloid_advice(unit: Mapping[str, Any], tolerances: Seed002Tolerances | None = None, *,
                   rated_torque_Nm: float = 10.0, lost_motion_pct: float = 3.0,
                   samples: int = 5000, binding: float = 0.025) -> dict[str, Any]:
    """The rotation modification Delta2 (mm) that takes the batch's lost motion lowest while
    at most ``binding`` of the units bind somewhere (seed 002: the rotation trims the side
    clearance the shift left, 2 Delta2 per side), with the shift kept at the unit's Delta1
    (= Delta_frt, seed 002's rule), and the batch band it gives."""
    base = cycloid_batch(unit, tolerances, rated_torque_Nm=rated_torque_Nm,
                         lost_motion_pct=lost_motion_pct, samples=samples, rotation_mm=0.0)
    pair = _pair(unit)
    to_um = 1000.0 * pair.pitch_radius_external_mm / ARCMIN_PER_RAD
    margin_um = float(np.quantile(base.least_play_arcmin, binding)) * to_um
    rotation = margin_um / 4000.0  # mm; 4 um of play per um of Delta2
    advised = cycloid_batch(unit, tolerances, rated_torque_Nm=rated_torque_Nm,
                            lost_motion_pct=lost_motion_pct, samples=samples,
                            rotation_mm=rotation)
    return advised.advice(
        f"rotation modification Delta2 for at most {100 * binding:g} % of units binding at "
        "their tightest crank position (seed 002 eqs. 11-12: -4 um of play per um), shift kept "
        "at Delta1",
        rotation_modification_mm=rotation,
        shift_modification_mm=float(unit.get("shift_modification_mm") or 0.0))
