"""The import map: how another lab's file becomes a rig-run/1 run (``rig import --map``).

A map is a TOML file (docs/import-export.md): the file's format (delimited text or NI TDMS),
its delimiter and decimal mark, which file column (or TDMS channel) holds which run column in
which unit, and the run.json ``test`` (and ``sensors``) keys the file cannot carry. It is
validated strictly: an unknown key or a bad value is a one-line error naming the map file
and the dotted key.

Units convert to the run's own: time to s, torque to N·m, angles to deg, temperature to °C.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

from rig.core.errors import RigError
from rig.core.ids import id_problem
from rig.core.ranges import (
    POSITION_DEG,
    RATED_TORQUE_NM,
    TEMPERATURE_READING_C,
    TORQUE_LIMIT_NM,
)
from rig.core.toml_files import describe_validation_error, read_toml
from rig.runformat.meta_check import meta_problems

__all__ = [
    "ABSOLUTE_ZERO_C", "COLUMN_KINDS", "RUN_UNITS", "TORQUE_MAX_NM", "UNITS", "ColumnRef",
    "ImportMap", "RunImportError", "convert_unit", "known_unit", "load_map", "resolve_unit",
    "same_unit",
]


class RunImportError(RigError):
    """A map, a unit file or a source file that cannot be imported (one line, exit 2)."""


def _scale(factor: float) -> Callable[[np.ndarray], np.ndarray]:
    return lambda x: x * factor


def _divide(divisor: float) -> Callable[[np.ndarray], np.ndarray]:
    return lambda x: x / divisor


def _same(x: np.ndarray) -> np.ndarray:
    return x


UNITS: dict[str, dict[str, Callable[[np.ndarray], np.ndarray]]] = {
    "time": {"s": _same, "ms": _divide(1e3), "us": _divide(1e6), "µs": _divide(1e6)},
    "torque": {
        "N*m": _same, "N·m": _same, "Nm": _same, "N.m": _same,
        "kN*m": _scale(1e3), "kN·m": _scale(1e3), "kNm": _scale(1e3), "kN.m": _scale(1e3),
    },
    "angle": {
        "deg": _same, "°": _same, "arcmin": _divide(60.0), "arcsec": _divide(3600.0),
        "rad": np.rad2deg,
    },
    "temperature": {"C": _same, "°C": _same, "degC": _same, "K": lambda x: x - 273.15},
}
"""Accepted units by kind, each with its conversion to the run's unit (s, N·m, deg, °C)."""

COLUMN_KINDS = {
    "t_s": "time",
    "torque_Nm": "torque",
    "output_angle_deg": "angle",
    "input_angle_deg": "angle",
    "temperature_C": "temperature",
}
"""The run columns a map can fill, and the kind of unit each takes."""


RUN_UNITS = {"time": "s", "torque": "N*m", "angle": "deg", "temperature": "C"}
"""The run's own unit of each kind (a column the map and the file give no unit for)."""


def convert_unit(values: np.ndarray, kind: str, unit: str | None) -> np.ndarray:
    """``values`` in ``unit`` (None: already the run's unit) as float64 in the run's unit."""
    values = np.asarray(values, dtype=np.float64)
    return values if unit is None else np.asarray(UNITS[kind][unit](values), dtype=np.float64)


def known_unit(text: str) -> tuple[str, str] | None:
    """(kind, the name :data:`UNITS` knows) of a unit as a file writes it: spaces ignored
    (``N m``, ``deg C``), case too where that leaves one unit (``Deg``, ``NM``); None when it
    is no unit rig knows."""
    compact = "".join(text.split())
    names = [(kind, name) for kind, units in UNITS.items() for name in units]
    exact = [kn for kn in names if kn[1] == compact]
    if exact:
        return exact[0]
    folded = [kn for kn in names if kn[1].lower() == compact.lower()]
    return folded[0] if len(folded) == 1 else None


def same_unit(kind: str, a: str, b: str) -> bool:
    """Do two units of ``kind`` convert alike (``N*m`` and ``Nm``; ``C`` and ``°C``)?"""
    probe = np.array([1.0, 7.5, -300.0])
    return bool(np.array_equal(UNITS[kind][a](probe), UNITS[kind][b](probe)))


def resolve_unit(kind: str, map_unit: str | None, file_unit: str | None,
                 where: str) -> str | None:
    """The unit a column's values are in: the map's, else the file's own (a catman
    header's ``[kN*m]``, a TDMS ``unit_string``), else the run's (None). A file unit that
    is another kind's, or that differs from the map's, is refused (``where`` names the
    column); a file unit rig does not know needs the map to say what it is."""
    if file_unit is None:
        return map_unit
    known = known_unit(file_unit)
    if known is None:
        if map_unit is None:
            raise RunImportError(f"{where}: the file gives the unit {file_unit!r}, which is not "
                                 f"a unit of {kind} rig knows ({', '.join(UNITS[kind])}); "
                                 "give the column's unit in the map")
        return map_unit
    file_kind, name = known
    if file_kind != kind:
        raise RunImportError(f"{where}: the file gives the unit {file_unit!r}, a unit of "
                             f"{file_kind}, not of {kind}; is the column mapped to the right "
                             "run column?")
    if map_unit is not None and not same_unit(kind, map_unit, name):
        raise RunImportError(f"{where}: the map says unit {map_unit!r} but the file says "
                             f"{file_unit!r}; remove the map's unit or correct it")
    return map_unit if map_unit is not None else name


_STRICT = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


