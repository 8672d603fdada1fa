"""Seed 001 TCA speed: wall time per mesh cycle of the beveloid pair's transmission error
(eq. 11 by the contact equations 7 and 10), for the parallel-axis line contact and for the
paper's combined installation errors, at 12 points per cycle (37 tooth-pair solves).

``cpu_s`` and the load average before the run tell a slow machine from a slow program."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator

from analysis.models.seed001_beveloid import PAPER_CASES, paper_pair, transmission_error

POINTS_PER_CYCLE = 12


def run() -> Iterator[dict]:
    pair = paper_pair()
    for name in ("standard", "combined"):
        load_before = os.getloadavg()[0]
        cpu_start = time.process_time()
        start = time.perf_counter()
        te = transmission_error(pair, PAPER_CASES[name], POINTS_PER_CYCLE)
        elapsed = time.perf_counter() - start
        yield {
            "name": f"seed001_tca_{name}_per_mesh_cycle",
            "value": round(elapsed, 3),
            "unit": "s",
            "points_per_cycle": POINTS_PER_CYCLE,
            "cpu_s": round(time.process_time() - cpu_start, 3),
            "load_avg_1min_before": round(load_before, 2),
            "te_peak_to_peak_arcsec": round(te.peak_to_peak_arcsec, 3),
        }
