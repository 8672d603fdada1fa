"""What the gap diagnosis can tell from a campaign's design, said before anything is measured
(issue 31 item 7): which candidate effects its runs can test and, for the others, why not.

The rules are the diagnosis's own (:func:`analysis.diagnosis.design.untestable`), applied to
the plan instead of the runs: the locking positions of ``axes.positions_deg``, the housing
temperatures of ``axes.temperatures_C`` (their span; none: not varied), the unit's tooth
counts and its kind's effects without a meaning of their own. The report of the measured
campaign says the same under ``design.untestable``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from analysis.diagnosis.design import untestable
from analysis.diagnosis.fit import unit_teeth
from analysis.diagnosis.kind_physics import physics_for_unit
from rig.plans import CampaignAxes
from rig.plans.campaign_file import TE_KIND, CampaignFile


@dataclass(frozen=True)
class DesignEffects:
    """``testable``: the effects the design can test; ``untestable``: effect -> why not."""

    testable: tuple[str, ...]
    untestable: dict[str, str]

    def lines(self) -> list[str]:
        """Two lines for a terminal or the page: what it can test, what not and why."""
        cannot = "; ".join(f"{name} ({why})" for name, why in self.untestable.items())
        return [f"diagnosis: this design can test {', '.join(self.testable) or 'no effect'}",
                f"diagnosis: it cannot test {cannot}" if cannot else
                "diagnosis: it can test every candidate effect"]

    def to_dict(self) -> dict[str, object]:
        return {"testable": list(self.testable), "untestable": dict(self.untestable)}


def design_effects(camp: CampaignFile) -> DesignEffects | None:
    """What the gap diagnosis can test on ``camp``'s runs; None for a transmission-error
    campaign (its runs are not diagnosed)."""
    if camp.test == TE_KIND:
        return None
    return effects_of_design(camp.unit_data(), camp.plan.rated_torque_Nm, camp.axes)


def effects_of_design(unit: Mapping[str, Any], rated_torque_Nm: float, axes: CampaignAxes
                      ) -> DesignEffects:
    """What the gap diagnosis can test on a loop campaign of ``unit`` over ``axes`` (its
    locking positions and housing temperatures) at ``rated_torque_Nm`` (N*m)."""
    unit = dict(unit)
    physics = physics_for_unit(unit, rated_torque_Nm)
    z_input, z_mate = unit_teeth(unit, physics)
    temps = [float(t) for t in axes.temperatures_C]
    span = (max(temps) - min(temps)) if temps else None
    why = untestable([float(p) for p in axes.positions_deg], z_input, z_mate, span,
                     physics.not_testable if physics is not None else {})
    return DesignEffects(testable=tuple(n for n, w in why.items() if not w),
                         untestable={n: w for n, w in why.items() if w})
