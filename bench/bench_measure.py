"""One ``rig measure --simulated`` as an operator runs it: start-up, the run, the finish.

* ``measure_simulated_wall_s``: wall time of the whole command (a child process that starts
  the simulated rig in its own process), the default GB/T loop;
* ``measure_simulated_cpu_s``: user + system CPU of the command and the simulated rig
  (``RUSAGE_CHILDREN``: both are reaped before it is read), which a loaded machine changes
  less than the wall time;
* ``measure_simulated_overhead_s``: wall time beyond the plan's own duration (the preview's
  estimate): imports, the rig's start, the end-of-run analysis, the shutdown.

Medians of ``BENCH_MEASURE_REPEATS`` (default 3) runs.
"""

from __future__ import annotations

import os
import re
import resource
import statistics
import subprocess
import sys
import sysconfig
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

RIG = str(Path(sysconfig.get_path("scripts")) / "rig")


def _cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _plan_s(store: Path) -> float:
    res = subprocess.run([sys.executable, RIG, "measure", "--simulated", "--preview",
                          "--store", str(store)], capture_output=True, text=True, timeout=120,
                         check=True)
    match = re.search(r"about ([0-9.]+) s", res.stdout + res.stderr)
    if match is None:
        raise RuntimeError(f"no duration in the preview: {(res.stdout + res.stderr)[-300:]!r}")
    return float(match.group(1))


def run() -> Iterator[dict[str, Any]]:
    repeats = int(os.environ.get("BENCH_MEASURE_REPEATS", "3"))
    walls: list[float] = []
    cpus: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        plan_s = _plan_s(Path(tmp) / "preview")
        for k in range(repeats):
            store = Path(tmp) / f"store{k}"
            cpu0, t0 = _cpu_s(), time.perf_counter()
            subprocess.run([sys.executable, RIG, "measure", "--simulated", "--store",
                            str(store), "--json", str(Path(tmp) / f"m{k}.json")],
                           capture_output=True, text=True, timeout=300, check=True)
            walls.append(time.perf_counter() - t0)
            cpus.append(_cpu_s() - cpu0)
    wall = statistics.median(walls)
    yield {"name": "measure_simulated_wall_s", "value": wall, "unit": "s", "runs": repeats,
           "plan_s": plan_s}
    yield {"name": "measure_simulated_cpu_s", "value": statistics.median(cpus), "unit": "s",
           "runs": repeats}
    yield {"name": "measure_simulated_overhead_s", "value": wall - plan_s, "unit": "s",
           "plan_s": plan_s}
