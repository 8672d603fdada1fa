"""float64 columns between Arrow and numpy through their buffers.

pyarrow's own conversions (``pa.array`` of a numpy array, ``to_numpy``, ``fill_null``) load
pandas on first use when it is installed: 0.8 s of CPU at the end of every measured run
(the samples' finalisation to Parquet and their reading back). These read and make the
buffers directly; values, NaN included, are kept bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
import pyarrow as pa


def float64_from_arrow(col: pa.Array | pa.ChunkedArray) -> np.ndarray:
    """A float64 Arrow array (or chunked array) as numpy, nulls (empty fields) as NaN. A single
    chunk without nulls is a read-only view of Arrow's memory."""
    if isinstance(col, pa.ChunkedArray):
        parts = [float64_from_arrow(c) for c in col.chunks]
        return parts[0] if len(parts) == 1 else np.concatenate(parts or [np.empty(0)])
    if not pa.types.is_float64(col.type):
        raise TypeError(f"expected a float64 Arrow array, got {col.type}")
    n, offset = len(col), col.offset
    validity, data = col.buffers()[:2]
    if data is None:  # an empty array may have no data buffer
        return np.full(n, math.nan)
    values = np.frombuffer(data, dtype=np.float64, count=offset + n)[offset:]
    if col.null_count:
        bits = np.unpackbits(np.frombuffer(validity, dtype=np.uint8), bitorder="little")
        values = np.where(bits[offset:offset + n].astype(bool), values, math.nan)
    return values


def float64_to_arrow(values: np.ndarray) -> pa.Array:
    """A numpy array as a float64 Arrow array without nulls (NaN stays a value)."""
    v = np.ascontiguousarray(values, dtype=np.float64)
    return pa.Array.from_buffers(pa.float64(), v.size, [None, pa.py_buffer(v)])
