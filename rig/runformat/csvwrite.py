"""Writing the samples of a rig-run/1 run as CSV text (docs/run-format.md).

Numbers are the shortest decimal that reads back bit for bit (Python's ``repr``: ``0.1``,
``1e-05``, ``20.0``); a missing value (NaN) is an empty field. In the columns the format
does not define (``torque_command_Nm``, ``step``, ``sample_window``, ...) a whole number is
written as an integer (``8``, not ``8.0``); it reads back as the same float64. The standard
columns (``t_s``, ``torque_Nm``, angles, ``temperature_C``) always carry their point.
Text fields are quoted only when they must be (a comma, a quote or a line break in them).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import orjson

from rig.runformat.base import KNOWN_NUMERIC_COLUMNS, Column

_MAX_EXACT_INT = 2.0**53
_NUMPY = orjson.OPT_SERIALIZE_NUMPY


def csv_field(text: str) -> str:
    """Quote a text field as the csv module does (only when needed)."""
    if any(c in text for c in ',"\r\n'):
        return '"' + text.replace('"', '""') + '"'
    return text


def csv_line(fields: Sequence[str]) -> str:
    return ",".join(csv_field(f) for f in fields) + "\n"


def writes_integers(column: str) -> bool:
    """Does this column write whole numbers as integers (every column but the standard ones)?"""
    return column not in KNOWN_NUMERIC_COLUMNS


def format_cell(value: float | str | None, integers: bool = False) -> str:
    """One cell: shortest round-trip float, empty for None/NaN, text quoted if needed;
    with ``integers`` a whole number (|x| < 2**53, not -0.0) as an integer."""
    if value is None:
        return ""
    if isinstance(value, str):
        return csv_field(value)
    x = float(value)
    if math.isnan(x):
        return ""
    if integers and _is_int(x):
        return str(int(x))
    return repr(x)


def _is_int(x: float) -> bool:
    return math.isfinite(x) and x == math.floor(x) and abs(x) < _MAX_EXACT_INT and not (
        x == 0.0 and math.copysign(1.0, x) < 0)


def format_numeric(values: np.ndarray, integers: bool = False) -> list[str]:
    """``format_cell`` of every value of a float64 array, vectorised (orjson, then ``repr``
    only where orjson's notation differs from Python's: below 1e-4, from 1e16, non-finite)."""
    v = np.ascontiguousarray(values, dtype=np.float64)
    if v.size == 0:
        return []
    texts = orjson.dumps(v, option=_NUMPY)[1:-1].decode("ascii").split(",")
    a = np.abs(v)
    with np.errstate(invalid="ignore"):
        odd = ~np.isfinite(v) | ((a < 1e-4) & (a != 0.0)) | (a >= 1e16)
    for i in np.flatnonzero(odd).tolist():
        x = float(v[i])
        texts[i] = "" if math.isnan(x) else repr(x)
    if integers:
        with np.errstate(invalid="ignore"):
            whole = (np.floor(v) == v) & (a < _MAX_EXACT_INT) & ~((v == 0.0) & np.signbit(v))
        if whole.any():
            ints = orjson.dumps(v[whole].astype(np.int64), option=_NUMPY)[1:-1]
            int_texts = ints.decode("ascii").split(",")
            if whole.all():
                return int_texts
            for i, s in zip(np.flatnonzero(whole).tolist(), int_texts, strict=True):
                texts[i] = s
    return texts


def samples_text(columns: list[str], data: dict[str, Column]) -> str:
    """The whole samples CSV: header line, then one line per row, each ending in a newline."""
    cells = [
        format_numeric(v, writes_integers(c)) if isinstance(v, np.ndarray)
        else [csv_field(s) for s in v]
        for c, v in ((c, data[c]) for c in columns)
    ]
    out = csv_line(columns)
    if cells and cells[0]:
        out += "\n".join(map(",".join, zip(*cells, strict=True))) + "\n"
    return out
