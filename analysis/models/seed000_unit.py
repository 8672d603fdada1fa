"""The ``unit`` object of run.json for kind ``internal_involute`` (the seed 000 pair).

Lengths in mm, angles in degrees, as run-format.md writes them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from analysis.errors import AnalysisError
from analysis.models.mesh_stiffness import MeshStiffness, internal_pair_stiffness

KIND = "internal_involute"

DEFAULT_PRESSURE_ANGLE_DEG = 20.0
DEFAULT_ADDENDUM_COEFF = 1.0
DEFAULT_CLEARANCE_COEFF = 0.25


@dataclass(frozen=True)
class InternalPairUnit:
    """Design and inspection data of an internal involute pair (ring Z1 = z_internal, pinion
    Z2 = z_external), mm and degrees. ``None`` means unknown (not measured / not given)."""

    z_internal: int
    z_external: int
    module_mm: float
    pressure_angle_deg: float = DEFAULT_PRESSURE_ANGLE_DEG
    addendum_coeff: float = DEFAULT_ADDENDUM_COEFF
    clearance_coeff: float = DEFAULT_CLEARANCE_COEFF
    face_width_mm: float | None = None
    center_distance_mm: float | None = None
    pin_diameter_mm: float | None = None
    m_value_internal_mm: tuple[float, ...] | None = None
    m_value_external_mm: tuple[float, ...] | None = None
    runout_internal_mm: float | None = None
    runout_external_mm: float | None = None
    bearing_clearance_mm: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if self.center_distance_mm is None:
            object.__setattr__(self, "center_distance_mm", self.standard_center_distance_mm)

    @property
    def pressure_angle_rad(self) -> float:
        """Reference pressure angle alpha (rad)."""
        return math.radians(self.pressure_angle_deg)

    @property
    def standard_center_distance_mm(self) -> float:
        """a0 = m (z_internal - z_external) / 2 (mm)."""
        return self.module_mm * (self.z_internal - self.z_external) / 2.0

    def pair_stiffness(self, face_width_mm: float, center_distance_mm: float) -> MeshStiffness:
        """Mesh and torsional stiffness of the pair over ``face_width_mm`` at
        ``center_distance_mm`` (mm): :func:`analysis.models.mesh_stiffness.internal_pair_stiffness`
        with this unit's teeth, module, pressure angle and addendum."""
        return internal_pair_stiffness(
            z_internal=self.z_internal,
            z_external=self.z_external,
            module_mm=self.module_mm,
            pressure_angle_rad=self.pressure_angle_rad,
            addendum_coeff=self.addendum_coeff,
            face_width_mm=face_width_mm,
            center_distance_mm=center_distance_mm,
        )

    @property
    def ring_pitch_radius_mm(self) -> float:
        """r = m z_internal / 2 (mm): the radius of seed 000 eq. (1)."""
        return self.module_mm * self.z_internal / 2.0

    @classmethod
    def from_mapping(cls, unit: Mapping[str, Any]) -> tuple[InternalPairUnit, list[str]]:
        """Build from a run.json ``unit`` mapping; return the unit and the assumptions made.

        Missing ``pressure_angle_deg``/``addendum_coeff``/``clearance_coeff``/
        ``center_distance_mm`` take documented defaults (20 deg, 1.0, 0.25, the standard center
        distance) and say so; other missing keys stay ``None`` (unknown) and are listed.
        Unknown extra keys are listed as ignored. Wrong types or values raise AnalysisError
        naming the key."""
        if not isinstance(unit, Mapping):
            raise AnalysisError(f"unit must be a JSON object, got {type(unit).__name__}")
        assumptions: list[str] = []
        kind = unit.get("kind")
        if kind is None:
            assumptions.append(f"kind missing: taken as '{KIND}'")
        elif kind != KIND:
            raise AnalysisError(f"unit key 'kind': this model needs '{KIND}', got {kind!r}")
        for key in unit:
            if key != "kind" and key not in _FIELDS:
                assumptions.append(f"unknown unit key {key!r} ignored")

        z_int = _integer(unit, "z_internal")
        z_ext = _integer(unit, "z_external")
        if z_int <= z_ext:
            raise AnalysisError(
                f"unit key 'z_internal': must exceed z_external ({z_ext}), got {z_int}"
            )
        values: dict[str, Any] = {
            "z_internal": z_int,
            "z_external": z_ext,
            "module_mm": _number(unit, "module_mm", positive=True),
        }
        defaults = {
            "pressure_angle_deg": DEFAULT_PRESSURE_ANGLE_DEG,
            "addendum_coeff": DEFAULT_ADDENDUM_COEFF,
            "clearance_coeff": DEFAULT_CLEARANCE_COEFF,
        }
        for key, default in defaults.items():
            if unit.get(key) is None:
                assumptions.append(f"{key} missing: standard {default} assumed")
                values[key] = default
            else:
                values[key] = _number(unit, key, positive=(key == "pressure_angle_deg"))
        if not 0.0 < values["pressure_angle_deg"] < 45.0:
            raise AnalysisError(
                f"unit key 'pressure_angle_deg': expected 0 < alpha < 45, "
                f"got {values['pressure_angle_deg']}"
            )
        a0 = values["module_mm"] * (z_int - z_ext) / 2.0
        if unit.get("center_distance_mm") is None:
            assumptions.append(f"center_distance_mm missing: standard {a0:g} mm assumed")
        else:
            values["center_distance_mm"] = _number(unit, "center_distance_mm", positive=True)

        optional = {
            "face_width_mm": "mesh stiffness unknown",
            "pin_diameter_mm": "M values cannot be interpreted",
            "runout_internal_mm": "runout term unknown",
            "runout_external_mm": "runout term unknown",
        }
        for key, consequence in optional.items():
            if unit.get(key) is None:
                assumptions.append(f"{key} missing: {consequence}")
            else:
                positive = key in ("face_width_mm", "pin_diameter_mm")
                values[key] = _number(unit, key, positive=positive)
        for key in ("m_value_internal_mm", "m_value_external_mm"):
            if unit.get(key) is None:
                assumptions.append(f"{key} missing: tooth thickness of that gear unknown")
            else:
                values[key] = _numbers(unit, key, positive=True)
        if unit.get("bearing_clearance_mm") is None:
            assumptions.append("bearing_clearance_mm missing: bearing term and eq. (9) unknown")
        else:
            raw = unit["bearing_clearance_mm"]
            if isinstance(raw, int | float) and not isinstance(raw, bool):
                values["bearing_clearance_mm"] = (_number(unit, "bearing_clearance_mm"),)
            else:
                values["bearing_clearance_mm"] = _numbers(unit, "bearing_clearance_mm")
        return cls(**values), assumptions

    def to_mapping(self) -> dict[str, Any]:
        """The run.json ``unit`` object of this unit (None values left out)."""
        out: dict[str, Any] = {"kind": KIND}
        for key in _FIELDS:
            value = getattr(self, key)
            if value is not None:
                out[key] = list(value) if isinstance(value, tuple) else value
        return out


