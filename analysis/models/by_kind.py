"""The nominal loop model of a unit, chosen by its ``kind`` (run-format.md ``unit.kind``).

- ``internal_involute`` (the default): the reference nominal model pinned in run-format.md
  (seed 000 eqs. 1-3 free play, seed 004 eq. 8 stiffness), :mod:`analysis.models.nominal`;
- ``cycloid``: the seed 002 compound cycloid pair, :mod:`analysis.models.cycloid_nominal`;
- ``beveloid``: the seed 001 beveloid pair, :mod:`analysis.models.beveloid_nominal`.

Every model offers ``play_arcmin``, ``stiffness_Nm_per_arcmin``, ``backlash_arcmin``,
``twist_arcmin(torque_Nm, start_flank)`` and ``lost_motion_arcmin(rated_torque_Nm, pct)``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol

import numpy as np

from analysis.errors import AnalysisError

KINDS = ("internal_involute", "cycloid", "beveloid")

MODEL_NAMES = {
    "internal_involute": ("seed 000 reference nominal model, no runout",
                          "seed 000 Table 1 tolerances"),
    "cycloid": ("seed 002 compound cycloid pair, mean over the mesh phases",
                "seed 002 modification budget"),
    "beveloid": ("seed 001 beveloid pair, closed-form backlash",
                 "seed 001 installation error budget"),
}
"""Per unit kind: the nominal model's name and the tolerances its batch band is drawn from
(what the page and the certificate print beside them)."""


class LoopModel(Protocol):
    """What a nominal loop model offers (units: arcmin at the output, N*m)."""

    play_arcmin: float
    stiffness_Nm_per_arcmin: float

    @property
    def backlash_arcmin(self) -> float: ...

    def twist_arcmin(self, torque_Nm: np.ndarray, start_flank: int = -1) -> np.ndarray: ...

    def lost_motion_arcmin(self, rated_torque_Nm: float, pct: float) -> float: ...


def nominal_model_for_unit(
    unit: Mapping[str, Any], rated_torque_Nm: float | None = None
) -> tuple[LoopModel, list[str]]:
    """The nominal model of ``unit`` and the assumptions made; AnalysisError when the unit's
    data cannot give one (the message names the missing or bad key, or the unknown kind)."""
    kind = unit.get("kind", "internal_involute")
    if kind == "internal_involute":
        from analysis.models.nominal import reference_nominal_model
        from analysis.models.seed000_unit import InternalPairUnit

        parsed, assumptions = InternalPairUnit.from_mapping(unit)
        return reference_nominal_model(parsed), list(assumptions)
    if kind == "cycloid":
        from analysis.models.cycloid_nominal import cycloid_nominal_model

        model, assumptions = cycloid_nominal_model(unit, reference_torque_Nm=rated_torque_Nm)
        return model, list(assumptions)
    if kind == "beveloid":
        from analysis.models.beveloid_nominal import beveloid_nominal_model

        model, assumptions = beveloid_nominal_model(unit)
        return model, list(assumptions)
    raise AnalysisError(f"unit kind {kind!r} has no nominal model (known: {', '.join(KINDS)})")
