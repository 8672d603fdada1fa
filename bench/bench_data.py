"""The columnar data path: open and write a 1,000,000-sample run (docs/run-format.md).

The run is a 1 kHz encoder run as the recorder writes it (rig/engine/record.py): ``t_s``
(monotonic clock, jittered), ``torque_Nm`` (a slow ±10 N·m sweep with noise),
``output_angle_deg`` and ``input_angle_deg`` (2^23-count encoders, unwrapped),
``temperature_C`` (0.01 °C steps), ``torque_command_Nm``, ``step`` and ``sample_window``
(whole numbers). Figures (the best of ``BENCH_REPEAT`` tries, default 3):

- ``data_open_1M_csv_s``: ``read_run`` of the run folder with ``samples.csv``;
- ``data_open_1M_csv_pyarrow_s``: ``pyarrow.csv.read_csv`` of the same file alone;
- ``data_open_1M_csv_ratio_vs_pyarrow``: the two above divided (target: within 2x);
- ``data_open_1M_from_store_s``: ``read_run`` of the stored folder (run.json +
  samples.parquet), what ``Store.load_run`` does after the index look-up (target < 0.05 s);
- ``data_write_1M_s``: writing the run into a store folder (samples.parquet + run.json,
  synced; target < 0.5 s); ``data_write_1M_csv_s``: ``write_run`` (rig-run/1 CSV);
  ``data_finalise_1M_s``: turning a recorded CSV stream into Parquet (end of a stored run);
- ``data_peak_memory_ratio``: peak RSS increase while ``read_run`` opens the CSV, divided
  by the bytes of the float64 columns (target < 3); ``data_peak_memory_ratio_store``: the
  same for the Parquet folder. Measured in a fresh process each (``ru_maxrss``).

``BENCH_DATA_ROWS`` changes the row count (the names keep "1M").
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
COUNTS_PER_REV = 2**23

PEAK = """
import resource, sys, numpy as np
sys.path.insert(0, sys.argv[2])
from rig.runformat import read_run
import pyarrow, pyarrow.csv, pyarrow.parquet
def rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize()
before = rss()
peak_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
run = read_run(sys.argv[1])
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
data = sum(v.nbytes for v in run.data.values() if isinstance(v, np.ndarray))
print(max(peak - max(before, peak_before), 0) / data if peak > peak_before else
      (rss() - before) / data)
"""


def make_run(n: int, seed: int = 0) -> Any:
    """A 1 kHz run of ``n`` samples with the recorder's columns (s, N·m, deg, °C)."""
    from rig.runformat import Run

    rng = np.random.default_rng(seed)
    t = 0.0123 + np.cumsum(rng.uniform(0.00095, 0.00105, n))
    step = np.floor(t / 2.0)
    command = np.round(10.0 * np.sin(2 * np.pi * step / 40.0), 3)
    torque = command * (1 - np.exp(-(t % 2.0) / 0.05)) + rng.normal(0, 0.004, n)
    twist = 0.07 * np.tanh(torque / 2.0) + torque * 0.002
    out_counts = np.round((123.4 + twist) / 360.0 * COUNTS_PER_REV)
    in_counts = np.round((45.0 + 0.001 * t) / 360.0 * COUNTS_PER_REV)
    return Run.from_arrays(
        "bench-1M", t, torque, out_counts * (360.0 / COUNTS_PER_REV),
        input_angle_deg=in_counts * (360.0 / COUNTS_PER_REV),
        temperature_C=np.round(20.0 + 0.5 * t / t[-1] + rng.normal(0, 0.01, n), 2),
        extra_meta={"started_at": "2026-11-25T08:00:00Z", "label": "bench"},
        extra_columns={"torque_command_Nm": command, "step": step,
                       "sample_window": np.full(n, 8.0)},
        test={"rated_torque_Nm": 10.0, "input_angle_deg": 45.0},
    )


