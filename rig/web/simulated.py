"""The simulated rig behind ``rig serve --simulated``: the plant built around an example unit
(rig/examples/units) with the effects of examples/campaigns/seed000-pair1.toml, or a plant TOML
(``--plant``: simulators/cycloid_plant.toml ...), started as its own process (``rig sim``) by
:func:`rig.measurement.service.open_session`."""

from __future__ import annotations

import json
from collections.abc import Callable
from contextlib import AbstractContextManager
from importlib import resources
from typing import Any

from rig.core.errors import RigError

SIMULATED_EFFECTS: dict[str, Any] = {"effects": {
    "runout": {"enabled": True},
    "friction": {"enabled": True, "model": "lugre", "coulomb_torque_Nm": 0.02,
                 "static_torque_Nm": 0.03, "viscous_Nms_per_arcmin": 0.002},
}}
"""The plant around the unit (docs/plant.md): the unit's runout (seed 000 eq. 4, sized by
``unit.runout_*_mm``) and a little seal and oil drag, noise seed 1."""
DEFAULT_UNIT = "seed000-pair1"


def example_unit_names() -> list[str]:
    folder = resources.files("rig.examples") / "units"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".json"))


def example_unit(name: str) -> dict[str, Any]:
    """An example unit of the package by name (``seed000-pair1`` ...); RigError if unknown."""
    names = example_unit_names()
    if name not in names:
        raise RigError(f"--unit {name!r}: no such example unit; known: {', '.join(names)}")
    folder = resources.files("rig.examples") / "units"
    return json.loads((folder / f"{name}.json").read_text(encoding="utf-8"))


def example_plant(unit_name: str = DEFAULT_UNIT) -> Any:
    """The simulated plant around the example unit ``unit_name``: the default plant with
    :data:`SIMULATED_EFFECTS`, the runout left off for a unit that gives no runouts (the
    cycloid and beveloid examples)."""
    return unit_plant(example_unit(unit_name))


def unit_plant(unit: dict[str, Any]) -> Any:
    """The simulated plant around ``unit`` (a run.json ``unit`` of any kind): the default
    plant with :data:`SIMULATED_EFFECTS`, the runout left off when the unit gives no
    runouts; a planetary unit with the errors of the example train (:func:`planetary_as_made`)."""
    from rig.measurement.service import plant_config_for
    from rig.plans.campaign_file import SimulationSection

    effects = dict(SIMULATED_EFFECTS["effects"])
    if not all(isinstance(unit.get(k), int | float) for k in ("runout_internal_mm",
                                                               "runout_external_mm")):
        effects.pop("runout")
    tables: dict[str, Any] = {"effects": effects}
    if unit.get("kind") == "planetary":
        tables["planetary"] = planetary_as_made()
    return plant_config_for(unit, SimulationSection(seed=1, plant=tables))


def planetary_as_made() -> dict[str, Any]:
    """A planetary unit's errors as made (the plant's ``[planetary]`` table, not unit data):
    those of simulators/planetary_plant.toml, seed 003's train drawn inside its tolerances.
    Without them the simulated train has no errors and its TE is noise only."""
    from simulators.plant.config import DEFAULT_PLANT_TOML, load_plant_config

    example = load_plant_config(DEFAULT_PLANT_TOML.parent / "planetary_plant.toml")
    return example.planetary.model_dump()


def simulated_session_factory(unit_name: str = DEFAULT_UNIT
                              ) -> Callable[[], AbstractContextManager[Any]]:
    """A factory of rig sessions on a new simulated rig whose plant is ``unit_name``'s
    (:func:`example_plant`)."""
    from rig.measurement.service import open_session

    plant = example_plant(unit_name)

    def factory() -> AbstractContextManager[Any]:
        return open_session(simulated=True, plant=plant)

    return factory


def unit_session_factory(unit: dict[str, Any]) -> AbstractContextManager[Any]:
    """A rig session on a new simulated rig whose plant is ``unit``'s (:func:`unit_plant`):
    how the page's simulated rig is started again for a unit of another kind than its plant
    (:class:`rig.web.controller.RigController`, issue 33 item 10)."""
    from rig.measurement.service import open_session

    return open_session(simulated=True, plant=unit_plant(unit))


def simulated_plant(path: str) -> Any:
    """The plant of a plant TOML (``rig sim --config`` FILE: simulators/cycloid_plant.toml,
    beveloid_plant.toml, default_plant.toml ...); RigError naming the file and what is wrong."""
    from simulators.plant.config import PlantConfigError, load_plant_config

    try:
        return load_plant_config(path)
    except PlantConfigError as exc:
        raise RigError(f"--plant: {exc}") from exc


def plant_session_factory(path: str) -> Callable[[], AbstractContextManager[Any]]:
    """A factory of rig sessions on a new simulated rig running the plant TOML ``path``
    (its unit of any kind, its effects, noise and rig tables as the file says)."""
    from rig.measurement.service import open_session

    plant = simulated_plant(path)

    def factory() -> AbstractContextManager[Any]:
        return open_session(simulated=True, plant=plant)

    return factory
