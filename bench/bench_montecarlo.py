"""Seed 003 Monte Carlo speed: 50,000 samples (the paper's count, target 2 s) and 1,000,000
samples (target 30 s), each the full evaluation of max |dtheta| over one output revolution.

``cpu_s`` (process CPU time, all threads) and the load average before the run tell a slow
machine (other jobs) from a slow program."""

from __future__ import annotations

import os
import resource
import time
from collections.abc import Iterator

from analysis.models.seed003_montecarlo import monte_carlo
from analysis.models.seed003_planetary import paper_train

TARGETS_S = {50_000: 2.0, 1_000_000: 30.0}


def run() -> Iterator[dict]:
    train = paper_train()
    monte_carlo(train, 4_096, seed=99)  # warm up BLAS threads and caches
    for samples, target in TARGETS_S.items():
        load_before = os.getloadavg()[0]
        cpu_start = time.process_time()
        start = time.perf_counter()
        stats = monte_carlo(train, samples, seed=0)
        elapsed = time.perf_counter() - start
        cpu = time.process_time() - cpu_start
        yield {
            "name": f"seed003_montecarlo_{samples}",
            "value": round(elapsed, 3),
            "unit": "s",
            "target": target,
            "ok": elapsed < target,
            "cpu_s": round(cpu, 3),
            "load_avg_1min_before": round(load_before, 2),
            "mean_arcsec": round(stats.mean_arcsec, 2),
            "std_arcsec": round(stats.std_arcsec, 2),
            "peak_rss_MiB": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        }
