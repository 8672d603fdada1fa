"""TE of an internal involute pair (the seed 000 reducer) from its eccentricities and tooth
spacing errors: the nominal curve and the batch band of Table 1.

Kinematics (the ring, ``z_internal``, fixed; the eccentric shaft the input; the pinion,
``z_external``, the output): ``i = -z_external / (z_internal - z_external)`` (-8 for 45/40).
The contact point turns with the eccentric, one tooth pair per ``360 / z_internal`` deg of
input: mesh ``n = floor(theta z_internal / 360)`` engages ring tooth ``n mod z_internal`` and
pinion tooth ``n mod z_external`` (the same convention as the simulated plant). So
``z_internal`` meshes per input revolution (``z_internal |i|`` = 360 per output revolution);
the output's tooth pitch, the window of f'_i, is ``360 / z_external`` deg (9 deg for the
seed 000 pair), because the output is the pinion.

TE at the output for flank ``s`` (+1 forward, -1 reverse), arcsec::

    TE_s(theta) = 60 K [ p_ring(n) - p_pinion(n) + e_t(theta) - s tan(alpha) (|AB|(theta) - a) ]

- ``K = 6.876 / (m z_internal)`` arcmin/um, seed 000 eq. (1) (circumferential um on the
  ring's reference circle to output arcmin);
- ``p``: each tooth's position (pitch) deviation, um, from the cumulative sum of single pitch
  deviations ``f_pt`` (the tooth spacing error);
- ``e_t``: the tangential part, across the crank line, of eq. (4)'s eccentricity vectors
  ``|AO1| = F_r,internal / 2`` (the ring's, fixed at phase ``internal_phase``) and
  ``|BO2| = F_r,external / 2`` (the pinion's, turning with it against the crank, phase
  ``beta``): ``e_t = |AO1| sin(phase_int - theta) + |BO2| sin(psi + beta - theta)`` with
  ``psi = -(z1 - z2) theta / z2``: orders ``|i|`` (8, once per crank turn) and ``|i| + 1``
  (9) per output revolution; it moves both flanks alike;
- ``|AB|(theta)``: eq. (4) as printed, the center distance; a longer center distance opens the
  play by ``2 tan(alpha)`` per um (eq. 3), half on each flank, so the two directions' curves
  move apart and together (orders 8 and, with eq. 4's printed ``+`` phase of B, 7). Under the
  brake the forward direction rests on the flank of positive torque, ``+play / 2``.

These are the conventions of the simulated plant (simulators/plant/geometry.py), so that a
run of the simulated rig is compared with the model that made it.

The batch band (:func:`internal_band`): Monte Carlo over seed 000 Table 1 (runouts F_r
grade 7 ring 23 um, grade 6 pinion 16 um, as eccentricities ``F_r / 2`` Rayleigh truncated at
2 sigma with uniform phases, seed 003's rule) and the single pitch deviations ``f_pt`` of the
same grades, which Table 1 does not list: GB/T 10095.1-2008 (ISO 1328-1) for 20 < d <= 50 mm,
0.5 <= m <= 2: +-9.5 um (grade 7), +-6.5 um (grade 6), normal truncated at +-1.6 sigma
(seed 003 eq. 17).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from analysis.effects import EQ1_FACTOR
from analysis.errors import AnalysisError
from analysis.models.seed000_batch import (
    TRUNCATION_SIGMAS_ECCENTRICITY,
    TRUNCATION_SIGMAS_TOOTH,
    _truncated_normal,
    _truncated_rayleigh,
)
from analysis.transmission.analyse import Kinematics
from analysis.transmission.orders import Order

F_PT_LIMIT_UM = {5: 4.7, 6: 6.5, 7: 9.5}
"""GB/T 10095.1-2008 single pitch deviation limit +-f_pt (um), 20 < d <= 50 mm, m 0.5..2."""
TABLE1_RUNOUT_UM = {"internal": 23.0, "external": 16.0}
"""Seed 000 Table 1: radial runout F_r, ring (grade 7) and pinion (grade 6), um."""
TABLE1_GRADES = {"internal": 7, "external": 6}


@dataclass(frozen=True)
class InternalGeometry:
    """What the TE of an internal pair needs: tooth counts, module (mm), pressure angle
    (rad), eccentric distance ``a`` (mm)."""

    z_internal: int
    z_external: int
    module_mm: float
    alpha_rad: float
    center_distance_mm: float

    @property
    def ratio(self) -> float:
        return -self.z_external / (self.z_internal - self.z_external)

    @property
    def arcsec_per_um(self) -> float:
        """Seed 000 eq. (1) in arcsec per um of circumferential displacement."""
        return 60.0 * EQ1_FACTOR / (self.module_mm * self.z_internal)

    @property
    def pinion_eccentricity_order(self) -> float:
        """Eq. (4) as printed: cycles of the pinion's eccentricity term per output rev."""
        z1, z2 = self.z_internal, self.z_external
        return abs(self.ratio) * abs(1.0 - (z1 - z2) / z2)

    def kinematics(self) -> Kinematics:
        z1, z2 = self.z_internal, self.z_external
        pinion_teeth = abs(self.ratio) * z1 / z2
        extra = (
            Order(_whole(self.pinion_eccentricity_order), "output_rev",
                  self.pinion_eccentricity_order, "pinion eccentricity (seed 000 eq. 4)"),
            Order(_whole(pinion_teeth), "output_rev", pinion_teeth,
                  "pinion tooth spacing (its turn against the crank)"),
        )
        return Kinematics(
            ratio=self.ratio, output_teeth=z2, crank_per_input=None, mesh_per_input=float(z1),
            extra_orders=extra,
            notes=(f"output tooth pitch: 360/{z2} deg (the output is the pinion, "
                   f"z_external = {z2}); the crank is the input shaft (its orders are "
                   "input_rev)",))


