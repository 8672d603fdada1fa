"""Campaign files opened from the control page (issue 21 item 17): the rig's own
``examples/campaigns`` listed by name, or a TOML file the operator uploads, turned into the
page's set-up (a :class:`rig.web.models.RunRequest` body) instead of retyping positions and
limits.

No path ever comes from the client: an example is looked up by its name among the files of
:func:`examples_dir` (a name not in that listing is 404), and an upload is parsed from its text.
An uploaded file's ``[unit] file`` is never opened: when its file name (without folders and
``.json``) is one of the package's example units, that unit is used; otherwise the unit keys
given inline are, and the page says so.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from rig.core.toml_files import MAX_TOML_BYTES, describe_validation_error
from rig.plans.campaign_file import CampaignError, CampaignFile, load_campaign
from rig.web.models import (
    NAME_PATTERN,
    UNIT_MODELS,
    AxesSettings,
    LimitSettings,
    PlanSettings,
    RunRequest,
    UnitData,
)
from rig.web.simulated import example_unit, example_unit_names

_NAME = re.compile(NAME_PATTERN)
_TOML_POSITION = re.compile(r"\(at line (\d+), column (\d+)\)")


def examples_dir() -> Path:
    """The rig's example campaigns: ``examples/campaigns`` beside the ``rig`` package (a
    source checkout or an editable install; absent in a wheel, then the list is empty)."""
    return Path(__file__).resolve().parents[2] / "examples" / "campaigns"


def example_names() -> list[str]:
    """Names (file names without ``.toml``) of the example campaigns, sorted."""
    folder = examples_dir()
    if not folder.is_dir():
        return []
    return sorted(p.stem for p in folder.glob("*.toml")
                  if p.is_file() and _NAME.fullmatch(p.stem))


def example_list() -> list[dict[str, str]]:
    """Each example's name and description (its first line's description key)."""
    out = []
    for name in example_names():
        try:
            data = tomllib.loads((examples_dir() / f"{name}.toml").read_text(encoding="utf-8"))
            description = str(data.get("description", ""))
        except (OSError, ValueError):
            description = ""
        out.append({"name": name, "description": description})
    return out


def example_setup(name: str) -> dict[str, Any] | None:
    """The set-up of example ``name`` (None: no such example; CampaignError: it is broken)."""
    if name not in example_names():
        return None
    camp = load_campaign(examples_dir() / f"{name}.toml")
    return setup_of(camp, camp.unit_data(), f"{name}.toml", [])


def display_name(file_name: str) -> str:
    """An uploaded file's name as shown in messages: its last part, at most 100 characters
    (a name, never used as a path)."""
    base = file_name.replace("\\", "/").rsplit("/", 1)[-1].strip()
    return (base or "uploaded file")[:100]


def upload_setup(file_name: str, text: str) -> dict[str, Any]:
    """The set-up of an uploaded campaign file's text; CampaignError naming the file (and
    line and column for a TOML syntax error, the key for a bad value)."""
    source = display_name(file_name)
    if len(text.encode("utf-8")) > MAX_TOML_BYTES:
        raise CampaignError(f"{source}: larger than {MAX_TOML_BYTES} bytes: not a campaign file")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        match = _TOML_POSITION.search(str(exc))
        where = f"{source}:{match.group(1)}:{match.group(2)}" if match else source
        raise CampaignError(f"{where}: TOML syntax error: "
                            f"{_TOML_POSITION.sub('', str(exc)).strip()}") from None
    except RecursionError:
        raise CampaignError(f"{source}: TOML nested too deeply") from None
    notes: list[str] = []
    unit = data.get("unit")
    base: dict[str, Any] = {}
    if isinstance(unit, dict) and "file" in unit:
        unit = dict(unit)
        named = str(unit.pop("file"))
        stem = display_name(named).removesuffix(".json")
        if stem in example_unit_names():
            base = example_unit(stem)
            notes.append(f"unit.file {display_name(named)}: the rig's example unit {stem}")
        else:
            notes.append(f"unit.file {display_name(named)} is not read from an uploaded file "
                         "(only the rig's example units are): the unit's inline keys are used")
        data = {**data, "unit": unit}
    try:
        camp = CampaignFile.model_validate({**data, "source": "<memory>"})
    except ValidationError as exc:
        raise CampaignError(describe_validation_error(exc, source).splitlines()[0]) from None
    try:
        unit_data = {**base, **camp.unit_data()} if base else camp.unit_data()
    except CampaignError:
        unit_data = None
    return setup_of(camp, unit_data, source, notes)


def setup_of(camp: CampaignFile, unit: dict[str, Any] | None, source: str,
             notes: list[str]) -> dict[str, Any]:
    """The page's set-up of a campaign: a RunRequest body (``request``; its ``unit`` None
    when unknown), with ``notes`` on what the page does not take over."""
    plan = camp.plan.model_dump()
    page_plan = {k: v for k, v in plan.items() if k in PlanSettings.model_fields}
    defaults = type(camp.plan)(rated_torque_Nm=camp.plan.rated_torque_Nm).model_dump()
    for key, value in plan.items():
        if key not in PlanSettings.model_fields and value != defaults.get(key):
            notes.append(f"plan.{key} = {value} is not set from the page (its default is used)")
    if camp.simulation.plant or camp.simulation.seed is not None:
        notes.append("[simulation] is not taken over: the page's simulated rig keeps its plant")
    axes = camp.axes.model_dump()
    page_axes = {k: v for k, v in axes.items() if k in AxesSettings.model_fields}
    request: dict[str, Any] = {
        "kind": "campaign", "name": camp.name[:80], "plan": page_plan, "axes": page_axes,
        "limits": {k: v for k, v in camp.limits.model_dump().items()
                   if k in LimitSettings.model_fields},
        "profile": camp.profile if camp.profile in ("nabtesco", "harmonic-drive", "gbt",
                                                     "spinea") else "nabtesco",
        "torque_limit_Nm": camp.torque_limit_Nm, "operator": camp.operator or None,
        "calibration_override": camp.calibration_override,
        "unit": unit,
        "test": camp.test,
        "confirm_long": camp.confirm_long,
    }
    if camp.test == "transmission_error":
        te = camp.te.model_dump()
        request["te"] = {k: te[k] for k in ("input_speed_rpm", "brake_torque_fraction",
                                             "output_revolutions", "ratio")}
        request["axes"] = {"repeats": camp.axes.repeats,
                           "temperatures_C": list(camp.axes.temperatures_C)}
        if te["directions"] != ["forward", "reverse"]:
            notes.append(f"te.directions = {te['directions']} is not set from the page (both "
                         "directions are turned)")
    # the unit as the page takes it: the keys of its kind's form (rig/web/models.py)
    unit_model = None if unit is None else UNIT_MODELS.get(
        str(unit.get("kind", "internal_involute")))
    page_unit = None if unit is None or unit_model is None else {
        k: v for k, v in unit.items() if k in unit_model.model_fields}
    if page_unit is None:
        request["unit"] = None
    else:
        try:
            unit_model.model_validate(page_unit)  # type: ignore[union-attr]
        except ValidationError:
            page_unit = request["unit"] = None  # the page says so and keeps its unit
    # what the page would send, checked now and said in words (a stand-in unit when the file
    # gives none: the plan, axes and limits are checked all the same)
    body = {k: v for k, v in request.items() if v is not None}
    body["unit"] = page_unit or UnitData(z_internal=45, z_external=40, module_mm=1.0).mapping()
    try:
        RunRequest.model_validate(body)
    except ValidationError as exc:
        raise CampaignError(describe_validation_error(exc, source).splitlines()[0]) from None
    return {"source": source, "name": camp.name, "description": camp.description,
            "request": request, "notes": notes}