def best(fn: Callable[[], Any], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def peak_ratio(folder: Path) -> float:
    out = subprocess.run([sys.executable, "-c", PEAK, str(folder), str(REPO)], check=True,
                         capture_output=True, text=True, timeout=300)
    return float(out.stdout.strip().splitlines()[-1])


def run() -> Iterator[dict[str, Any]]:
    import pyarrow.csv as pacsv

    from rig.runformat import RUN_JSON, read_run, runs_equal, write_run, write_samples_parquet
    from rig.store.files import finalise_samples, sync_dir, write_json_atomic

    n = int(os.environ.get("BENCH_DATA_ROWS", "1000000"))
    repeat = int(os.environ.get("BENCH_REPEAT", "3"))
    run_ = make_run(n)
    with tempfile.TemporaryDirectory(prefix="bench-data-") as tmp:
        csv_dir, store_dir = Path(tmp) / "csv", Path(tmp) / "store"
        write_csv_s = best(lambda: write_run(run_, csv_dir), repeat)
        csv_path = csv_dir / "samples.csv"
        size = csv_path.stat().st_size

        def write_store() -> None:
            store_dir.mkdir(exist_ok=True)
            write_samples_parquet(store_dir / "samples.parquet", run_.columns, run_.data)
            write_json_atomic(store_dir / RUN_JSON, run_.meta)
            sync_dir(store_dir)

        write_s = best(write_store, repeat)
        open_csv_s = best(lambda: read_run(csv_dir), repeat)
        open_pa_s = best(lambda: pacsv.read_csv(str(csv_path)), repeat)
        open_store_s = best(lambda: read_run(store_dir), repeat)
        assert runs_equal(read_run(csv_dir), run_) and runs_equal(read_run(store_dir), run_)

        def finalise() -> None:
            shutil.rmtree(Path(tmp) / "stream", ignore_errors=True)
            shutil.copytree(csv_dir, Path(tmp) / "stream")
            t0 = time.perf_counter()
            finalise_samples(Path(tmp) / "stream")
            times.append(time.perf_counter() - t0)

        times: list[float] = []
        for _ in range(repeat):
            finalise()
        ratio_csv = peak_ratio(csv_dir)
        ratio_store = peak_ratio(store_dir)
    common = {"rows": n, "columns": len(run_.columns)}
    yield {"name": "data_open_1M_csv_s", "value": round(open_csv_s, 3), "unit": "s",
           "csv_MB": round(size / 1e6, 1), **common}
    yield {"name": "data_open_1M_csv_pyarrow_s", "value": round(open_pa_s, 3), "unit": "s",
           **common}
    yield {"name": "data_open_1M_csv_ratio_vs_pyarrow", "value": round(open_csv_s / open_pa_s, 2),
           "unit": "x", "target": 2.0}
    yield {"name": "data_open_1M_from_store_s", "value": round(open_store_s, 4), "unit": "s",
           "target": 0.05, **common}
    yield {"name": "data_write_1M_s", "value": round(write_s, 3), "unit": "s", "target": 0.5,
           "what": "store folder: samples.parquet + run.json, fsynced", **common}
    yield {"name": "data_write_1M_csv_s", "value": round(write_csv_s, 3), "unit": "s",
           "what": "write_run: rig-run/1 samples.csv + run.json", **common}
    yield {"name": "data_finalise_1M_s", "value": round(min(times), 3), "unit": "s",
           "what": "samples.csv stream to samples.parquet at the end of a stored run"}
    yield {"name": "data_peak_memory_ratio", "value": round(ratio_csv, 2), "unit": "x",
           "target": 3.0, "what": "peak RSS increase / float64 data bytes, read_run of CSV"}
    yield {"name": "data_peak_memory_ratio_store", "value": round(ratio_store, 2), "unit": "x",
           "target": 3.0, "what": "the same for the Parquet store folder"}


if __name__ == "__main__":
    for row in run():
        print(json.dumps(row), flush=True)
