"""``rig reanalyse`` at scale: 2,000 stored campaigns re-analysed on a local Dask cluster with
1 and with 2 worker processes; the wall time of each and the speed-up.

Each campaign is small and synthetic (:func:`rig.store.synthetic_runs.write_campaign`: the seed 000
pair 1 unit, 2 positions, the dead-zone loop with 100 steps per quarter, 401 samples a run):
per campaign 2 run analyses and 1 diagnosis. The store is SQLite in a temporary folder.
``BENCH_CAMPAIGNS`` changes the count. On a shared machine the speed-up is bounded by the
cores actually free.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent


def run() -> Iterator[dict[str, Any]]:
    from rig.store import Store
    from rig.store.reanalyse import reanalyse
    from rig.store.synthetic_runs import write_campaign

    n = int(os.environ.get("BENCH_CAMPAIGNS", "2000"))
    unit = json.loads((REPO / "rig/examples/units/seed000-pair1.json").read_text())
    with tempfile.TemporaryDirectory(prefix="bench-reanalyse-") as tmp:
        st = Store(Path(tmp) / "store")
        t0 = time.perf_counter()
        for k in range(n):
            write_campaign(st, f"B{k:05d}", play_arcmin=[4.2 + 0.001 * (k % 50), 4.3],
                           unit_data=unit, n_quarter=100)
        yield {"name": "reanalyse_store_build", "value": round(time.perf_counter() - t0, 1),
               "unit": "s", "campaigns": n, "runs": 2 * n}
        times = {}
        for workers in (1, 2):
            t = time.perf_counter()
            summary = reanalyse(st, workers=workers, software_version=f"bench-{workers}w")
            times[workers] = time.perf_counter() - t
            yield {"name": f"reanalyse_{workers}_worker_s", "value": round(times[workers], 1),
                   "unit": "s", "campaigns": n, "jobs": summary.written,
                   "not_analysable": summary.errors, "unreadable": len(summary.unreadable),
                   "jobs_per_s": round(summary.written / times[workers], 1)}
        yield {"name": "reanalyse_speedup_2_vs_1_worker",
               "value": round(times[1] / times[2], 2), "unit": "x", "campaigns": n,
               "cpus": os.cpu_count()}
