"""Nominal loop model of a compound cycloid unit (run.json ``unit.kind = "cycloid"``, seed 002).

The unit is a few-tooth-difference drive: gear 2 (internal, the compound cycloid of seed 002
eq. 1) is fixed, gear 1 (external, conjugate by eqs. 2-8, modified by eqs. 9-14) turns about
the locked eccentric and is the output. The model gives, like
:class:`analysis.models.nominal.NominalModel`:

* **free play**: the turn of gear 1 between first flank contacts on either side, from the
  shift and rotation modifications (:func:`analysis.models.seed002_clearance.free_play`),
  averaged over one mesh cycle (it varies a little with the mesh phase, z2 times per input turn);
* **stiffness** (an estimate): each flank that touches is a spring of seed 004 eq. (8)'s
  single-pair stiffness ``k' b`` (N/um) on its normal, with arm l about O1; the flanks engage one
  after another as gear 1 turns (``T = sum k l^2 (theta - theta_i)+``). The linear loop uses the
  secant stiffness from first contact to ``reference_torque_Nm``;
* the flank rule of run-format.md: ``twist = s * play / 2 + T / K``.

Unit keys (mm unless named): required ``z_internal``, ``z_external``, ``module_mm``,
``height_coeff`` (h1), ``shape_coeff`` (f1); optional ``shift_modification_mm`` (Delta1),
``rotation_modification_mm`` (Delta2), ``eccentricity_mm``, ``face_width_mm``,
``reference_torque_Nm``. Missing optional keys are assumed and said so.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np

from analysis.errors import AnalysisError
from analysis.models.mesh_stiffness import single_pair_stiffness_N_per_mm_um
from analysis.models.nominal import NominalModel
from analysis.models.seed002_clearance import (
    Modification,
    flank_clearance,
    flank_contacts,
    loaded_turn_rad,
)
from analysis.models.seed002_cycloid import CompoundCycloidPair

REQUIRED_KEYS = ("z_internal", "z_external", "module_mm", "height_coeff", "shape_coeff")
PAPER_REFERENCE_TORQUE_NM = 200.0
"""Seed 002's FE load (200 N*m), the default reference torque of the secant stiffness."""
ARCMIN_PER_RAD = 180.0 * 60.0 / math.pi
MESH_PHASES = 6


