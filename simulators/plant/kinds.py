"""The plant geometry of each unit kind: :func:`geometry_for` picks it from ``unit.kind``.

Kept apart from :mod:`simulators.plant.geometry` (the seed 000 internal involute pair, the base
of every kind) so that the kinds import the base and this module imports the kinds: no cycle.
"""

from __future__ import annotations

from collections.abc import Mapping

from simulators.plant.beveloid import BeveloidGeometry
from simulators.plant.cycloid import CycloidGeometry
from simulators.plant.geometry import MeshGeometry, UnitAndEffects
from simulators.plant.planetary import PlanetaryGeometry


def geometry_for(config: UnitAndEffects) -> MeshGeometry:
    """The plant geometry of the unit's ``kind`` (run-format.md ``unit.kind``):
    ``internal_involute`` (default, seed 000), ``cycloid`` (seed 002), ``beveloid`` (seed 001),
    ``planetary`` (seed 003).
    Raises ValueError naming the key."""
    unit = config.unit
    kind = unit.get("kind", "internal_involute") if isinstance(unit, Mapping) else None
    if kind == "cycloid":
        return CycloidGeometry.from_config(config)
    if kind == "beveloid":
        return BeveloidGeometry.from_config(config)
    if kind == "planetary":
        return PlanetaryGeometry.from_config(config)
    if kind not in (None, "internal_involute"):
        raise ValueError(f"key unit.kind: {kind!r} has no plant (known: internal_involute, "
                         "cycloid, beveloid, planetary)")
    return MeshGeometry.from_config(config)
