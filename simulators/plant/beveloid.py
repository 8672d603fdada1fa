"""Plant geometry of a ``beveloid`` unit: seed 001's parallel-axis helical beveloid pair.

The pinion is the input (locked at ``input_angle_deg``), the gear the output; the output turns
opposite to the input, ``ratio = z_gear / z_pinion``. Plays are circumferential in um on the
gear's pitch circle r2 (output angle ``arcmin = 3437.75 j / (1000 r2)``).

* Nominal play and stiffness: the unit's nominal loop
  (:func:`analysis.models.beveloid_nominal.beveloid_nominal_model`: the closed-form backlash of
  :func:`analysis.models.seed001_beveloid.backlash_closed_form` at the unit's center distance
  and axial shift, seed 004 eq. 8 stiffness).
* Installation errors of seed 001 eq. (8) (``[beveloid]``): the center distance error dx and
  the lateral offset dy make the center distance ``A' = hypot(A + dx, dy)``, the axial shift
  error dz moves the gear along its axis; the play is the same closed form at ``A'`` and
  ``shift + dz`` (``j ~ 2 (dA - dz tan(delta)) tan(a_n) cos(delta) / cos(beta)``: the
  beveloid's backlash is set by its axial position). The shaft-angle errors dl_h (about the
  line of centres: crossed axes) and dl_v (in the plane of the axes) give the eq. (11)
  transmission error of the TCA (eqs. 3-10, edge contact): a sawtooth over each mesh cycle
  (``360 / z_pinion`` deg of input), solved at +-0.5 deg for the unit's pair and scaled
  linearly with the angle (the TCA's TE is linear in it: 0.25 deg gives half of 0.5 deg), each
  axis apart and summed. The TE moves the loop's centre with the input angle; its effect on
  the coast flank (and so on the play) is not modelled.
* Runout (``effects.runout``): the pinion's eccentricity ``external_mm / 2`` turns with the
  input, the gear's ``internal_mm / 2`` with the output; the center distance over the input
  angle is ``|A x + e_p u(theta) - e_g u(-theta / ratio + beta)|`` and the play changes by
  ``+2 tan(a_n) cos(delta) / cos(beta)`` per um (an external pair opens with the distance).
* Bearing clearance: the shafts' radial clearances ``u_r`` let the mesh force part the gears by
  ``sum(u_r) / 2``: ``2 tan(a_n) cos(delta) / cos(beta) sum(u_r) / 2`` of play (seed 000 eq.
  7's reading), then the soft stage.
* Tooth spacing: per-tooth thickness and pitch errors (um on r2); the tooth pair in mesh is
  ``n = floor(theta z_pinion / 360)``, gear tooth ``n mod z_gear`` (the ``*_internal`` tables),
  pinion tooth ``n mod z_pinion`` (the ``*_external`` tables).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from analysis.errors import AnalysisError
from analysis.models.beveloid_nominal import beveloid_nominal_model, beveloid_pair_from_unit
from analysis.models.seed001_beveloid import (
    ARCSEC_PER_RAD,
    BeveloidPair,
    Installation,
    backlash_closed_form,
    transmission_error,
)
from simulators.plant.geometry import ARCMIN_PER_RAD, MeshGeometry, NominalMesh, UnitAndEffects

TE_REFERENCE_DEG = 0.5
"""Shaft-angle error (deg) the TCA is solved at; other sizes scale linearly."""


@lru_cache(maxsize=16)
def _te_reference(pair: BeveloidPair, axis: str, sign: float, points: int) -> np.ndarray:
    """Eq. (11) TE (arcsec) over one mesh cycle (points + 1 values) at ``sign`` 0.5 deg about
    ``axis`` ("horizontal" dl_h or "vertical" dl_v), by the TCA of seed 001 eqs. (3)-(10)."""
    angle = sign * TE_REFERENCE_DEG
    inst = (Installation(horizontal_deg=angle) if axis == "horizontal"
            else Installation(vertical_deg=angle))
    return np.asarray(transmission_error(pair, inst, points).te_arcsec, dtype=float)


@dataclass(frozen=True)
class BeveloidGeometry(MeshGeometry):
    """Seed 001's beveloid pair as installed (see the module docstring)."""

    r2_mm: float = 30.0
    z_pinion: int = 20
    z_gear: int = 20
    deviation_play_um: float = 0.0
    te_arcsec: np.ndarray | None = None
    injected: dict[str, Any] | None = None

    @classmethod
    def from_config(cls, config: UnitAndEffects) -> BeveloidGeometry:
        """Build from a PlantConfig with a ``kind = "beveloid"`` unit (ValueError names the
        key)."""
        unit = dict(config.unit)
        try:
            model, _ = beveloid_nominal_model(unit)
            pair, shift, _ = beveloid_pair_from_unit(unit)
        except AnalysisError as exc:
            raise ValueError(f"key unit: {exc}") from exc
        bv = config.beveloid
        a = pair.center_distance_mm
        installed_a = math.hypot(a + bv.center_distance_error_mm, bv.lateral_offset_mm)
        try:
            installed = backlash_closed_form(
                BeveloidPair(pair.pinion, pair.gear, installed_a), shift + bv.axial_shift_error_mm)
        except AnalysisError as exc:
            raise ValueError(f"key beveloid: {exc}") from exc
        te = np.zeros(bv.te_points_per_cycle + 1)
        for axis, angle in (("horizontal", bv.shaft_angle_horizontal_deg),
                            ("vertical", bv.shaft_angle_vertical_deg)):
            if angle:
                try:
                    ref = _te_reference(pair, axis, math.copysign(1.0, angle),
                                        bv.te_points_per_cycle)
                except AnalysisError as exc:
                    raise ValueError(f"key beveloid.shaft_angle_{axis}_deg: {exc}") from exc
                te = te + ref * abs(angle) / TE_REFERENCE_DEG
        p, g = pair.pinion, pair.gear
        r2 = g.pitch_radius_mm
        nominal = NominalMesh.of(model)
        sensitivity = math.tan(p.alpha_n) * math.cos(p.delta) / math.cos(p.beta)
        injected = {
            "axial_shift_error_mm": bv.axial_shift_error_mm,
            "center_distance_error_mm": bv.center_distance_error_mm,
            "lateral_offset_mm": bv.lateral_offset_mm,
            "shaft_angle_horizontal_deg": bv.shaft_angle_horizontal_deg,
            "shaft_angle_vertical_deg": bv.shaft_angle_vertical_deg,
        }
        return cls.build(
            config, nominal, g.teeth, p.teeth, p.normal_module_mm, sensitivity, a,
            kind="beveloid", runout_sign=1.0, r2_mm=r2, z_pinion=p.teeth, z_gear=g.teeth,
            deviation_play_um=installed.circumferential_um - model.play_um, te_arcsec=te,
            injected=injected)

    # -- overrides -----------------------------------------------------------------------
    @property
    def ratio(self) -> float:
        """z_gear / z_pinion: input (pinion) turns per output (gear) turn."""
        return self.z_gear / self.z_pinion

    def arcmin_from_um(self, j_t_um: float) -> float:
        """Circumferential play (um on the gear's pitch circle r2) -> output angle (arcmin)."""
        return ARCMIN_PER_RAD * j_t_um / (1000.0 * self.r2_mm)

    def base_play_um(self, input_angle_deg: float) -> float:
        """The installed pair's play (closed form at A' and shift + dz), um on r2."""
        return self.nominal.play_um + self.deviation_play_um

    def te_arcsec_at(self, input_angle_deg: float) -> float:
        """Eq. (11) TE (arcsec at the gear) at the pinion angle, over its mesh cycle."""
        te = self.te_arcsec
        if te is None or not te.any():
            return 0.0
        u = (input_angle_deg * self.z_pinion / 360.0) % 1.0 * (te.size - 1)
        i = min(int(u), te.size - 2)
        return float(te[i] + (u - i) * (te[i + 1] - te[i]))

    def pitch_offset_um(self, input_angle_deg: float) -> float:
        """Tooth pitch errors plus the installation's TE, um on r2."""
        te_um = self.te_arcsec_at(input_angle_deg) / ARCSEC_PER_RAD * self.r2_mm * 1000.0
        return super().pitch_offset_um(input_angle_deg) + te_um

    def tooth_pair(self, input_angle_deg: float) -> tuple[int, int, int]:
        """(mesh index n, gear tooth, pinion tooth): one pair per pinion tooth pitch."""
        n = math.floor(input_angle_deg * self.z_pinion / 360.0 + 1e-9)
        return n, n % self.z_gear, n % self.z_pinion

    def center_distance_mm(self, input_angle_deg: float) -> float:
        """Center distance (mm) with the pinion's eccentricity turning with the input and the
        gear's with the output (opposite, 1 / ratio as fast)."""
        theta = math.radians(input_angle_deg)
        gear = -theta / self.ratio + self.beta_rad
        x = (self.eccentric_distance_mm + self.ecc_external_mm * math.cos(theta)
             - self.ecc_internal_mm * math.cos(gear + self.internal_phase_rad))
        y = (self.ecc_external_mm * math.sin(theta)
             - self.ecc_internal_mm * math.sin(gear + self.internal_phase_rad))
        return math.hypot(x, y)

    def worst_case_runout_play_um(self) -> float:
        return 2.0 * self.tan_alpha * 1000.0 * (self.ecc_internal_mm + self.ecc_external_mm)

    def kind_truth(self, input_angle_deg: float) -> dict[str, Any]:
        return {
            "kind": "beveloid",
            "installation_play_arcmin": self.arcmin_from_um(self.deviation_play_um),
            "transmission_error_arcsec": self.te_arcsec_at(input_angle_deg),
            "transmission_error_pp_arcsec": float(np.ptp(self.te_arcsec))
            if self.te_arcsec is not None else 0.0,
            "play_per_center_distance_um_per_um": 2.0 * self.tan_alpha,
            "pitch_radius_output_mm": self.r2_mm,
            "injected": dict(self.injected or {}),
        }