@dataclass(frozen=True)
class CycloidNominalModel:
    """The loop predicted for a cycloid unit (arcmin at gear 1 = the output, N*m)."""

    play_arcmin: float
    play_min_arcmin: float
    play_max_arcmin: float
    stiffness_Nm_per_arcmin: float
    reference_torque_Nm: float
    contact_stiffness_N_per_um: float
    flanks_loaded_at_reference: float
    side_clearance_pitch_um: float
    radial_clearance_um: float
    assumptions: tuple[str, ...] = field(default=())
    play_phases_arcmin: tuple[float, ...] = field(default=())
    """The free play at each of the ``MESH_PHASES`` mesh phases over one pitch of gear 2
    (arcmin); ``play_arcmin`` is their mean."""

    @property
    def backlash_arcmin(self) -> float:
        """Loop width at zero torque (Nabtesco "backlash", GB/T 齿隙) = the free play."""
        return self.play_arcmin

    def _loop(self) -> NominalModel:
        """The pinned loop of run-format.md with this play and stiffness."""
        return NominalModel(
            play_arcmin=self.play_arcmin,
            play_um=math.nan,
            stiffness_Nm_per_arcmin=self.stiffness_Nm_per_arcmin,
            mesh_stiffness_N_per_um=self.contact_stiffness_N_per_um,
            contact_ratio=math.nan,
            working_pressure_angle_deg=math.nan,
        )

    def twist_arcmin(self, torque_Nm: np.ndarray, start_flank: int = -1) -> np.ndarray:
        """Output twist (arcmin) along a torque history, ``s * play / 2 + T / K`` (the flank
        rule of run-format.md, shared with the reference nominal model)."""
        return self._loop().twist_arcmin(torque_Nm, start_flank)

    def lost_motion_arcmin(self, rated_torque_Nm: float, pct: float) -> float:
        """Lost motion (arcmin) between +-pct % of the rated torque: ``play + 2 T / K``."""
        return self._loop().lost_motion_arcmin(rated_torque_Nm, pct)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields (an unknown stiffness, K = inf, is written as None)."""
        k = self.stiffness_Nm_per_arcmin
        return {
            "kind": "cycloid",
            "play_arcmin": self.play_arcmin,
            "play_min_arcmin": self.play_min_arcmin,
            "play_max_arcmin": self.play_max_arcmin,
            "stiffness_Nm_per_arcmin": k if math.isfinite(k) else None,
            "reference_torque_Nm": self.reference_torque_Nm,
            "contact_stiffness_N_per_um": self.contact_stiffness_N_per_um,
            "flanks_loaded_at_reference": self.flanks_loaded_at_reference,
            "side_clearance_pitch_um": self.side_clearance_pitch_um,
            "radial_clearance_um": self.radial_clearance_um,
            "play_phases_arcmin": list(self.play_phases_arcmin),
            "assumptions": list(self.assumptions),
        }


def _number(unit: Mapping[str, Any], key: str) -> float:
    value = unit[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise AnalysisError(f"unit key {key!r} must be a finite number, got {value!r}")
    return float(value)


def _count(unit: Mapping[str, Any], key: str) -> int:
    value = _number(unit, key)
    if value != int(value):
        raise AnalysisError(f"unit key {key!r} must be a whole tooth count, got {value!r}")
    return int(value)


def _side_secant(
    pair: CompoundCycloidPair, mod: Modification, side: int, phase: float, torque: float,
    k_contact: float,
) -> tuple[float, float, int]:
    """(first-contact turn rad, turn from first contact to ``torque`` rad, loaded flanks)."""
    reach = 150.0
    for _ in range(4):
        contacts = flank_contacts(pair, mod, side, phase, reach_um=reach)
        first = contacts.first_rad
        if not math.isfinite(k_contact):
            return first, 0.0, 1
        try:
            turn = float(loaded_turn_rad(contacts, np.array([torque]), k_contact)[0])
        except AnalysisError:
            reach *= 4.0
            continue
        loaded = int(np.sum(side * contacts.angle_rad < side * turn))
        return first, abs(turn - first), loaded
    raise AnalysisError(f"{torque} N*m turns gear 1 beyond {reach / 4:.0f} um: check the unit")


@lru_cache(maxsize=32)
def _model(
    pair: CompoundCycloidPair, mod: Modification, face_width_mm: float | None, torque: float
) -> tuple[Any, ...]:
    """Play (arcmin: mean, min, max over the mesh phases), secant stiffness (N*m/arcmin), contact
    stiffness (N/um), loaded flanks and the per-phase plays of the assembled pair: seed 002
    eqs. (1)-(14) through :func:`flank_contacts`, seed 004 eq. (8) per flank."""
    k_contact = math.inf
    if face_width_mm is not None:
        k_contact = face_width_mm * single_pair_stiffness_N_per_mm_um(
            pair.z_internal, pair.z_external
        )
    plays, compliances, loaded = [], [], []
    for phase in np.arange(MESH_PHASES) * 2.0 * math.pi / pair.z_internal / MESH_PHASES:
        plus, d_plus, n_plus = _side_secant(pair, mod, +1, phase, torque, k_contact)
        minus, d_minus, n_minus = _side_secant(pair, mod, -1, phase, torque, k_contact)
        plays.append((plus - minus) * ARCMIN_PER_RAD)
        compliances += [d_plus * ARCMIN_PER_RAD / torque, d_minus * ARCMIN_PER_RAD / torque]
        loaded += [n_plus, n_minus]
    compliance = float(np.mean(compliances))
    stiffness = math.inf if compliance == 0.0 else 1.0 / compliance
    return (
        float(np.mean(plays)), float(np.min(plays)), float(np.max(plays)), stiffness,
        k_contact, float(np.mean(loaded)), tuple(float(p) for p in plays),
    )


def cycloid_nominal_model(
    unit: Mapping[str, Any], reference_torque_Nm: float | None = None
) -> tuple[CycloidNominalModel, list[str]]:
    """The nominal loop model of a ``cycloid`` unit from its run.json ``unit`` mapping.

    ``reference_torque_Nm`` (else the unit's key of that name, else seed 002's 200 N*m) sets
    the secant stiffness. Returns the model and the assumptions it made; missing required keys,
    bad values or a modification that makes the gears interfere raise AnalysisError."""
    missing = [key for key in REQUIRED_KEYS if unit.get(key) is None]
    if missing:
        raise AnalysisError(
            "cycloid unit lacks required key(s) " + ", ".join(repr(k) for k in missing)
            + " (seed 002 eq. 15: z2, z1, m, h1, f1)"
        )
    assumptions: list[str] = []
    ecc = None if unit.get("eccentricity_mm") is None else _number(unit, "eccentricity_mm")
    pair = CompoundCycloidPair(
        module_mm=_number(unit, "module_mm"),
        z_internal=_count(unit, "z_internal"),
        z_external=_count(unit, "z_external"),
        height_coeff=_number(unit, "height_coeff"),
        shape_coeff=_number(unit, "shape_coeff"),
        eccentricity_mm=ecc,
    )
    if ecc is None:
        assumptions.append(f"eccentricity_mm missing: e = m (z2 - z1) = {pair.e_mm:g} mm")
    values = {}
    for key in ("shift_modification_mm", "rotation_modification_mm"):
        if unit.get(key) is None:
            assumptions.append(f"{key} missing: taken as 0 (unmodified)")
            values[key] = 0.0
        else:
            values[key] = _number(unit, key)
    mod = Modification(values["shift_modification_mm"], values["rotation_modification_mm"])
    if mod == Modification():
        assumptions.append("no modification: the pair is conjugate, free play ~0")
    face = None if unit.get("face_width_mm") is None else _number(unit, "face_width_mm")
    if face is None:
        assumptions.append("face_width_mm missing: stiffness unknown, mesh taken as rigid")
    elif not face > 0:
        raise AnalysisError(f"unit key 'face_width_mm' must be > 0, got {face}")
    torque = reference_torque_Nm
    if torque is None and unit.get("reference_torque_Nm") is not None:
        torque = _number(unit, "reference_torque_Nm")
    if torque is None:
        torque = PAPER_REFERENCE_TORQUE_NM
        assumptions.append(
            f"reference_torque_Nm missing: secant stiffness at seed 002's {torque:g} N*m"
        )
    if not torque > 0:
        raise AnalysisError(f"reference torque must be > 0 N*m, got {torque}")
    assumptions.append(
        "stiffness is an estimate: seed 004 eq. (8) single-pair stiffness per touching flank"
    )
    play, play_min, play_max, k, k_contact, loaded, phases = _model(
        pair, mod, face, float(torque))
    side = flank_clearance(pair, mod) if mod != Modification() else None
    model = CycloidNominalModel(
        play_arcmin=play,
        play_min_arcmin=play_min,
        play_max_arcmin=play_max,
        stiffness_Nm_per_arcmin=k,
        reference_torque_Nm=float(torque),
        contact_stiffness_N_per_um=k_contact,
        flanks_loaded_at_reference=loaded,
        side_clearance_pitch_um=0.0 if side is None else side.circumferential_um,
        radial_clearance_um=0.0 if side is None else side.tip_reduction_um,
        assumptions=tuple(assumptions),
        play_phases_arcmin=phases,
    )
    return model, assumptions
