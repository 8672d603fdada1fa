"""Plant geometry of a ``cycloid`` unit: seed 002's compound cycloid pair, assembled.

Gear 2 (internal, the compound cycloid of eq. 1) is fixed in the housing; gear 1 (external,
conjugate by eqs. 2-8 and modified by eqs. 9-14) sits on the crank at the eccentricity e and
is the output (its rotation reaches the output flange); the crank (input) is locked. At crank
angle theta the pair is at mesh phase ``beta = theta`` (eq. 6's O1 = e (-sin beta, cos beta)),
so the pattern repeats every tooth pitch of gear 2, ``360 / z2`` deg of input.

Per mesh phase (``[cycloid] mesh_phases`` of them over one pitch, interpolated between) the
assembled pair is solved (:func:`analysis.models.seed002_clearance.flank_contacts`): gear 1
turned about O1 until a flank touches, each way. That gives

* the free play ``theta_+ - theta_-`` and its centre (the loop's twist offset) at the phase;
* the **loaded flank contact**: the flanks within reach, their first-contact turns and the
  moment arms of their contact normals, ``T = sum_i k l_i^2 (theta - theta_i)+`` (seed 004 eq.
  8 single-pair stiffness k per flank): the stiffness grows as more flanks take load. The
  mean of that curve over the phases and both sides is the plant's mesh compliance.

The switchable effects and the unit's deviations, with circumferential plays in um on gear
1's pitch circle r1 (output angle ``arcmin = 3437.75 j / (1000 r1)``, the seed 000 eq. (1)
form at r1):

* offset (shift) modification Delta1 and its error: to first order at the pitch circle each
  side opens by ``Delta1 cot(chi)``, ``tan(chi) = 2 h1 / (1 - 4 f1 h1)`` (seed 002 eqs. 9-10,
  :func:`analysis.models.seed002_clearance.closed_form_clearance`); the design's Delta1 is in
  the solved tables, an as-made error ``shift_error_mm`` adds ``2 cot(chi)`` per mm of play;
* rotation modification Delta2 and its error: ``-2 Delta2`` per side (eq. 11-12, seed 002's
  "twice Delta2" along the pitch circle), ``rotation_error_mm`` adds ``-4`` per mm of play;
* equidistant modification delta (each flank ground back ``delta`` along its normal): the
  first-contact turn grows by ``delta / l`` each side (l the contact normal's arm about O1);
* eccentricity error and runouts: the center distance O1O2 of eq. (6) is ``e + de``; a larger
  one acts as a negative shift (eq. 9: the shift is a center-distance change between tool and
  gear), ``-2 cot(chi)`` um of play per um; the gears' runouts change O1O2 with the crank
  angle as seed 000 eq. (4) does for any few-tooth-difference pair;
* crank bearings: their radial clearances let O1 move toward gear 2 by ``sum(u_r) / 2``
  (seed 000 eq. 7's reading), ``+2 cot(chi) sum(u_r) / 2`` of play, then a soft stage;
* per-tooth profile (thickness) and pitch errors of gear 2 and gear 1 (um on r1, the circle
  seed 002 defines Delta_fpt on): the tooth pair at the mesh's centre, ``n = floor(theta z2 /
  360)``, gear 2 tooth ``n mod z2``, gear 1 tooth ``n mod z1``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from analysis.errors import AnalysisError
from analysis.models.cycloid_nominal import cycloid_nominal_model
from analysis.models.mesh_stiffness import single_pair_stiffness_N_per_mm_um
from analysis.models.seed002_clearance import Modification, flank_contacts, loaded_turn_rad
from analysis.models.seed002_cycloid import CompoundCycloidPair, flank_angle_rad
from simulators.plant.geometry import ARCMIN_PER_RAD, MeshGeometry, NominalMesh, UnitAndEffects

LOAD_GRID_NM = (0.0, 2.0, 5.0, 10.0, 20.0, 40.0, 80.0, 160.0, 320.0)
"""Flank torques (N*m) the mean loaded-contact curve is tabulated at (linear between, the
last slope beyond)."""


@dataclass(frozen=True)
class _Phases:
    """Per mesh phase: play (rad), centre (rad), arms of the first contacts (mm)."""

    play_rad: np.ndarray
    centre_rad: np.ndarray
    arm_plus_mm: np.ndarray
    arm_minus_mm: np.ndarray
    mean_turn_rad: np.ndarray  # mean loaded turn beyond first contact at LOAD_GRID_NM


@lru_cache(maxsize=16)
def _solve_phases(pair: CompoundCycloidPair, mod: Modification, phases: int,
                  k_contact_N_per_um: float) -> _Phases:
    """The assembled pair at ``phases`` mesh phases over one pitch of gear 2 (seed 002 eqs.
    1-14 through flank_contacts; loaded turns by loaded_turn_rad)."""
    grid = np.asarray(LOAD_GRID_NM)
    plays, centres, arm_p, arm_m, turns = [], [], [], [], []
    for beta in np.arange(phases) * 2.0 * math.pi / pair.z_internal / phases:
        first, arms = {}, {}
        for side in (1, -1):
            reach = 150.0
            for _ in range(5):
                contacts = flank_contacts(pair, mod, side, float(beta), reach_um=reach)
                try:
                    turn = loaded_turn_rad(contacts, grid, k_contact_N_per_um)
                    break
                except AnalysisError:
                    reach *= 3.0
            else:
                raise AnalysisError(f"{grid[-1]} N*m turns gear 1 beyond {reach} um")
            first[side] = contacts.first_rad
            arms[side] = float(contacts.arm_mm[np.argmin(side * contacts.angle_rad)])
            turns.append(side * (turn - contacts.first_rad))
        plays.append(first[1] - first[-1])
        centres.append(0.5 * (first[1] + first[-1]))
        arm_p.append(arms[1])
        arm_m.append(arms[-1])
    return _Phases(np.array(plays), np.array(centres), np.array(arm_p), np.array(arm_m),
                   np.mean(turns, axis=0))


@dataclass(frozen=True)
class CycloidGeometry(MeshGeometry):
    """Seed 002's assembled compound cycloid pair on the rig (see the module docstring)."""

    r1_mm: float = 78.0
    cot_chi: float = 1.0
    phase_count: int = 6
    phase_play_um: np.ndarray | None = None
    phase_centre_um: np.ndarray | None = None
    phase_arm_plus_mm: np.ndarray | None = None
    phase_arm_minus_mm: np.ndarray | None = None
    deviation_play_um: float = 0.0
    equidistant_mm: float = 0.0
    eccentricity_error_um: float = 0.0
    stages: tuple[tuple[float, float], ...] = ()
    injected: dict[str, Any] | None = None

    @classmethod
    def from_config(cls, config: UnitAndEffects) -> CycloidGeometry:
        """Build from a PlantConfig with a ``kind = "cycloid"`` unit (ValueError names the
        key)."""
        unit = dict(config.unit)
        try:
            model, _ = cycloid_nominal_model(unit)
        except AnalysisError as exc:
            raise ValueError(f"key unit: {exc}") from exc
        if unit.get("face_width_mm") is None:
            raise ValueError("key unit.face_width_mm: missing (the plant needs the stiffness)")
        pair = CompoundCycloidPair(
            module_mm=float(unit["module_mm"]), z_internal=int(unit["z_internal"]),
            z_external=int(unit["z_external"]), height_coeff=float(unit["height_coeff"]),
            shape_coeff=float(unit["shape_coeff"]),
            eccentricity_mm=None if unit.get("eccentricity_mm") is None
            else float(unit["eccentricity_mm"]))
        mod = Modification(float(unit.get("shift_modification_mm") or 0.0),
                           float(unit.get("rotation_modification_mm") or 0.0))
        cy = config.cycloid
        k_contact = float(unit["face_width_mm"]) * single_pair_stiffness_N_per_mm_um(
            pair.z_internal, pair.z_external)
        try:
            ph = _solve_phases(pair, mod, cy.mesh_phases, k_contact)
        except AnalysisError as exc:
            raise ValueError(f"key unit: {exc}") from exc
        r1 = pair.pitch_radius_external_mm
        cot_chi = 1.0 / math.tan(flank_angle_rad(pair))
        um = 1000.0 * r1
        # the mean loaded-contact curve: initial compliance, then a drop per segment
        grid = np.asarray(LOAD_GRID_NM)
        slopes = np.diff(ph.mean_turn_rad) / np.diff(grid)
        stages = tuple((float(grid[i]), float(slopes[i - 1] - slopes[i]))
                       for i in range(1, slopes.size) if slopes[i - 1] - slopes[i] > 0.0)
        c0 = float(slopes[0])
        play_um = ph.play_rad * um
        nominal = NominalMesh(
            play_um=float(np.mean(play_um)),
            play_arcmin=float(np.mean(ph.play_rad)) * ARCMIN_PER_RAD,
            mesh_stiffness_N_per_um=k_contact,
            stiffness_Nm_per_arcmin=1.0 / (c0 * ARCMIN_PER_RAD),
            contact_ratio=model.flanks_loaded_at_reference,
            working_pressure_angle_deg=90.0 - math.degrees(flank_angle_rad(pair)),
        )
        deviation = 2.0 * cot_chi * 1000.0 * cy.shift_error_mm - 4.0 * 1000.0 * cy.rotation_error_mm
        injected = {
            "eccentricity_error_um": cy.eccentricity_error_um,
            "shift_error_mm": cy.shift_error_mm, "rotation_error_mm": cy.rotation_error_mm,
            "equidistant_modification_mm": cy.equidistant_modification_mm,
        }
        return cls.build(
            config, nominal, pair.z_internal, pair.z_external, pair.module_mm, cot_chi,
            pair.e_mm, kind="cycloid", runout_sign=-1.0, r1_mm=r1, cot_chi=cot_chi,
            phase_count=cy.mesh_phases, phase_play_um=play_um,
            phase_centre_um=ph.centre_rad * um, phase_arm_plus_mm=ph.arm_plus_mm,
            phase_arm_minus_mm=ph.arm_minus_mm, deviation_play_um=deviation,
            equidistant_mm=cy.equidistant_modification_mm,
            eccentricity_error_um=cy.eccentricity_error_um, stages=stages, injected=injected)

    # -- overrides -----------------------------------------------------------------------
    def arcmin_from_um(self, j_t_um: float) -> float:
        """Circumferential play (um on gear 1's pitch circle r1) -> output angle (arcmin)."""
        return ARCMIN_PER_RAD * j_t_um / (1000.0 * self.r1_mm)

    @property
    def mesh_stiffening(self) -> tuple[tuple[float, float], ...]:
        return self.stages

    def _phase(self, input_angle_deg: float, table: np.ndarray) -> float:
        """Periodic linear interpolation of a per-phase table at crank angle theta (deg)."""
        u = (input_angle_deg * self.z_internal / 360.0) % 1.0 * self.phase_count
        i = int(math.floor(u)) % self.phase_count
        w = u - math.floor(u)
        return float((1.0 - w) * table[i] + w * table[(i + 1) % self.phase_count])

    def modification_play_um(self, input_angle_deg: float) -> float:
        """Play (um on r1) the as-made deviations add: shift/rotation errors (eqs. 9-12 first
        order), the equidistant modification (``delta r1 (1/l+ + 1/l-)``) and the eccentricity
        error (``-2 cot(chi) de``)."""
        eq = 0.0
        if self.equidistant_mm:
            inv = (1.0 / self._phase(input_angle_deg, self.phase_arm_plus_mm)
                   + 1.0 / self._phase(input_angle_deg, self.phase_arm_minus_mm))
            eq = 1000.0 * self.equidistant_mm * self.r1_mm * inv
        ecc = self.runout_sign * 2.0 * self.tan_alpha * self.eccentricity_error_um
        return self.deviation_play_um + eq + ecc

    def base_play_um(self, input_angle_deg: float) -> float:
        """The assembled pair's play at the crank angle (solved tables) with the deviations."""
        return (self._phase(input_angle_deg, self.phase_play_um)
                + self.modification_play_um(input_angle_deg))

    def pitch_offset_um(self, input_angle_deg: float) -> float:
        """The play's centre at the mesh phase plus the tooth pitch errors (um on r1)."""
        return (self._phase(input_angle_deg, self.phase_centre_um)
                + super().pitch_offset_um(input_angle_deg))

    def kind_truth(self, input_angle_deg: float) -> dict[str, Any]:
        return {
            "kind": "cycloid",
            "mesh_phase": (input_angle_deg * self.z_internal / 360.0) % 1.0,
            "assembled_play_arcmin": self.arcmin_from_um(
                self._phase(input_angle_deg, self.phase_play_um)),
            "modification_play_arcmin": self.arcmin_from_um(
                self.modification_play_um(input_angle_deg)),
            "play_per_center_distance_um_per_um": self.runout_sign * 2.0 * self.tan_alpha,
            "pitch_radius_output_mm": self.r1_mm,
            "injected": dict(self.injected or {}),
        }
