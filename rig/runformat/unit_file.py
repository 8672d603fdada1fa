"""A unit file (``UNIT.json``, or the ``unit`` of a whole run.json) read with clear errors."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rig.core.errors import RigError, RunFormatError
from rig.core.json_files import read_json_file
from rig.runformat.meta_check import unit_problems


def load_unit_mapping(path: Path) -> dict[str, Any]:
    """The ``unit`` object from a unit file or a whole run.json (errors name file, line, col)."""
    data = read_json_file(path, RigError, "unit file")
    if isinstance(data, dict) and isinstance(data.get("unit"), dict):
        data = data["unit"]
    if not isinstance(data, dict):
        raise RunFormatError(path, "expected a JSON object (a unit or a run.json)")
    problems = unit_problems(data)
    if problems:
        raise RigError(f"{path}: {problems[0]}")
    return data
