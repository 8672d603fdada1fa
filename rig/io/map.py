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

from rig.errors import RigError
from rig.run_meta_check import meta_problems
from rig.toml_files import describe_validation_error, read_toml

__all__ = [
    "COLUMN_KINDS", "UNITS", "ColumnRef", "ImportMap", "RunImportError", "convert_unit",
    "load_map",
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


def convert_unit(values: np.ndarray, kind: str, unit: str | None) -> np.ndarray:
    """``values`` in ``unit`` (None: already the run's unit) as float64 in the run's unit."""
    values = np.asarray(values, dtype=np.float64)
    return values if unit is None else np.asarray(UNITS[kind][unit](values), dtype=np.float64)


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

    @field_validator("*", mode="after")
    @classmethod
    def _unit(cls, ref: ColumnRef | None, info: ValidationInfo) -> ColumnRef | None:
        kind = COLUMN_KINDS[str(info.field_name)]
        if ref is not None and ref.unit is not None and ref.unit not in UNITS[kind]:
            raise ValueError(f"unit {ref.unit!r} is not a unit of {kind}; use one of "
                             f"{', '.join(UNITS[kind])}")
        return ref


KNOWN_TEST_KEYS = ("rated_torque_Nm", "input_angle_deg", "temperature_C", "cycles",
                   "start_flank", "amplitude_pct", "amplitude_Nm", "ratio", "repeat",
                   "lost_motion_pct", "hd_T1_Nm", "hd_T2_Nm")


class Test(BaseModel):
    """``[test]``: run.json ``test`` keys. ``rated_torque_Nm`` is required; other keys are
    kept as given unless they look like a misspelt known key."""

    model_config = ConfigDict(extra="allow", strict=True, allow_inf_nan=False)
    rated_torque_Nm: float = Field(gt=0)
    input_angle_deg: float | None = None
    temperature_C: float | None = None
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
    run_id: str | None = Field(default=None, min_length=1)
    columns: Columns
    test: Test
    sensors: dict[str, Any] = Field(default_factory=dict)

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
