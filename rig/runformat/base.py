"""Names and small helpers shared by the rig-run/1 modules (``rig.runformat*``).

Units follow the column names: ``t_s`` in s, ``torque_Nm`` in N·m, angles in deg, ``_C`` in °C.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from rig.core.errors import RunFormatError

RUN_FORMAT = "rig-run/1"
CAMPAIGN_FORMAT = "rig-campaign/1"
RUN_JSON = "run.json"
SAMPLES_CSV = "samples.csv"
SAMPLES_PARQUET = "samples.parquet"
CAMPAIGN_JSON = "campaign.json"
REQUIRED_COLUMNS = ("t_s", "torque_Nm", "output_angle_deg")
OPTIONAL_NUMERIC_COLUMNS = ("input_angle_deg", "temperature_C")
KNOWN_NUMERIC_COLUMNS = REQUIRED_COLUMNS + OPTIONAL_NUMERIC_COLUMNS

Column = np.ndarray | list[str]
Samples = tuple[list[str], dict[str, Column], list[str]]
"""What a samples reader returns: column order, columns by name, notes."""


def check_column_names(columns: list[str], error: Callable[[str, int | None], Exception]) -> None:
    """Raise ``error(message, 1-based column)`` for an empty, duplicate or missing name."""
    seen: set[str] = set()
    for i, name in enumerate(columns, 1):
        if not name:
            raise error(f"column {i} has an empty name", i)
        if name in seen:
            raise error(f"column {i} {name!r} appears twice in the header", i)
        seen.add(name)
    for name in REQUIRED_COLUMNS:
        if name not in seen:
            others = [c for c in columns if c not in KNOWN_NUMERIC_COLUMNS]
            case = [c for c in others if c.lower() == name.lower()]
            near = case or difflib.get_close_matches(name, others, n=1, cutoff=0.6)
            col = columns.index(near[0]) + 1 if near else None
            hint = f"; did you mean column {col} {near[0]!r}?" if near else ""
            raise error(
                f"required column {name!r} is missing from the header {columns} "
                f"(names are case-sensitive){hint}",
                col,
            )


def read_bytes(path: Path) -> bytes:
    """The whole file; a missing or unreadable file is a RunFormatError naming it."""
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise RunFormatError(path, "no such file") from None
    except IsADirectoryError:
        raise RunFormatError(path, "is a folder, expected a file") from None
    except OSError as e:
        raise RunFormatError(path, f"cannot read: {e.strerror or e}") from None


def decode(path: Path, raw: bytes, csv_fields: bool = False) -> str:
    """Decode UTF-8 (a leading BOM is dropped). A bad byte is an error at its line and column:
    the CSV field index if ``csv_fields``, else the character column.
    """
    try:
        return raw.decode("utf-8").removeprefix("\ufeff")
    except UnicodeDecodeError as e:
        line_start = raw.rfind(b"\n", 0, e.start) + 1
        line = raw.count(b"\n", 0, e.start) + 1
        prefix = raw[line_start : e.start]
        col = prefix.count(b",") + 1 if csv_fields else len(prefix.decode("utf-8", "replace")) + 1
        raise RunFormatError(
            path, f"not UTF-8: byte 0x{raw[e.start]:02x} is not valid UTF-8", line, col
        ) from None


def numeric_bits_equal(x: np.ndarray, y: np.ndarray) -> bool:
    """Same shape, NaN at the same places, every other value bit-identical (-0.0 != 0.0)."""
    if x.shape != y.shape or not np.array_equal(np.isnan(x), np.isnan(y)):
        return False
    keep = ~np.isnan(x)
    return bool(np.array_equal(x[keep].view(np.uint64), y[keep].view(np.uint64)))


def as_float_column(name: str, values: Any) -> np.ndarray:
    arr = np.array(values, dtype=np.float64)
    if arr.ndim != 1:
        raise ValueError(f"column {name!r} must be 1-D, got shape {arr.shape}")
    return arr
