"""Nominal loop of a parallel-axis helical beveloid unit (unit kind ``beveloid``).

Same loop as the reference nominal model (:class:`analysis.models.nominal.NominalModel`:
``twist = s play / 2 + T / K``), with the beveloid's own play and stiffness:

* **play**: seed 001's pair at its center distance and axial position, from the closed form
  :func:`analysis.models.seed001_beveloid.backlash_closed_form` (checked against the contact
  equations in tests/analysis/test_seed001.py). The output is the gear (``z_gear``).
* **stiffness**: seed 004 eq. (8) ``k_m = b (0.75 eps + 0.25) k'`` with ISO 6336-1's virtual
  tooth numbers ``z / cos^3(beta)`` in ``k'`` and eq. (9)'s transverse contact ratio of each
  flank side at its working pressure angle (tip radii at mid face); at the output
  ``K = k_m (r_b cos(beta_b))^2`` for each flank side, and the loop's single K is the one of
  the mean compliance of the two sides (they differ by a few per cent: the flanks of a helical
  beveloid have different pressure angles).

Unit keys (run.json ``unit``): ``z_pinion``, ``z_gear``, ``module_mm`` (normal),
``pressure_angle_deg`` (normal), ``helix_angle_deg`` (pinion, + right hand),
``cone_angle_deg`` (pinion), ``face_width_mm``, optional ``center_distance_mm`` (default: the
standard one), ``axial_shift_mm`` (gear's axial position from the zero-backlash one, + towards
the pinion's thick end; default 0) and ``addendum_coeff`` (default 1.0).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from analysis.errors import AnalysisError
from analysis.models.mesh_stiffness import (
    mesh_stiffness_N_per_um,
    single_pair_stiffness_N_per_mm_um,
    torsional_stiffness_Nm_per_arcmin,
)
from analysis.models.nominal import NominalModel
from analysis.models.seed001_beveloid import (
    COAST,
    DRIVE,
    BeveloidPair,
    backlash_closed_form,
)
from analysis.models.seed001_surfaces import BeveloidGear

REQUIRED = (
    "z_pinion", "z_gear", "module_mm", "pressure_angle_deg", "helix_angle_deg",
    "cone_angle_deg", "face_width_mm",
)


def _number(unit: Mapping[str, Any], key: str) -> float:
    value = unit[key]
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise AnalysisError(f"unit key {key!r} must be a finite number, got {value!r}")
    return float(value)


def beveloid_pair_from_unit(unit: Mapping[str, Any]) -> tuple[BeveloidPair, float, list[str]]:
    """The pair, the gear's axial shift (mm) and the assumptions made for missing keys."""
    if unit.get("kind", "beveloid") != "beveloid":
        raise AnalysisError(f"unit kind {unit.get('kind')!r} is not 'beveloid'")
    missing = [k for k in REQUIRED if k not in unit]
    if missing:
        raise AnalysisError(f"beveloid unit lacks key(s) {', '.join(missing)}")
    assumptions: list[str] = []
    teeth = {}
    for key in ("z_pinion", "z_gear"):
        z = unit[key]
        if isinstance(z, bool) or not isinstance(z, int) or z < 5:
            raise AnalysisError(f"unit key {key!r} must be an integer >= 5, got {z!r}")
        teeth[key] = z
    if "addendum_coeff" in unit:
        h_a = _number(unit, "addendum_coeff")
    else:
        h_a = 1.0
        assumptions.append("addendum_coeff missing: taken as 1.0")
    m_n, a_n = _number(unit, "module_mm"), _number(unit, "pressure_angle_deg")
    beta, delta = _number(unit, "helix_angle_deg"), _number(unit, "cone_angle_deg")
    width = _number(unit, "face_width_mm")
    pinion = BeveloidGear(teeth["z_pinion"], m_n, a_n, beta, delta, width, h_a)
    gear = BeveloidGear(teeth["z_gear"], m_n, a_n, -beta, -delta, width, h_a)
    standard = pinion.pitch_radius_mm + gear.pitch_radius_mm
    if "center_distance_mm" in unit:
        a = _number(unit, "center_distance_mm")
    else:
        a = standard
        assumptions.append(f"center_distance_mm missing: standard {standard:.4f} mm taken")
    if "axial_shift_mm" in unit:
        shift = _number(unit, "axial_shift_mm")
    else:
        shift = 0.0
        assumptions.append("axial_shift_mm missing: gear taken at the zero-backlash position")
    return BeveloidPair(pinion, gear, a), shift, assumptions


def _contact_ratio(pair: BeveloidPair, side: int) -> tuple[float, float]:
    """Seed 004 eq. (9) for the external pair, transverse, for one flank side; and the
    working pressure angle (rad) of eq. (10)."""
    p, g = pair.pinion, pair.gear
    alpha_t = p.transverse_pressure_angle(side)
    r_sum = p.pitch_radius_mm + g.pitch_radius_mm
    alpha_w = math.acos(r_sum * math.cos(alpha_t) / pair.center_distance_mm)
    total = 0.0
    for gear in (p, g):
        tip = float(gear.tip_radius_mm(0.0))
        base = gear.pitch_radius_mm * math.cos(alpha_t)
        total += gear.teeth * (math.tan(math.acos(base / tip)) - math.tan(alpha_w))
    eps = total / (2 * math.pi)
    if eps <= 0:
        raise AnalysisError(f"contact ratio {eps:.3f} <= 0: the pair does not mesh")
    return eps, alpha_w


def beveloid_nominal_model(unit: Mapping[str, Any]) -> tuple[NominalModel, list[str]]:
    """Nominal loop (NominalModel) of a beveloid unit and the assumptions it made.

    A negative play (the gear's axial position or the center distance makes the teeth
    interfere) raises AnalysisError."""
    pair, shift, assumptions = beveloid_pair_from_unit(unit)
    play = backlash_closed_form(pair, shift)
    if play.angle_arcmin < 0:
        raise AnalysisError(
            f"axial shift {shift} mm at center distance {pair.center_distance_mm} mm gives a "
            f"negative play ({play.circumferential_um:.2f} um): the teeth interfere"
        )
    p, g = pair.pinion, pair.gear
    z_virtual = [gear.teeth / math.cos(gear.beta) ** 3 for gear in (p, g)]
    k1 = single_pair_stiffness_N_per_mm_um(round(z_virtual[0]), round(z_virtual[1]))
    compliance, mesh, eps_mean, alpha_w_mean = 0.0, 0.0, 0.0, 0.0
    for side in (DRIVE, COAST):
        eps, alpha_w = _contact_ratio(pair, side)
        k_m = mesh_stiffness_N_per_um(p.face_width_mm, eps, k1)
        arm = g.base_radius_mm(side) * math.cos(g.base_helix_angle(side))
        compliance += 0.5 / torsional_stiffness_Nm_per_arcmin(k_m, arm)
        mesh += 0.5 * k_m
        eps_mean += 0.5 * eps
        alpha_w_mean += 0.5 * alpha_w
    assumptions.append(
        "stiffness: seed 004 eq. (8) with virtual tooth numbers, mean compliance of both flanks"
    )
    model = NominalModel(
        play_arcmin=play.angle_arcmin,
        play_um=play.circumferential_um,
        stiffness_Nm_per_arcmin=1.0 / compliance,
        mesh_stiffness_N_per_um=mesh,
        contact_ratio=eps_mean,
        working_pressure_angle_deg=math.degrees(alpha_w_mean),
        assumptions=tuple(dict.fromkeys(assumptions)),
    )
    return model, assumptions
