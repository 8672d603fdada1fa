"""The ``rig batch`` report (rig-batch/1): lost motion of a production batch built to a seed
000 design (arcmin, at its worst and at a random eccentric-shaft position)."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def batch_report(unit_file: Path, *, samples: int, seed: int, compensate: bool,
                 rated_torque_Nm: float, lost_motion_pct: float) -> dict[str, Any]:
    """Seed 003's Monte Carlo of ``samples`` units within seed 000 Table 1's tolerances,
    built to the unit of ``unit_file`` (a unit JSON or a whole run.json); ``compensate``: each
    unit's eccentric distance set by seed 000 eq. (9); lost motion at ``lost_motion_pct`` % of
    ``rated_torque_Nm`` (N*m)."""
    from analysis.models.seed000_batch import lost_motion_batch
    from analysis.models.seed000_unit import InternalPairUnit
    from rig.runformat.unit_file import load_unit_mapping

    unit, _ = InternalPairUnit.from_mapping(load_unit_mapping(unit_file))
    result = lost_motion_batch(unit, samples=samples, seed=seed, compensate=compensate,
                               rated_torque_Nm=rated_torque_Nm,
                               lost_motion_pct=lost_motion_pct)
    return {"format": "rig-batch/1", "unit_file": str(unit_file), "compensated": compensate,
            **result.to_dict()}
