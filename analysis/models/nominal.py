"""The reference nominal model, version 1, exactly as pinned in run-format.md.

Free play from seed 000 eqs. (1)-(3) (M-value deviation and center distance), torsional
stiffness from seed 004 eq. (8) (see :mod:`analysis.models.mesh_stiffness`), and the flank
rule ``twist = s * play / 2 + T / K``. Runout and bearing clearance are *not* in it: they are
effects of their own. The design chain around it is :mod:`analysis.models.seed000`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from analysis.errors import AnalysisError
from analysis.models.seed000_geometry import backlash_arcmin_from_um, m_value_mm
from analysis.models.seed000_unit import InternalPairUnit


def standard_m_values_mm(unit: InternalPairUnit) -> tuple[float, float]:
    """M0 of the ring and of the pinion (mm): seed 000 eqs. (12)-(14) with x = 0, rounded to
    0.001 mm as the paper does (42.434 and 42.436 mm for the seed 000 pair)."""
    if unit.pin_diameter_mm is None:
        raise AnalysisError("unit key 'pin_diameter_mm' missing: M0 (eqs. 12-14) needs it")
    m0 = [
        round(
            m_value_mm(z, unit.module_mm, unit.pressure_angle_rad, unit.pin_diameter_mm, 0.0,
                       internal=internal),
            3,
        )
        for z, internal in ((unit.z_internal, True), (unit.z_external, False))
    ]
    return m0[0], m0[1]


def m_value_deviation_mm(unit: InternalPairUnit) -> tuple[float, list[str]]:
    """E_M (mm) of run-format.md: (min internal - M0_int) + (M0_ext - max external).

    A gear without M values is taken at nominal tooth thickness (its term 0) and said so; M
    values without ``pin_diameter_mm`` cannot be read and raise AnalysisError."""
    assumptions: list[str] = []
    if unit.m_value_internal_mm is None and unit.m_value_external_mm is None:
        return 0.0, ["no M values: tooth thickness taken as nominal (E_M = 0)"]
    if unit.pin_diameter_mm is None:
        raise AnalysisError("unit key 'pin_diameter_mm' missing: the M values cannot be read")
    m0_int, m0_ext = standard_m_values_mm(unit)
    e_m = 0.0
    if unit.m_value_internal_mm is None:
        assumptions.append("m_value_internal_mm missing: ring tooth thickness taken as nominal")
    else:
        e_m += min(unit.m_value_internal_mm) - m0_int
    if unit.m_value_external_mm is None:
        assumptions.append("m_value_external_mm missing: pinion tooth thickness taken as nominal")
    else:
        e_m += m0_ext - max(unit.m_value_external_mm)
    return e_m, assumptions


def nominal_free_play_um(unit: InternalPairUnit) -> tuple[float, list[str]]:
    """Signed circumferential free play j_t (um), seed 000 eqs. (2) + (3) as pinned:
    ``1000 tan(alpha) (E_M + 2 (a0 - a))``. Negative means interference."""
    e_m, assumptions = m_value_deviation_mm(unit)
    a0 = unit.standard_center_distance_mm
    a = float(unit.center_distance_mm)  # never None: InternalPairUnit fills in a0
    j_t = 1000.0 * math.tan(unit.pressure_angle_rad) * (e_m + 2.0 * (a0 - a))
    return j_t, assumptions


@dataclass(frozen=True)
class NominalModel:
    """The loop predicted by the reference nominal model (arcmin at the output, N*m)."""

    play_arcmin: float
    play_um: float
    stiffness_Nm_per_arcmin: float
    mesh_stiffness_N_per_um: float
    contact_ratio: float
    working_pressure_angle_deg: float
    m_value_deviation_mm: float = 0.0
    assumptions: tuple[str, ...] = field(default=())

    @property
    def backlash_arcmin(self) -> float:
        """Loop width at zero torque (= Nabtesco "backlash", GB/T 齿隙) = the free play."""
        return self.play_arcmin

    def twist_arcmin(self, torque_Nm: np.ndarray, start_flank: int = -1) -> np.ndarray:
        """Output twist (arcmin) along a torque history: ``s * play / 2 + T / K``.

        The flank s becomes +1 when T > 0, -1 when T < 0 and is kept while T == 0; before the
        first non-zero torque it is ``start_flank`` (-1: preloaded to -T, run-format.md)."""
        if start_flank not in (-1, 1):
            raise AnalysisError(f"start_flank must be -1 or +1, got {start_flank!r}")
        torque = np.asarray(torque_Nm, dtype=float)
        if torque.ndim != 1:
            raise AnalysisError(f"torque must be a 1-D array, got shape {torque.shape}")
        if not np.all(np.isfinite(torque)):
            raise AnalysisError("torque contains NaN or infinite values")
        sign = np.sign(torque)
        index = np.where(sign != 0, np.arange(1, torque.size + 1), 0)
        last = np.maximum.accumulate(index) if torque.size else index
        flank = np.concatenate(([float(start_flank)], sign))[last]
        return flank * self.play_arcmin / 2.0 + torque / self.stiffness_Nm_per_arcmin

    def lost_motion_arcmin(self, rated_torque_Nm: float, pct: float) -> float:
        """Lost motion (arcmin): the loop width between +-pct % of the rated torque,
        ``play + 2 (pct / 100 * T) / K``."""
        if not rated_torque_Nm > 0 or not pct >= 0:
            raise AnalysisError(
                f"rated torque must be > 0 and pct >= 0, got {rated_torque_Nm}, {pct}"
            )
        torque = pct / 100.0 * rated_torque_Nm
        return self.play_arcmin + 2.0 * torque / self.stiffness_Nm_per_arcmin

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields (an unknown stiffness, K = inf, is written as None)."""
        def finite(x: float) -> float | None:
            return x if math.isfinite(x) else None

        return {
            "play_arcmin": self.play_arcmin,
            "play_um": self.play_um,
            "stiffness_Nm_per_arcmin": finite(self.stiffness_Nm_per_arcmin),
            "mesh_stiffness_N_per_um": finite(self.mesh_stiffness_N_per_um),
            "contact_ratio": self.contact_ratio,
            "working_pressure_angle_deg": self.working_pressure_angle_deg,
            "m_value_deviation_mm": self.m_value_deviation_mm,
            "assumptions": list(self.assumptions),
        }


