"""Lost motion of a production batch of seed 000 pairs, by Monte Carlo over the tolerances.

The method of seed 003 (random errors drawn within their tolerance grades, the maximum error
of each sampled unit, the distribution over the batch) applied to the seed 000 internal pair:

- M value deviations (tooth thickness, eq. 2) of ring and pinion: truncated normal within the
  limit deviations of Table 1 (±1.6 sigma, seed 003 eqs. 12-17's rule for tooth errors);
- ring and pinion runout F_r (center distance, eqs. 3-7): the eccentricities e = F_r / 2 are
  Rayleigh, truncated at 2 sigma = F_r,max / 2 (seed 003's rule for eccentricities), with a
  uniform phase beta of the pinion's eccentricity (eq. 4);
- bearing radial clearances: uniform within their grade; they shorten the center distance by
  sum(u_r) / 2 (the term eq. 9 compensates), so the play grows by 2 tan(alpha) sum(u_r) / 2;
- eccentric distance error Delta f_a: uniform within its limits (a center distance error, eq. 3).

Each unit's free play varies with the eccentric-shaft angle through eq. (4); its lost motion is
taken at the worst position (the maximum over eight crank revolutions, the period of eq. 4 for
45/40) and, for comparison, at one random position. A unit whose play falls below zero at some
position binds there (interference): the fraction is reported, the play is clipped at zero.

Units: um for the tolerances, mm for geometry, arcmin for angles.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from analysis.errors import AnalysisError
from analysis.models.seed000_geometry import backlash_arcmin_from_um, runout_center_distance_mm
from analysis.models.seed000_unit import InternalPairUnit

TRUNCATION_SIGMAS_TOOTH = 1.6  # seed 003: tooth errors truncated normal at ±1.6 sigma
TRUNCATION_SIGMAS_ECCENTRICITY = 2.0  # seed 003: eccentricities Rayleigh truncated at 2 sigma


@dataclass(frozen=True)
class Seed000Tolerances:
    """Limit deviations (um) of seed 000 Table 1 (grade 7 ring, grade 6 pinion, P6, grade 5)."""

    m_value_internal_um: tuple[float, float] = (23.0, 53.0)
    m_value_external_um: tuple[float, float] = (-38.0, -17.0)
    runout_internal_max_um: float = 23.0
    runout_external_max_um: float = 16.0
    bearing_clearance_max_um: tuple[float, ...] = (6.0, 6.0)
    eccentric_distance_um: tuple[float, float] = (-2.0, 2.0)

    def __post_init__(self) -> None:
        for name in ("m_value_internal_um", "m_value_external_um", "eccentric_distance_um"):
            low, high = getattr(self, name)
            if not low <= high:
                raise AnalysisError(f"tolerance {name}: lower limit {low} above upper {high}")
        if self.runout_internal_max_um < 0 or self.runout_external_max_um < 0:
            raise AnalysisError("runout tolerances must be >= 0 um")
        if any(u < 0 for u in self.bearing_clearance_max_um):
            raise AnalysisError("bearing clearances must be >= 0 um")


@dataclass(frozen=True)
class LostMotionBatch:
    """Lost motion (arcmin) of the sampled units: at their worst position and at a random one."""

    worst_position_arcmin: np.ndarray
    random_position_arcmin: np.ndarray
    interference_fraction: float
    interference_max_um: float
    lost_motion_pct: float
    rated_torque_Nm: float
    samples: int
    notes: tuple[str, ...] = field(default=())

    def band_arcmin(self, coverage: float = 0.95) -> tuple[float, float]:
        """Central interval of the worst-position lost motion holding ``coverage`` of units."""
        tail = 50.0 * (1.0 - coverage)
        low, high = np.percentile(self.worst_position_arcmin, [tail, 100.0 - tail])
        return float(low), float(high)

    def to_dict(self) -> dict[str, object]:
        def summary(x: np.ndarray) -> dict[str, float]:
            p = np.percentile(x, [2.5, 50.0, 97.5])
            return {
                "mean": float(np.mean(x)),
                "std": float(np.std(x, ddof=1)) if x.size > 1 else 0.0,
                "min": float(np.min(x)),
                "max": float(np.max(x)),
                "p2_5": float(p[0]),
                "median": float(p[1]),
                "p97_5": float(p[2]),
            }

        return {
            "samples": self.samples,
            "lost_motion_pct": self.lost_motion_pct,
            "rated_torque_Nm": self.rated_torque_Nm,
            "worst_position_arcmin": summary(self.worst_position_arcmin),
            "random_position_arcmin": summary(self.random_position_arcmin),
            "band_95_arcmin": list(self.band_arcmin(0.95)),
            "interference_fraction": self.interference_fraction,
            "interference_max_um": self.interference_max_um,
            "notes": list(self.notes),
        }


def play_over_positions_um(
    unit: InternalPairUnit,
    theta_rad: np.ndarray,
    *,
    m_value_deviation_mm: np.ndarray | float,
    eccentric_distance_mm: np.ndarray | float,
    eccentricity_internal_mm: np.ndarray | float,
    eccentricity_external_mm: np.ndarray | float,
    beta_rad: np.ndarray | float,
) -> np.ndarray:
    """Free play j_t (um, signed: < 0 binds) over the eccentric-shaft angle, seed 000 eqs. 2-4.

    ``j = 1000 tan(alpha) (E_M + 2 (a0 - |AB|(theta)))`` with |AB| from eq. (4) (the pinned
    linear convention of run-format.md for eqs. 2-3). Array arguments broadcast against
    ``theta_rad[None, :]`` as column vectors (one unit per row).
    """

    def column(x: np.ndarray | float) -> np.ndarray:
        return np.asarray(x, dtype=float).reshape(-1, 1)

    cd = runout_center_distance_mm(
        np.asarray(theta_rad, dtype=float)[None, :],
        eccentric_distance_mm=column(eccentric_distance_mm),
        eccentricity_internal_mm=column(eccentricity_internal_mm),
        eccentricity_external_mm=column(eccentricity_external_mm),
        z_internal=unit.z_internal,
        z_external=unit.z_external,
        beta_rad=column(beta_rad),
    )
    tan_a = math.tan(unit.pressure_angle_rad)
    a0 = unit.standard_center_distance_mm
    return 1000.0 * tan_a * (column(m_value_deviation_mm) + 2.0 * (a0 - cd))


def shaft_angles_rad(unit: InternalPairUnit, angles_per_rev: int = 64) -> np.ndarray:
    """Eccentric-shaft angles covering one period of eq. (4): Z2 / gcd(Z1 - Z2, Z2) revs."""
    period_rev = unit.z_external // math.gcd(unit.z_internal - unit.z_external, unit.z_external)
    return np.linspace(
        0.0, 2.0 * math.pi * period_rev, int(angles_per_rev * period_rev), endpoint=False
    )


def _truncated_normal(
    rng: np.random.Generator, low: float, high: float, n: int, sigmas: float
) -> np.ndarray:
    """Normal centred in [low, high] with the limits at ±``sigmas`` standard deviations."""
    if high == low:
        return np.full(n, low)
    centre, half = 0.5 * (low + high), 0.5 * (high - low)
    return centre + half / sigmas * stats.truncnorm.rvs(-sigmas, sigmas, size=n, random_state=rng)


def _truncated_rayleigh(
    rng: np.random.Generator, limit: float, n: int, sigmas: float
) -> np.ndarray:
    """Rayleigh with scale ``limit / sigmas``, truncated at ``limit`` (inverse-CDF sampling)."""
    if limit == 0:
        return np.zeros(n)
    scale = limit / sigmas
    cdf_max = 1.0 - math.exp(-0.5 * sigmas**2)
    u = rng.uniform(0.0, cdf_max, n)
    return scale * np.sqrt(-2.0 * np.log1p(-u))


def lost_motion_batch(
    unit: InternalPairUnit,
    tolerances: Seed000Tolerances | None = None,
    *,
    samples: int = 20_000,
    seed: int = 0,
    rated_torque_Nm: float = 10.0,
    lost_motion_pct: float = 3.0,
    angles_per_rev: int = 64,
    chunk: int = 4096,
    progress: Callable[[int], None] | None = None,
    compensate: bool = False,
) -> LostMotionBatch:
    """Monte Carlo lost motion of a batch of units built to ``unit``'s design (see module doc).

    ``unit`` gives the design: tooth counts, module, pressure angle, face width, pin diameter and
    the assembly eccentric distance ``center_distance_mm``; its measured M values and runouts are
    NOT used (the batch draws its own within ``tolerances``). The stiffness term 2 p T / K of
    the lost motion comes from the reference nominal model (seed 004 eq. 8).

    ``compensate=False``: every unit is assembled at the design eccentric distance.
    ``compensate=True``: the seed 000 method, each unit's eccentric distance chosen by eq. (9)
    from its own measured M values and runouts (then built with the eccentric-distance error).
    """
    if samples < 2:
        raise AnalysisError(f"samples must be >= 2, got {samples}")
    if unit.pin_diameter_mm is None:
        raise AnalysisError("unit key 'pin_diameter_mm' missing: the M value budget needs it")
    tol = tolerances or Seed000Tolerances()
    rng = np.random.default_rng(seed)
    a0 = unit.standard_center_distance_mm
    a_design = float(unit.center_distance_mm)
    theta = shaft_angles_rad(unit, angles_per_rev)
    period_rev = round(theta.size / angles_per_rev)
    if unit.face_width_mm is None:
        raise AnalysisError("unit key 'face_width_mm' missing: the stiffness term needs it")
    stiffness = unit.pair_stiffness(unit.face_width_mm, a_design).torsional_stiffness_Nm_per_arcmin
    elastic_arcmin = 2.0 * lost_motion_pct / 100.0 * rated_torque_Nm / stiffness

    worst = np.empty(samples)
    at_random = np.empty(samples)
    binding = 0
    deepest = 0.0
    done = 0
    while done < samples:
        n = min(chunk, samples - done)
        dev_int = _truncated_normal(rng, *tol.m_value_internal_um, n, TRUNCATION_SIGMAS_TOOTH)
        dev_ext = _truncated_normal(rng, *tol.m_value_external_um, n, TRUNCATION_SIGMAS_TOOTH)
        e_int = _truncated_rayleigh(
            rng, tol.runout_internal_max_um / 2.0, n, TRUNCATION_SIGMAS_ECCENTRICITY
        )
        e_ext = _truncated_rayleigh(
            rng, tol.runout_external_max_um / 2.0, n, TRUNCATION_SIGMAS_ECCENTRICITY
        )
        beta = rng.uniform(0.0, 2.0 * math.pi, n)
        bearing = sum(rng.uniform(0.0, u, n) for u in tol.bearing_clearance_max_um)
        d_fa = rng.uniform(*tol.eccentric_distance_um, n)
        e_m_mm = (dev_int - dev_ext) / 1000.0
        if compensate:
            # eq. (9) per unit, in the pinned linear convention: the eccentric distance at which
            # the largest center distance of eq. (4) closes the play, from the unit's own M values
            # and runouts, plus half the bearing clearances (the design a'' of each unit)
            a_nominal = a0 + e_m_mm / 2.0 - (e_int + e_ext) / 1000.0 + bearing / 2000.0
        else:
            a_nominal = np.full(n, a_design)
        # what is built: the nominal eccentric distance, its error, the bearing clearances
        a_set = a_nominal + d_fa / 1000.0 - bearing / 2000.0  # mm
        play_um = play_over_positions_um(
            unit,
            theta,
            m_value_deviation_mm=e_m_mm,
            eccentric_distance_mm=a_set,
            eccentricity_internal_mm=e_int / 1000.0,
            eccentricity_external_mm=e_ext / 1000.0,
            beta_rad=beta,
        )
        least = play_um.min(axis=1)
        binding += int(np.count_nonzero(least < 0.0))
        deepest = max(deepest, float(-least.min()))
        play_um = np.clip(play_um, 0.0, None)
        play = backlash_arcmin_from_um(play_um, unit.module_mm, unit.z_internal)
        worst[done : done + n] = play.max(axis=1) + elastic_arcmin
        pick = rng.integers(0, theta.size, n)
        at_random[done : done + n] = play[np.arange(n), pick] + elastic_arcmin
        done += n
        if progress is not None:
            progress(done)
    notes = (
        "M value deviations truncated normal at ±1.6 sigma, eccentricities F_r/2 Rayleigh "
        "truncated at 2 sigma, phases, bearing clearances and eccentric-distance error uniform",
        f"worst position = max over {period_rev} crank revolutions (the period of eq. 4)",
    )
    return LostMotionBatch(
        worst_position_arcmin=worst,
        random_position_arcmin=at_random,
        interference_fraction=binding / samples,
        interference_max_um=deepest,
        lost_motion_pct=lost_motion_pct,
        rated_torque_Nm=rated_torque_Nm,
        samples=samples,
        notes=notes,
    )