class ColumnRef(BaseModel):
    """One mapped column: the file's column header (a TDMS channel name) and its unit."""

    model_config = _STRICT
    column: str = Field(min_length=1)
    unit: str | None = None


class Columns(BaseModel):
    """``[columns]``: run column -> file column, as ``"Header"`` or ``{column, unit}``."""

    model_config = _STRICT
    t_s: ColumnRef | None = None
    torque_Nm: ColumnRef
    output_angle_deg: ColumnRef
    input_angle_deg: ColumnRef | None = None
    temperature_C: ColumnRef | None = None

    @field_validator("*", mode="before")
    @classmethod
    def _ref(cls, value: Any) -> Any:
        return {"column": value} if isinstance(value, str) else value

    @model_validator(mode="after")
    def _distinct(self) -> Columns:
        seen: dict[str, str] = {}
        for name in COLUMN_KINDS:
            ref = getattr(self, name)
            if ref is None:
                continue
            if ref.column in seen:
                raise ValueError(f"{seen[ref.column]} and {name} both map to {ref.column!r}; "
                                 "each run column needs its own file column")
            seen[ref.column] = name
        return self

    @field_validator("*", mode="after")
    @classmethod
    def _unit(cls, ref: ColumnRef | None, info: ValidationInfo) -> ColumnRef | None:
        kind = COLUMN_KINDS[str(info.field_name)]
        if ref is not None and ref.unit is not None and ref.unit not in UNITS[kind]:
            raise ValueError(f"unit {ref.unit!r} is not a unit of {kind}; use one of "
                             f"{', '.join(UNITS[kind])}")
        return ref


TORQUE_MAX_NM = RATED_TORQUE_NM.high
"""A rated torque (N·m) above this is no gear reducer's (the largest wind-turbine gearboxes
carry a few MN·m): a typo or a unit mistake, refused (:mod:`rig.core.ranges`)."""
ABSOLUTE_ZERO_C = -273.15
"""No temperature (°C) is below it."""

KNOWN_TEST_KEYS = ("rated_torque_Nm", "input_angle_deg", "temperature_C", "cycles",
                   "start_flank", "amplitude_pct", "amplitude_Nm", "ratio", "repeat",
                   "lost_motion_pct", "hd_T1_Nm", "hd_T2_Nm")


class Test(BaseModel):
    """``[test]``: run.json ``test`` keys. ``rated_torque_Nm`` is required; other keys are
    kept as given unless they look like a misspelt known key."""

    model_config = ConfigDict(extra="allow", strict=True, allow_inf_nan=False)
    rated_torque_Nm: float = Field(gt=0, le=TORQUE_MAX_NM)
    input_angle_deg: POSITION_DEG.type | None = None
    temperature_C: TEMPERATURE_READING_C.after(Field(ge=ABSOLUTE_ZERO_C)) | None = None
    amplitude_Nm: TORQUE_LIMIT_NM.type | None = None
    cycles: int | None = Field(default=None, ge=1)
    start_flank: Literal[-1, 1] | None = None
    amplitude_pct: float | None = Field(default=None, gt=0)
    repeat: int | None = Field(default=None, ge=0)

    @model_validator(mode="before")
    @classmethod
    def _no_misspelt_keys(cls, data: Any) -> Any:
        if isinstance(data, dict):
            for key in data:
                if key in KNOWN_TEST_KEYS:
                    continue
                near = [k for k in KNOWN_TEST_KEYS if k.lower() == str(key).lower()]
                near = near or difflib.get_close_matches(str(key), KNOWN_TEST_KEYS, 1, 0.85)
                if near:
                    raise ValueError(f"{key}: unknown key; did you mean {near[0]!r}?")
        return data


class ImportMap(BaseModel):
    """The whole map file (see the module doc and docs/import-export.md)."""

    model_config = _STRICT
    format: Literal["csv", "tdms"] | None = None
    delimiter: str = Field(default=",", min_length=1, max_length=1)
    decimal: Literal[".", ","] = "."
    skip_rows: int = Field(default=0, ge=0)
    encoding: str = "utf-8"
    group: str | None = None
    run_id: str | None = None
    columns: Columns
    test: Test
    sensors: dict[str, Any] = Field(default_factory=dict)

    @field_validator("run_id")
    @classmethod
    def _run_id(cls, value: str | None) -> str | None:
        problem = None if value is None else id_problem(value, "run")
        if problem is not None:
            raise ValueError(problem)
        return value

    @model_validator(mode="after")
    def _marks(self) -> ImportMap:
        if self.delimiter == self.decimal:
            raise ValueError(f"delimiter and decimal are both {self.delimiter!r}")
        return self

    def file_format(self, source: Path) -> str:
        """"csv" or "tdms": the map's ``format``, else by the file's extension."""
        if self.format is not None:
            return self.format
        return "tdms" if source.suffix.lower() == ".tdms" else "csv"

    def test_meta(self) -> dict[str, Any]:
        """The run.json ``test`` object: the keys the map gives, in its order."""
        return self.test.model_dump(exclude_unset=True)


def load_map(path: str | Path) -> ImportMap:
    """Read and validate a map file; :class:`RunImportError` naming the file and key."""
    file = Path(path)
    data = read_toml(file, RunImportError, "import map")
    try:
        mapping = ImportMap.model_validate(data)
    except ValidationError as exc:
        first = describe_validation_error(exc, str(file)).splitlines()[0]
        raise RunImportError(first) from None
    problems = meta_problems({"test": mapping.test_meta(), "sensors": mapping.sensors})
    if problems:
        raise RunImportError(f"{file}: {problems[0]}")
    return mapping
