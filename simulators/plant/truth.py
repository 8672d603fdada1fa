"""What the simulated plant injected and the loop it holds: a run's ``generator`` block.

Every campaign run measured on the simulated rig, and every run generated offline, can carry
this block in its run.json (``generator``): the unit's kind, every value injected (the
switchable effects switched on, with all their parameters, and the kind's own deviations:
``[cycloid]`` modification and eccentricity errors, ``[beveloid]`` installation errors of
seed 001 eq. 8, ``[planetary]`` seed 003 error values and phases), and the plant's
quasi-static truth at the run's lock angle and housing temperature
(:meth:`simulators.plant.GearPlant.true_parameters`, ``true_lost_motion_arcmin``). Angles
arcmin, torques N*m.
"""

from __future__ import annotations

import math
from typing import Any

from simulators.clock import ManualClock
from simulators.plant import GearPlant
from simulators.plant.config import PlantConfig

_KIND_SECTIONS = {"cycloid": "cycloid", "beveloid": "beveloid", "planetary": "planetary"}


def injected_values(config: PlantConfig) -> dict[str, Any]:
    """Every injected value: ``effects`` (each effect switched on, all its parameters) and the
    kind's deviations that differ from the design (``cycloid`` / ``beveloid`` tables)."""
    fx = config.effects
    out: dict[str, Any] = {"effects": {name: getattr(fx, name).model_dump(exclude={"enabled"})
                                       for name in fx.enabled_names()}}
    kind = config.unit.get("kind", "internal_involute")
    section = _KIND_SECTIONS.get(kind)
    if section is not None:
        table = getattr(config, section).model_dump()
        defaults = type(getattr(config, section))()
        out[section] = {k: v for k, v in table.items() if v != getattr(defaults, k)}
    return out


def _finite(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def generator_block(config: PlantConfig, *, input_angle_deg: float = 0.0,
                    temperature_C: float | None = None, rated_torque_Nm: float | None = None,
                    pct: float = 3.0) -> dict[str, Any]:
    """The ``generator`` block of a run of ``config``'s plant locked at ``input_angle_deg``
    (deg), housing at ``temperature_C`` (None: the config's), with the true lost motion at
    ``+-pct`` % of ``rated_torque_Nm`` when given. JSON-safe (non-finite numbers as None)."""
    changes: dict[str, Any] = {"rig": {"initial_input_angle_deg": float(input_angle_deg)}}
    if temperature_C is not None:
        changes["housing"] = {"initial_C": float(temperature_C),
                              "ambient_C": float(temperature_C)}
    plant = GearPlant(config.with_changes(**changes), clock=ManualClock())
    truth = plant.true_parameters()
    block: dict[str, Any] = {
        "what": "simulators.plant (simulated, not a measurement)",
        "kind": config.unit.get("kind", "internal_involute"),
        "injected": injected_values(config),
        "input_angle_deg": float(input_angle_deg),
        "truth": truth,
        "true_play_arcmin": truth["play_arcmin"],
        "true_stiffness_Nm_per_arcmin": truth["stiffness_Nm_per_arcmin"],
    }
    if rated_torque_Nm:
        block["true_lost_motion_arcmin"] = plant.true_lost_motion_arcmin(
            float(rated_torque_Nm), pct)
        block["lost_motion_pct"] = pct
        block["rated_torque_Nm"] = float(rated_torque_Nm)
    return _finite(block)
