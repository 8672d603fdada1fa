"""The samples of a stored run as Parquet (``samples.parquet`` beside ``run.json``).

The store keeps a finished run's samples in Parquet; rig-run/1 CSV stays the exchange format.
Columns keep their names and order: numeric columns as float64 (NaN = missing value, kept
bit for bit), text columns as UTF-8 strings. A Parquet file made by another tool may hold
integer columns: they are read as float64.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from rig.core.errors import RunFormatError
from rig.runformat.arrow_arrays import float64_from_arrow, float64_to_arrow
from rig.runformat.base import (
    KNOWN_NUMERIC_COLUMNS,
    REQUIRED_COLUMNS,
    Column,
    Samples,
    check_column_names,
)


def write_samples_parquet(path: Path, columns: list[str], data: dict[str, Column]) -> None:
    """Write the columns to ``path`` atomically: temporary file, fsync, rename."""
    arrays = [
        float64_to_arrow(v) if isinstance(v, np.ndarray)
        else pa.array(v, type=pa.string())
        for v in (data[c] for c in columns)
    ]
    table = pa.Table.from_arrays(arrays, names=list(columns))
    tmp = path.with_name(f".{path.name}.tmp")
    pq.write_table(table, tmp, compression="none", use_dictionary=False,
                   write_statistics=False, row_group_size=max(1, table.num_rows))
    fd = os.open(tmp, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)


def read_samples_parquet(path: Path) -> Samples:
    """Read (columns, data, notes); a problem is a RunFormatError naming the file, the column
    (1-based) and the row (1-based, in the message: Parquet has no lines)."""
    try:
        with pq.ParquetFile(path) as source:
            names = list(source.schema_arrow.names)
            check_column_names(names, lambda msg, col: RunFormatError(path, msg, column=col))
            data: dict[str, Column] = {}
            for j, name in enumerate(names):  # column by column: peak memory near the data
                data[name] = _column(path, j, name, source.read(columns=[name]).column(0))
    except FileNotFoundError:
        raise RunFormatError(path, "no such file") from None
    except (OSError, pa.ArrowException) as e:
        raise RunFormatError(path, f"not a readable Parquet file: {e}") from None
    _check_values(path, names, data)
    return names, data, []


def _column(path: Path, j: int, name: str, col: pa.ChunkedArray) -> Column:
    """One Parquet column as a float64 array (writable, NaN = missing) or a list of str."""
    kind = col.type
    if pa.types.is_string(kind) or pa.types.is_large_string(kind):
        if name in KNOWN_NUMERIC_COLUMNS:
            raise RunFormatError(path, f"column {name!r} holds text, not numbers", column=j + 1)
        return [s if s is not None else "" for s in col.to_pylist()]
    if not (pa.types.is_floating(kind) or pa.types.is_integer(kind)):
        raise RunFormatError(path, f"column {name!r} has the type {kind}, expected numbers "
                             "or text", column=j + 1)
    if not pa.types.is_float64(kind):
        col = col.cast(pa.float64())
    arr = float64_from_arrow(col)
    return arr if arr.flags.writeable else arr.copy()


def _check_values(path: Path, names: list[str], data: dict[str, Column]) -> None:
    for name in REQUIRED_COLUMNS:
        bad = np.flatnonzero(~np.isfinite(data[name]))
        if bad.size:
            r = int(bad[0])
            raise RunFormatError(
                path, f"column {name!r}: row {r + 1}: non-finite value "
                f"{float(data[name][r])!r} in a required column", column=names.index(name) + 1)
    t = data["t_s"]
    bad = np.flatnonzero(~(np.diff(t) > 0))
    if bad.size:
        r = int(bad[0]) + 1
        raise RunFormatError(
            path, f"column 't_s': row {r + 1}: time must be strictly ascending: "
            f"{float(t[r])!r} after {float(t[r - 1])!r}", column=names.index("t_s") + 1)