def _whole(x: float) -> float:
    return float(round(x)) if abs(x - round(x)) < 1e-9 else float(x)


def geometry_from_unit(unit: Mapping[str, Any]) -> InternalGeometry:
    """The geometry of a run.json ``unit`` of kind ``internal_involute``."""
    try:
        z1, z2 = int(unit["z_internal"]), int(unit["z_external"])
        m = float(unit["module_mm"])
    except (KeyError, TypeError, ValueError) as exc:
        raise AnalysisError(f"unit: z_internal, z_external and module_mm are needed ({exc})"
                            ) from None
    if not z1 > z2 > 0 or not m > 0:
        raise AnalysisError(f"unit: needs z_internal > z_external > 0 and module_mm > 0, got "
                            f"{z1}, {z2}, {m}")
    alpha = math.radians(float(unit.get("pressure_angle_deg", 20.0)))
    a = float(unit.get("center_distance_mm") or m * (z1 - z2) / 2.0)
    return InternalGeometry(z1, z2, m, alpha, a)


def input_angles_deg(geo: InternalGeometry, per_mesh: int = 4) -> np.ndarray:
    """Input angles (deg) over one output revolution, ``per_mesh`` points per mesh cycle, each
    in the middle of its slot (never on a tooth change)."""
    n = int(round(abs(geo.ratio) * geo.z_internal)) * per_mesh
    step = abs(geo.ratio) * 360.0 / n
    return (np.arange(n) + 0.5) * step


def te_curves_arcsec(
    geo: InternalGeometry,
    theta_in_deg: np.ndarray,
    *,
    ecc_internal_um: np.ndarray | float,
    ecc_external_um: np.ndarray | float,
    beta_rad: np.ndarray | float,
    internal_phase_rad: np.ndarray | float,
    pitch_internal_um: np.ndarray,
    pitch_external_um: np.ndarray,
) -> dict[int, np.ndarray]:
    """TE (arcsec, centred) of each flank (+1, -1) at ``theta_in_deg``, for one or many units
    (arrays broadcast as rows: unit x angle; pitch tables unit x teeth)."""
    def col(x: np.ndarray | float) -> np.ndarray:
        return np.asarray(x, dtype=float).reshape(-1, 1)

    theta = np.radians(np.asarray(theta_in_deg, dtype=float))[None, :]
    a = geo.center_distance_mm * 1000.0  # um
    phase = (geo.z_internal - geo.z_external) * theta / geo.z_external + col(beta_rad)
    e1, e2, p1 = col(ecc_internal_um), col(ecc_external_um), col(internal_phase_rad)
    x = a * np.cos(theta) + e2 * np.cos(phase) + e1 * np.cos(p1)
    y = a * np.sin(theta) + e2 * np.sin(phase) + e1 * np.sin(p1)
    delta_a = np.hypot(x, y) - a  # um, eq. (4)
    psi = -(geo.z_internal - geo.z_external) * theta / geo.z_external
    e_t = e1 * np.sin(p1 - theta) + e2 * np.sin(psi + col(beta_rad) - theta)
    n = np.floor(np.asarray(theta_in_deg, dtype=float) * geo.z_internal / 360.0 + 1e-9)
    n = n.astype(np.int64)
    pint = np.atleast_2d(np.asarray(pitch_internal_um, dtype=float))
    pext = np.atleast_2d(np.asarray(pitch_external_um, dtype=float))
    pitch = pint[:, n % geo.z_internal] - pext[:, n % geo.z_external]
    k = geo.arcsec_per_um
    tan_a = math.tan(geo.alpha_rad)
    out = {}
    for s in (1, -1):
        te = k * (pitch + e_t - s * tan_a * delta_a)
        out[s] = te - te.mean(axis=1, keepdims=True)
    return out