def reference_nominal_model(unit: InternalPairUnit | Mapping[str, Any]) -> NominalModel:
    """Reference nominal model v1 of run-format.md for a unit (or its run.json mapping).

    A missing ``face_width_mm`` leaves the stiffness unknown: the mesh is taken as rigid
    (K = inf) and the assumption is listed. A negative free play (interference at this
    center distance) raises AnalysisError."""
    assumptions: list[str] = []
    if not isinstance(unit, InternalPairUnit):
        unit, assumptions = InternalPairUnit.from_mapping(unit)
    j_t, more = nominal_free_play_um(unit)
    assumptions += more
    if j_t < 0:
        raise AnalysisError(
            f"center distance {unit.center_distance_mm} mm gives a negative free play "
            f"({j_t:.2f} um): the teeth interfere, no loop to predict"
        )
    e_m, _ = m_value_deviation_mm(unit)
    stiffness = unit.pair_stiffness(
        unit.face_width_mm if unit.face_width_mm is not None else 1.0,
        float(unit.center_distance_mm),
    )
    k_m = stiffness.mesh_stiffness_N_per_um
    k_t = stiffness.torsional_stiffness_Nm_per_arcmin
    if unit.face_width_mm is None:
        assumptions.append(
            "face_width_mm missing: stiffness unknown, mesh taken as rigid (K = inf)"
        )
        k_m = k_t = math.inf
    return NominalModel(
        play_arcmin=backlash_arcmin_from_um(j_t, unit.module_mm, unit.z_internal),
        play_um=j_t,
        stiffness_Nm_per_arcmin=k_t,
        mesh_stiffness_N_per_um=k_m,
        contact_ratio=stiffness.contact_ratio,
        working_pressure_angle_deg=stiffness.working_pressure_angle_deg,
        m_value_deviation_mm=e_m,
        assumptions=tuple(dict.fromkeys(assumptions)),
    )
