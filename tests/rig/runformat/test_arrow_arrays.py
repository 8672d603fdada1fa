"""float64 columns between Arrow and numpy through their buffers (rig/runformat/arrow_arrays)."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pyarrow as pa
import pytest

from rig.runformat.arrow_arrays import float64_from_arrow, float64_to_arrow

VALUES = [1.0, None, 3.0, None, 5.0, 6.0, 7.0, 8.0, 9.0, None, 11.0]


def _expected(values: list[float | None]) -> np.ndarray:
    return np.array([math.nan if v is None else v for v in values], dtype=np.float64)


def test_every_slice_with_and_without_nulls_reads_as_its_values() -> None:
    """Nulls (empty CSV fields) read as NaN at every offset of the validity bitmap."""
    whole = pa.array(VALUES, type=pa.float64())
    for offset in range(len(VALUES)):
        for length in range(len(VALUES) - offset + 1):
            got = float64_from_arrow(whole.slice(offset, length))
            assert np.array_equal(got, _expected(VALUES[offset:offset + length]),
                                  equal_nan=True), (offset, length)


def test_chunked_columns_join_and_nan_payloads_survive_bit_for_bit() -> None:
    """A NaN with a payload (a value NaN, not a null) comes back with the same bits, through a
    chunked column as Parquet reads it."""
    odd_nan = np.frombuffer(np.uint64(0x7FF8_0000_DEAD_BEEF).tobytes(), dtype=np.float64)[0]
    values = np.array([0.5, odd_nan, -0.0, 1e308, -math.inf])
    arrow = float64_to_arrow(values)
    assert arrow.null_count == 0 and arrow.type == pa.float64()
    chunked = pa.chunked_array([arrow.slice(0, 2), arrow.slice(2)])
    back = float64_from_arrow(chunked)
    assert back.tobytes() == values.tobytes()
    assert float64_from_arrow(pa.chunked_array([], type=pa.float64())).size == 0


def test_a_non_float64_array_is_refused() -> None:
    with pytest.raises(TypeError, match="float64"):
        float64_from_arrow(pa.array([1, 2], type=pa.int64()))


def test_a_samples_round_trip_through_csv_and_parquet_never_loads_pandas(tmp_path) -> None:
    """The point of the module: finalising a run's samples (CSV -> Parquet -> read back) does
    not load pandas (0.8 s of CPU at every run's end). A fresh interpreter, so that nothing
    else of the test session has loaded it."""
    code = f"""
import sys
from pathlib import Path
import numpy as np
from rig.runformat.csvread import read_samples_csv
from rig.runformat.parquet import read_samples_parquet, write_samples_parquet
folder = Path({str(tmp_path)!r})
t = np.arange(1, 201) * 0.004
lines = ["t_s,torque_Nm,output_angle_deg,temperature_C"] + [
    f"{{a:.6f}},{{b:.9f}},{{c:.9f}},{{'' if i == 7 else '21.5'}}"
    for i, (a, b, c) in enumerate(zip(t, np.sin(t), np.cos(t)))]
(folder / "samples.csv").write_text("\\n".join(lines) + "\\n")
columns, data, _ = read_samples_csv(folder / "samples.csv", allow_truncated_tail=False)
write_samples_parquet(folder / "samples.parquet", columns, data)
_, back, _ = read_samples_parquet(folder / "samples.parquet")
assert all(np.array_equal(back[c], data[c], equal_nan=True) for c in columns)
assert np.isnan(back["temperature_C"][7]) and back["temperature_C"][8] == 21.5
print("pandas" in sys.modules)
"""
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip() == "False"