def positions_from_single_pitch(f_pt_um: np.ndarray) -> np.ndarray:
    """Tooth position deviations (um) from single pitch deviations: the cumulative sum, with
    the mean single deviation taken out so the circle closes (the pitches add to 360 deg)."""
    f = np.atleast_2d(np.asarray(f_pt_um, dtype=float))
    f = f - f.mean(axis=1, keepdims=True)
    pos = np.cumsum(f, axis=1)
    return pos - pos.mean(axis=1, keepdims=True)


@dataclass(frozen=True)
class InternalUnitErrors:
    """One unit's errors (um, rad): eccentricities, phases and tooth positions."""

    ecc_internal_um: float
    ecc_external_um: float
    beta_rad: float
    internal_phase_rad: float
    pitch_internal_um: np.ndarray
    pitch_external_um: np.ndarray
    assumed: tuple[str, ...] = ()


def unit_errors(geo: InternalGeometry, unit: Mapping[str, Any]) -> InternalUnitErrors:
    """The unit's own errors from run.json ``unit``: ``runout_internal_mm`` /
    ``runout_external_mm`` (F_r, eccentricity F_r / 2), ``runout_phase_deg`` (beta of eq. 4)
    and ``runout_internal_phase_deg`` (default 0: eq. 4 as printed), ``pitch_internal_um`` /
    ``pitch_external_um`` (each tooth's position deviation, um; default none)."""
    assumed = []

    def num(key: str, default: float) -> float:
        v = unit.get(key)
        if v is None:
            assumed.append(f"{key} unknown: {default:g}")
            return default
        return float(v)

    def table(key: str, z: int) -> np.ndarray:
        v = unit.get(key)
        if v is None:
            assumed.append(f"{key} unknown: no tooth spacing error")
            return np.zeros(z)
        arr = np.asarray(v, dtype=float)
        if arr.shape != (z,):
            raise AnalysisError(f"unit key {key}: expected {z} values (one per tooth), got "
                                f"{arr.size}")
        return arr

    return InternalUnitErrors(
        ecc_internal_um=500.0 * num("runout_internal_mm", 0.0),
        ecc_external_um=500.0 * num("runout_external_mm", 0.0),
        beta_rad=math.radians(num("runout_phase_deg", 0.0)),
        internal_phase_rad=math.radians(num("runout_internal_phase_deg", 0.0)),
        pitch_internal_um=table("pitch_internal_um", geo.z_internal),
        pitch_external_um=table("pitch_external_um", geo.z_external),
        assumed=tuple(assumed))


def unit_curves(geo: InternalGeometry, errors: InternalUnitErrors, theta_in_deg: np.ndarray
                ) -> dict[int, np.ndarray]:
    """The TE curves (arcsec) of one unit with known errors, rows of one."""
    return te_curves_arcsec(
        geo, theta_in_deg, ecc_internal_um=errors.ecc_internal_um,
        ecc_external_um=errors.ecc_external_um, beta_rad=errors.beta_rad,
        internal_phase_rad=errors.internal_phase_rad,
        pitch_internal_um=errors.pitch_internal_um, pitch_external_um=errors.pitch_external_um)


def batch_errors(geo: InternalGeometry, n: int, rng: np.random.Generator, *,
                 runout_um: Mapping[str, float] | None = None,
                 f_pt_um: Mapping[str, float] | None = None) -> dict[str, np.ndarray]:
    """``n`` units' errors drawn within the tolerances (module doc): arrays for
    :func:`te_curves_arcsec`."""
    runout = dict(TABLE1_RUNOUT_UM, **(runout_um or {}))
    fpt = {k: F_PT_LIMIT_UM[g] for k, g in TABLE1_GRADES.items()} | dict(f_pt_um or {})
    s_e, s_t = TRUNCATION_SIGMAS_ECCENTRICITY, TRUNCATION_SIGMAS_TOOTH

    def singles(limit: float, z: int) -> np.ndarray:
        return _truncated_normal(rng, -limit, limit, n * z, s_t).reshape(n, z)

    return {
        "ecc_internal_um": _truncated_rayleigh(rng, runout["internal"] / 2.0, n, s_e),
        "ecc_external_um": _truncated_rayleigh(rng, runout["external"] / 2.0, n, s_e),
        "beta_rad": rng.uniform(0.0, 2.0 * math.pi, n),
        "internal_phase_rad": rng.uniform(0.0, 2.0 * math.pi, n),
        "pitch_internal_um": positions_from_single_pitch(singles(fpt["internal"],
                                                                 geo.z_internal)),
        "pitch_external_um": positions_from_single_pitch(singles(fpt["external"],
                                                                 geo.z_external)),
    }
