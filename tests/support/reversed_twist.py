"""A run whose output encoder counts the other way round: the bundled example run
``pair1-pos000`` with its twist's sign flipped, so every loop figure comes out below zero
(lost motion about -5.19 arcmin, stiffness about -27.8 N·m/arcmin, a negative loop area)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rig.examples import RUNS_DIR
from rig.runformat import Run, read_run, write_run

LIMITS = {"lost_motion_arcmin_max": 6.0, "backlash_arcmin_max": 6.0}
"""Limits every figure of the flipped run would meet if it were taken as a measurement."""


def reversed_twist_run(limits: dict[str, Any] | None = None) -> Run:
    """``pair1-pos000`` with ``output_angle_deg`` negated and ``limits`` in its run.json."""
    run = read_run(RUNS_DIR / "pair1-pos000")
    run.data["output_angle_deg"] = -run.data["output_angle_deg"]
    run.meta["limits"] = dict(LIMITS if limits is None else limits)
    return run


def write_reversed_twist_run(folder: Path) -> Path:
    """The flipped run as a rig-run/1 folder at ``folder`` (no result recorded)."""
    write_run(reversed_twist_run(), folder)
    return folder


def store_reversed_twist_run(store_root: Path) -> str:
    """The flipped run imported into the store at ``store_root`` (analysed, its outcome
    recorded, as ``rig import --into`` does); its run id."""
    from rig.io.importer import store_imported

    return store_imported(reversed_twist_run(), store_root)
