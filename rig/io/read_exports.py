"""The columns of the rig's own binary exports (``rig export --format parquet|xlsx|mat``),
read back for ``rig import`` (issue 33 item 12: the engineer's round trip).

Each reader returns the file's columns by their names, in file order: float64 arrays, or
the cells' texts for a text column. :mod:`rig.io.read` picks the mapped ones from them. A
file that is not what its leading bytes say is one :class:`rig.io.map.RunImportError`
naming it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rig.io.map import RunImportError

__all__ = ["EXPORT_FORMATS", "export_format", "read_export_columns"]

Columns = dict[str, np.ndarray | list[str]]

EXPORT_FORMATS = ((b"PAR1", "parquet"), (b"PK\x03\x04", "xlsx"),
                  (b"MATLAB 5.0 MAT-file", "mat"))
"""Leading bytes of the files ``rig export`` writes, and their format."""
V73_MAGICS = (b"MATLAB 7.3 MAT-file", b"\x89HDF\r\n\x1a\n")
"""Leading bytes of a MATLAB v7.3 file (its text header; an HDF5 file without one)."""


def export_format(path: Path) -> str | None:
    """"parquet", "xlsx" or "mat" by the file's leading bytes; None for anything else.
    A MATLAB v7.3 (HDF5) file, which ``rig export`` never writes, is refused in one line."""
    with open(path, "rb") as f:
        head = f.read(32)
    if head.startswith(V73_MAGICS):
        raise RunImportError(f"{path}: a MATLAB v7.3 (HDF5) .mat file: rig import reads the "
                             "v5 .mat files rig export writes; save it with "
                             "save(..., '-v7') or export CSV")
    return next((fmt for magic, fmt in EXPORT_FORMATS if head.startswith(magic)), None)


def _column(values: object) -> np.ndarray | list[str]:
    array = np.asarray(values)
    if array.dtype.kind in "fiub":
        return array.astype(np.float64, copy=False).ravel()
    return ["" if v is None else str(v) for v in array.ravel()]


def _parquet(path: Path) -> Columns:
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    return {name: _column(table.column(name).to_numpy(zero_copy_only=False))
            for name in table.column_names}


def _xlsx(path: Path) -> Columns:
    import pandas as pd

    with pd.ExcelFile(path, engine="openpyxl") as book:
        sheet = "samples" if "samples" in book.sheet_names else book.sheet_names[0]
        frame = book.parse(sheet)
    return {str(name): _column(frame[name].to_numpy()) for name in frame.columns}


def _cell_texts(cell: np.ndarray) -> list[str]:
    """A MATLAB cell column of strings as loadmat gives it (object array of 1-element
    arrays)."""
    return [str(np.asarray(v).ravel()[0]) if np.asarray(v).size else "" for v in cell.ravel()]


def _mat(path: Path) -> Columns:
    from scipy.io import loadmat

    variables = loadmat(path)
    if "columns" in variables and "variables" in variables:  # rig export: names kept aside
        pairs = zip(_cell_texts(variables["columns"]), _cell_texts(variables["variables"]),
                    strict=True)
    else:
        pairs = ((k, k) for k in variables if not k.startswith("__"))
    out: Columns = {}
    for name, var in pairs:
        value = variables.get(var)
        if value is None:
            raise RunImportError(f"{path}: variable {var!r} (column {name!r}) is missing")
        out[name] = _cell_texts(value) if value.dtype == object else _column(value)
    return out


READERS = {"parquet": _parquet, "xlsx": _xlsx, "mat": _mat}


def read_export_columns(path: Path, fmt: str) -> Columns:
    """All columns of a ``rig export`` file of format ``fmt``; one line if it cannot be read."""
    try:
        return READERS[fmt](path)
    except RunImportError:
        raise
    except Exception as exc:  # pyarrow, openpyxl and scipy raise their own on a broken file
        text = " ".join(str(exc).split()) or type(exc).__name__
        raise RunImportError(f"{path}: not a readable {fmt} file ({text})") from None
