"""Validation of a run's metadata on read: every number the analysis uses is a finite real
number of the right sign, and the unit names its kind.

Outside-probe rows 3a, 3c and 3h of issue 12: ``test.rated_torque_Nm = {}`` gave a
``TypeError`` traceback, ``sensors.encoder_counts_per_rev = NaN`` reached the JSON output,
and ``unit.kind = null`` was analysed with an assumed kind. Each is now refused in one line
naming the file and the key (``run.json: test.rated_torque_Nm: ...``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from analysis.models.by_kind import KINDS

__all__ = ["NUMERIC_KEYS", "meta_problems", "unit_problems"]

NUMERIC_KEYS: dict[tuple[str, str], str] = {
    ("test", "rated_torque_Nm"): "positive",
    ("test", "ratio"): "nonzero",
    ("test", "amplitude_pct"): "positive",
    ("test", "amplitude_Nm"): "positive",
    ("test", "input_angle_deg"): "finite",
    ("test", "lost_motion_pct"): "positive",
    ("test", "hd_T1_Nm"): "positive",
    ("test", "hd_T2_Nm"): "positive",
    ("sensors", "encoder_counts_per_rev"): "positive",
    ("sensors", "torque_full_scale_Nm"): "positive",
    ("sensors", "torque_resolution_Nm"): "nonnegative",
}
"""Keys whose value, when present and not null, must be a number (dotted key -> its sign)."""

_RULES = {
    "finite": (lambda v: True, "a finite number"),
    "positive": (lambda v: v > 0, "a number above 0"),
    "nonnegative": (lambda v: v >= 0, "a number of at least 0"),
    "nonzero": (lambda v: v != 0, "a number other than 0"),
}


def _number_problem(value: Any, rule: str) -> str | None:
    ok, words = _RULES[rule]
    if isinstance(value, bool) or not isinstance(value, int | float):
        return f"must be {words}, got {value!r}"
    if not math.isfinite(value) or not ok(value):
        return f"must be {words}, got {value!r}"
    return None


def unit_problems(unit: Any, where: str = "unit") -> list[str]:
    """What is wrong with a ``unit`` mapping as a whole (its design keys are checked by the
    models): it must be an object, and ``kind``, when given, a name (a kind without a model,
    such as another maker's, is analysed without one; null is no kind at all)."""
    if not isinstance(unit, Mapping):
        return [f"{where}: must be a JSON object, got {type(unit).__name__}"]
    if "kind" in unit and not (isinstance(unit["kind"], str) and unit["kind"].strip()):
        return [f"{where}.kind: the kind decides the model; must be one of "
                f"{', '.join(KINDS)} (or left out for internal_involute), got {unit['kind']!r}"]
    return []


def meta_problems(meta: Mapping[str, Any]) -> list[str]:
    """Every problem of a run.json's ``test``, ``sensors`` and ``unit`` objects, one line each
    (``dotted.key: what it must be, got what``); empty when the metadata can be analysed."""
    problems: list[str] = []
    for section in ("test", "sensors", "unit"):
        value = meta.get(section)
        if value is not None and not isinstance(value, Mapping):
            problems.append(f"{section}: must be a JSON object, got {type(value).__name__}")
    for (section, key), rule in NUMERIC_KEYS.items():
        block = meta.get(section)
        if not isinstance(block, Mapping) or block.get(key) is None:
            continue
        problem = _number_problem(block[key], rule)
        if problem:
            problems.append(f"{section}.{key}: {problem}")
    if isinstance(meta.get("unit"), Mapping):
        problems.extend(unit_problems(meta["unit"]))
    return problems