_FIELDS = tuple(InternalPairUnit.__dataclass_fields__)


def _integer(unit: Mapping[str, Any], key: str) -> int:
    value = unit.get(key)
    if value is None:
        raise AnalysisError(f"unit key {key!r} missing: the model needs it")
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        raise AnalysisError(f"unit key {key!r}: expected a positive integer, got {value!r}")
    return value


def _number(unit: Mapping[str, Any], key: str, *, positive: bool = False) -> float:
    value = unit.get(key)
    if value is None:
        raise AnalysisError(f"unit key {key!r} missing: the model needs it")
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise AnalysisError(f"unit key {key!r}: expected a finite number, got {value!r}")
    if value < 0 or (positive and value == 0):
        need = "> 0" if positive else ">= 0"
        raise AnalysisError(f"unit key {key!r}: expected a number {need}, got {value!r}")
    return float(value)


def _numbers(unit: Mapping[str, Any], key: str, *, positive: bool = False) -> tuple[float, ...]:
    value = unit.get(key)
    if not isinstance(value, list | tuple) or not value:
        raise AnalysisError(
            f"unit key {key!r}: expected a non-empty list of numbers, got {value!r}"
        )
    out = []
    for i, item in enumerate(value):
        name = f"{key}[{i}]"
        if item is None:
            raise AnalysisError(f"unit key {name!r}: expected a finite number, got None")
        out.append(_number({name: item}, name, positive=positive))
    return tuple(out)
