"""The identity of a unit's design: the build geometry its ``unit`` records (run-format.md).

Two units are of one design when they are built to the same geometry: tooth counts, module,
pressure angle, addendum and clearance coefficients, face width and the center distance the
eccentric is set to (seed 000: pair 1 at 2.5 mm and pair 3 at 2.5222 mm, compensated by eq. 9,
are two builds), and for the other kinds their own design keys (:data:`BUILD_KEYS`). What is
measured on each unit (M values over pins, runouts, bearing clearances), its serial and the
names it carries (``design``, ``model``) are not part of the geometry.

:func:`design_key` is a short, stable hash of that geometry (``"g-"`` and 10 hex digits), the
same for every run of the design whatever the key order, spelling of numbers (``2.5`` and
``2.50``, ``45`` and ``45.0``) or the inspection data; None for a unit that records no build
geometry. It is derived from the ``unit`` every run.json (and campaign.json) has carried since
format version 1, so old runs get it without any new field.
"""

from __future__ import annotations

import hashlib
import json
import math
from typing import Any

DEFAULT_KIND = "internal_involute"
BUILD_KEYS: dict[str, tuple[str, ...]] = {
    "internal_involute": (
        "z_internal", "z_external", "module_mm", "pressure_angle_deg", "addendum_coeff",
        "clearance_coeff", "face_width_mm", "center_distance_mm",
    ),
    "cycloid": (
        "z_internal", "z_external", "module_mm", "height_coeff", "shape_coeff",
        "eccentricity_mm", "shift_modification_mm", "rotation_modification_mm",
        "face_width_mm",
    ),
    "beveloid": (
        "z_pinion", "z_gear", "module_mm", "pressure_angle_deg", "helix_angle_deg",
        "cone_angle_deg", "face_width_mm", "addendum_coeff", "center_distance_mm",
        "axial_shift_mm",
    ),
}
"""Per unit kind, the keys that define the build (the design data its nominal model reads)."""
NOT_GEOMETRY = ("serial", "design", "model", "pin_diameter_mm", "reference_torque_Nm")
"""Keys of a unit of another kind that are never build geometry (names, inspection tools,
analysis settings); nor is a key starting with ``runout_``, ``bearing_``, ``m_value_``."""
INSPECTION_PREFIXES = ("runout_", "bearing_", "m_value_")


def _number(value: Any) -> int | float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return value if math.isfinite(value) else None


def design_geometry(unit: Any) -> dict[str, Any]:
    """The build geometry of a ``unit`` mapping: ``kind`` and each of its kind's
    :data:`BUILD_KEYS` the unit records as a finite number (a kind not listed there: every
    finite number that is not a name, an inspection value or an analysis setting). Empty when
    the unit records none."""
    if not isinstance(unit, dict):
        return {}
    kind = unit.get("kind") or DEFAULT_KIND
    if kind in BUILD_KEYS:
        keys: tuple[str, ...] = BUILD_KEYS[kind]
    else:
        keys = tuple(sorted(k for k in unit if isinstance(k, str) and k not in NOT_GEOMETRY
                            and not k.startswith(INSPECTION_PREFIXES)))
    found = {k: _number(unit.get(k)) for k in keys}
    found = {k: v for k, v in found.items() if v is not None}
    return {"kind": str(kind), **found} if found else {}


def design_key(unit: Any) -> str | None:
    """A stable key of the unit's build geometry (:func:`design_geometry`): ``"g-"`` and the
    first 10 hex digits of the SHA-256 of its canonical JSON (numbers to 9 significant
    digits); None when the unit records no build geometry."""
    geometry = design_geometry(unit)
    if not geometry:
        return None
    canonical = {k: (v if k == "kind" else f"{float(v):.9g}") for k, v in geometry.items()}
    text = json.dumps(canonical, sort_keys=True, separators=(",", ":"))
    return "g-" + hashlib.sha256(text.encode("utf-8")).hexdigest()[:10]
