"""Seed 000 design chain for the internal involute pair: eqs. (1)-(16) end to end.

M values over pins -> pressure angle at the pin centre (eqs. 12/13) -> equivalent profile shift
(eq. 14) -> working pressure angle (eq. 15, standard and printed forms) -> zero-backlash center
distance (eq. 16) -> eccentric distance to set (eq. 9); and the backlash budget: tooth
thickness (eq. 2), center distance (eq. 3), runout over the shaft angle (eqs. 4-7), bearing
clearance (eq. 7), as angles by eq. (1). The loop every analysis compares a measurement with is
:func:`analysis.models.nominal.reference_nominal_model`; this chain answers design questions.
Lengths in mm, backlash in um, angles in arcmin or degrees as named.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from analysis.errors import AnalysisError
from analysis.models import seed000_geometry as geo
from analysis.models.nominal import (
    m_value_deviation_mm,
    nominal_free_play_um,
    standard_m_values_mm,
)
from analysis.models.seed000_geometry import format_arcmin, runout_center_distance_mm
from analysis.models.seed000_unit import InternalPairUnit

__all__ = [
    "InternalPairUnit",
    "Seed000Design",
    "design_chain",
    "format_arcmin",
    "runout_center_distance_mm",
]

FORMS = ("standard", "paper")


@dataclass(frozen=True)
class Seed000Design:
    """Everything the seed 000 chain says about one unit (None = unknown from the data).

    Dicts keyed ``internal``/``external`` are per gear; keyed ``standard``/``paper`` are the two
    forms of eq. (15) (standard involute relation / as printed)."""

    unit: InternalPairUnit
    standard_m_value_mm: dict[str, float] | None
    m_value_deviation_mm: dict[str, float | None] | None
    pin_pressure_angle_deg: dict[str, float | None] | None
    equivalent_shift_coeff: dict[str, float]
    working_pressure_angle_deg: dict[str, float]
    zero_backlash_center_distance_mm: dict[str, float]
    recommended_eccentric_distance_mm: dict[str, float | None]
    backlash_budget_um: dict[str, float | None]
    design_lost_motion_arcmin: float | None
    compensated_lost_motion_arcmin: float | None
    nominal_play_arcmin: float
    torsional_stiffness_Nm_per_arcmin: float | None
    center_distance_period_rev: int
    center_distance_range_mm: dict[str, float] | None
    fit_check: dict[str, Any] | None
    assumptions: list[str] = field(default_factory=list)

    @property
    def equivalent_shift_mm(self) -> dict[str, float]:
        """Equivalent radial shift x m (mm) of each gear (Table 3 "等效变位量")."""
        return {k: v * self.unit.module_mm for k, v in self.equivalent_shift_coeff.items()}

    def to_dict(self) -> dict[str, Any]:
        """The ``rig model --json`` document (numbers in arcmin as floats, mm, um)."""
        budget_arcmin = {
            k: (None if v is None else self._arcmin(v)) for k, v in self.backlash_budget_um.items()
        }
        return {
            "model": "seed000",
            "unit": self.unit.to_mapping(),
            "standard_m_value_mm": self.standard_m_value_mm,
            "m_value_deviation_mm": self.m_value_deviation_mm,
            "pin_pressure_angle_deg": self.pin_pressure_angle_deg,
            "equivalent_shift_coeff": self.equivalent_shift_coeff,
            "equivalent_shift_mm": self.equivalent_shift_mm,
            "working_pressure_angle_deg": self.working_pressure_angle_deg,
            "zero_backlash_center_distance_mm": self.zero_backlash_center_distance_mm,
            "recommended_eccentric_distance_mm": self.recommended_eccentric_distance_mm,
            "backlash_budget_um": self.backlash_budget_um,
            "backlash_budget_arcmin": budget_arcmin,
            "design_lost_motion_arcmin": self.design_lost_motion_arcmin,
            "compensated_lost_motion_arcmin": self.compensated_lost_motion_arcmin,
            "nominal_play_arcmin": self.nominal_play_arcmin,
            "torsional_stiffness_Nm_per_arcmin": self.torsional_stiffness_Nm_per_arcmin,
            "center_distance_period_rev": self.center_distance_period_rev,
            "center_distance_range_mm": self.center_distance_range_mm,
            "fit_check": self.fit_check,
            "assumptions": list(self.assumptions),
        }

    def _arcmin(self, j_t_um: float) -> float:
        return geo.backlash_arcmin_from_um(j_t_um, self.unit.module_mm, self.unit.z_internal)


def design_chain(
    unit: InternalPairUnit | Mapping[str, Any],
    *,
    bearing_clearance_mm: tuple[float, ...] | list[float] | None = None,
) -> Seed000Design:
    """Run seed 000 eqs. (1)-(16) on a unit (or its run.json mapping).

    ``bearing_clearance_mm`` overrides the unit's bearing radial clearances (mm, one per
    bearing of eq. 9). Raises AnalysisError on data the equations cannot take."""
    assumptions: list[str] = []
    if not isinstance(unit, InternalPairUnit):
        unit, assumptions = InternalPairUnit.from_mapping(unit)
    if bearing_clearance_mm is not None:
        clearances: tuple[float, ...] | None = tuple(float(u) for u in bearing_clearance_mm)
        if any(not math.isfinite(u) or u < 0 for u in clearances):
            raise AnalysisError(f"bearing_clearance_mm must be >= 0, got {bearing_clearance_mm}")
    else:
        clearances = unit.bearing_clearance_mm
    alpha = unit.pressure_angle_rad
    a0 = unit.standard_center_distance_mm
    a = float(unit.center_distance_mm)

    # eqs. (12)-(14): M values -> alpha_M -> equivalent shift
    m0, deviation, pin_angle, shift = _equivalent_shifts(unit, assumptions)
    # eqs. (15), (16), (9)
    work_angle: dict[str, float] = {}
    zero_backlash: dict[str, float] = {}
    eccentric: dict[str, float | None] = {}
    runouts_known = unit.runout_internal_mm is not None and unit.runout_external_mm is not None
    for form in FORMS:
        angle = geo.working_pressure_angle_rad(
            shift["internal"], shift["external"], unit.z_internal, unit.z_external, alpha, form
        )
        work_angle[form] = math.degrees(angle)
        zero_backlash[form] = geo.zero_backlash_center_distance_mm(a0, alpha, angle)
        eccentric[form] = (
            geo.recommended_eccentric_distance_mm(
                zero_backlash[form], unit.runout_internal_mm, unit.runout_external_mm, clearances
            )
            if runouts_known and clearances is not None
            else None
        )
    if not (runouts_known and clearances is not None):
        assumptions.append("eq. (9) needs both runouts and the bearing clearances: not computed")

    # backlash budget, eqs. (2), (3), (7)
    j_nominal, more = nominal_free_play_um(unit)
    assumptions += more
    e_m, _ = m_value_deviation_mm(unit)
    runout_um = (
        geo.eccentricity_backlash_um(
            [unit.runout_internal_mm / 2.0, unit.runout_external_mm / 2.0], alpha
        )
        if runouts_known
        else None
    )
    bearing_um = (
        geo.eccentricity_backlash_um([u / 2.0 for u in clearances], alpha)
        if clearances is not None
        else None
    )
    budget = {
        "tooth_thickness": geo.tooth_thickness_backlash_um(e_m, alpha),
        "center_distance": geo.center_distance_backlash_um(a0 - a, alpha),
        "runout_worst_case": runout_um,
        "bearing_clearance_worst_case": bearing_um,
    }

    def arcmin(j_um: float) -> float:
        return geo.backlash_arcmin_from_um(j_um, unit.module_mm, unit.z_internal)

    design = compensated = None
    if runout_um is not None:
        compensated = arcmin(runout_um)
        if j_nominal >= 0:
            design = arcmin(j_nominal + runout_um)
        else:
            assumptions.append(
                f"free play by eqs. (2)-(3) is negative ({j_nominal:.1f} um) at {a:g} mm: "
                "interference, design lost motion undefined"
            )
    else:
        assumptions.append("runouts unknown: design and compensated lost motion not computed")

    stiffness = None
    if unit.face_width_mm is not None:
        stiffness = unit.pair_stiffness(unit.face_width_mm, a).torsional_stiffness_Nm_per_arcmin

    cd_range = fit = None
    if runouts_known:
        e1, e2 = unit.runout_internal_mm / 2.0, unit.runout_external_mm / 2.0
        cd_range = {
            "max": geo.center_distance_max_mm(a, e1, e2),
            "min": geo.center_distance_min_mm(a, e1, e2),
        }
        fit = _fit_check(unit, a, zero_backlash, eccentric, clearances, assumptions)

    return Seed000Design(
        unit=unit,
        standard_m_value_mm=m0,
        m_value_deviation_mm=deviation,
        pin_pressure_angle_deg=pin_angle,
        equivalent_shift_coeff=shift,
        working_pressure_angle_deg=work_angle,
        zero_backlash_center_distance_mm=zero_backlash,
        recommended_eccentric_distance_mm=eccentric,
        backlash_budget_um=budget,
        design_lost_motion_arcmin=design,
        compensated_lost_motion_arcmin=compensated,
        nominal_play_arcmin=arcmin(j_nominal),
        torsional_stiffness_Nm_per_arcmin=stiffness,
        center_distance_period_rev=geo.center_distance_period_rev(
            unit.z_internal, unit.z_external
        ),
        center_distance_range_mm=cd_range,
        fit_check=fit,
        assumptions=list(dict.fromkeys(assumptions)),
    )


def _equivalent_shifts(
    unit: InternalPairUnit, assumptions: list[str]
) -> tuple[Any, Any, Any, dict[str, float]]:
    """Seed 000 eqs. (12)-(14) on the smallest ring and largest pinion M value (Table 3)."""
    shift = {"internal": 0.0, "external": 0.0}
    if unit.m_value_internal_mm is None and unit.m_value_external_mm is None:
        assumptions.append("no M values: equivalent shifts taken as 0 (nominal teeth)")
        return None, None, None, shift
    if unit.pin_diameter_mm is None:
        raise AnalysisError("unit key 'pin_diameter_mm' missing: the M values cannot be read")
    m0_int, m0_ext = standard_m_values_mm(unit)
    m0 = {"internal": m0_int, "external": m0_ext}
    deviation: dict[str, float | None] = {"internal": None, "external": None}
    pin_angle: dict[str, float | None] = {"internal": None, "external": None}
    gears = (
        ("internal", unit.z_internal, unit.m_value_internal_mm, min),
        ("external", unit.z_external, unit.m_value_external_mm, max),
    )
    for name, z, values, pick in gears:
        if values is None:
            assumptions.append(f"m_value_{name}_mm missing: its equivalent shift taken as 0")
            continue
        measured = pick(values)
        deviation[name] = measured - m0[name]
        alpha_m = geo.pin_pressure_angle_rad(
            measured, z, unit.module_mm, unit.pressure_angle_rad, unit.pin_diameter_mm,
            internal=(name == "internal"),
        )
        pin_angle[name] = math.degrees(alpha_m)
        shift[name] = geo.shift_coeff_from_pin_angle(
            alpha_m, z, unit.module_mm, unit.pressure_angle_rad, unit.pin_diameter_mm,
            internal=(name == "internal"),
        )
    return m0, deviation, pin_angle, shift


def _fit_check(
    unit: InternalPairUnit,
    a: float,
    zero_backlash: dict[str, float],
    eccentric: dict[str, float | None],
    clearances: tuple[float, ...] | None,
    assumptions: list[str],
) -> dict[str, Any]:
    """Largest effective center distance over the shaft angle (eq. 5, less half the bearing
    clearances, which close the mesh gap) against the zero-backlash distance of each form."""
    if clearances is None:
        assumptions.append("fit check: bearing clearance unknown, taken as 0 (conservative)")
    half_runout = (unit.runout_internal_mm + unit.runout_external_mm) / 2.0
    half_bearing = float(sum(clearances or ())) / 2.0

    def verdict(eccentric_mm: float, form: str) -> dict[str, Any]:
        largest = eccentric_mm + half_runout - half_bearing
        margin_um = 1000.0 * (zero_backlash[form] - largest)
        return {
            "eccentric_distance_mm": eccentric_mm,
            "largest_center_distance_mm": largest,
            "margin_um": margin_um,
            "verdict": "interference" if margin_um < -1e-6 else "clearance",
        }

    out: dict[str, Any] = {"at_center_distance": {f: verdict(a, f) for f in FORMS}}
    paper_eccentric = eccentric.get("paper")
    if paper_eccentric is not None:
        out["standard_form_at_paper_eccentric_distance"] = verdict(paper_eccentric, "standard")
    return out
