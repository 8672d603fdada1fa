"""``rig import`` of a large file (issue 21 item 8): a ~160 MB catman-style export.

The file is generated in a temporary folder: ``Time [s];Torque [N*m];Angle [arcsec]`` with
decimal commas (``examples/maps/catman.toml``), a 1 kHz hysteresis loop (±10 N·m sine of
20 s, 3 arcmin of play, 28 N·m/arcmin, noise), about 5.5 million rows. It is imported by
``rig import … --into STORE`` in a child process (what the issue timed at 134 s and 2.8 GB),
and by ``rig import … --out RUN`` (the same reading and checks, no analysis, a run folder):

- ``import_160mb_s``: wall time of ``--into`` (read, check, ``rig analyse``'s metrics, the
  run in the store); target under 30 s;
- ``import_160mb_peak_rss_mb``: that child's peak resident memory (``wait4`` rusage);
  target under 1000 MB;
- ``import_160mb_out_s`` / ``import_160mb_out_peak_rss_mb``: the same for ``--out``;
- each time also as ``cpu_s`` (user + system CPU of the child), which a loaded machine
  changes less than the wall time.

``BENCH_IMPORT_ROWS`` changes the row count (the names keep "160mb").
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
MAP = REPO / "examples" / "maps" / "catman.toml"
UNIT = REPO / "rig" / "examples" / "units" / "seed000-pair1.json"
ROWS = 5_500_000
CHUNK = 500_000


def write_catman(path: Path, rows: int, seed: int = 0) -> int:
    """Write the catman-style file (``;``, decimal comma) in chunks; its size in bytes."""
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.csv as pacsv

    rng = np.random.default_rng(seed)
    header = ["Time [s]", "Torque [N*m]", "Angle [arcsec]"]
    options = pacsv.WriteOptions(include_header=False, delimiter=";", quoting_style="none")
    with open(path, "wb") as f:
        f.write((";".join(header) + "\n").encode())
        for start in range(0, rows, CHUNK):
            k = np.arange(start, min(rows, start + CHUNK))
            t = k * 1e-3
            command = 10.0 * np.sin(2 * np.pi * t / 20.0)
            flank = np.where(np.cos(2 * np.pi * t / 20.0) >= 0, 1.0, -1.0)
            torque = np.round(command + rng.normal(0, 0.004, k.size), 5)
            twist_arcmin = flank * 1.5 + torque / 28.0
            angle = np.round(444_000.0 + twist_arcmin * 60.0 + rng.normal(0, 0.1, k.size), 4)
            cols = [pc.replace_substring(pc.cast(pa.array(np.round(v, 6)), pa.string()),
                                         ".", ",") for v in (t, torque, angle)]
            pacsv.write_csv(pa.table(cols, names=header), f, write_options=options)
    return path.stat().st_size


def timed_child(args: list[str], cwd: Path) -> tuple[float, float, float]:
    """(wall s, peak RSS MB, CPU s) of ``python -m rig ARGS`` run to its end."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    t0 = time.perf_counter()
    with tempfile.TemporaryFile("w+") as err:
        child = subprocess.Popen([sys.executable, "-m", "rig", *args], cwd=cwd, env=env,
                                 stdout=subprocess.DEVNULL, stderr=err)
        _pid, status, usage = os.wait4(child.pid, 0)
        wall = time.perf_counter() - t0
        child.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        text = err.read()
    if child.returncode != 0:
        raise RuntimeError(f"rig {' '.join(args[:1])} failed: {text.strip()[-500:]}")
    return wall, usage.ru_maxrss / 1024.0, usage.ru_utime + usage.ru_stime


def run() -> Iterator[dict[str, Any]]:
    rows = int(os.environ.get("BENCH_IMPORT_ROWS", str(ROWS)))
    with tempfile.TemporaryDirectory(prefix="bench-import-") as tmp:
        work = Path(tmp)
        source = work / "catman.csv"
        size = write_catman(source, rows)
        common = {"rows": rows, "file_MB": round(size / 1e6, 1),
                  "load_avg_1min": round(os.getloadavg()[0], 1)}
        base = ["import", str(source), "--map", str(MAP), "--unit", str(UNIT)]
        wall, rss, cpu = timed_child([*base, "--into", str(work / "store")], work)
        yield {"name": "import_160mb_s", "value": round(wall, 1), "unit": "s", "target": 30,
               "cpu_s": round(cpu, 1),
               "what": "rig import --into STORE (read, check, analyse, store)", **common}
        yield {"name": "import_160mb_peak_rss_mb", "value": round(rss), "unit": "MB",
               "target": 1000, **common}
        wall, rss, cpu = timed_child([*base, "--out", str(work / "run")], work)
        yield {"name": "import_160mb_out_s", "value": round(wall, 1), "unit": "s",
               "cpu_s": round(cpu, 1),
               "what": "rig import --out RUN (read, check, run folder; no analysis)", **common}
        yield {"name": "import_160mb_out_peak_rss_mb", "value": round(rss), "unit": "MB",
               **common}


if __name__ == "__main__":
    for row in run():
        print(json.dumps(row), flush=True)
