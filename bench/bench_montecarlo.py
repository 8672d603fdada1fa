"""Seed 003 Monte Carlo speed: 50,000 samples (the paper's count, target 2 s) and 1,000,000
samples (target 30 s), each the full evaluation of max |dtheta| over one output revolution.

``cpu_s`` (process CPU time, all threads) and the load average before the run tell a slow
machine (other jobs) from a slow program."""

from __future__ import annotations

import resource
from collections.abc import Iterator

from analysis.models.seed003_montecarlo import monte_carlo
from analysis.models.seed003_planetary import paper_train
from bench.timing import timed

TARGETS_S = {50_000: 2.0, 1_000_000: 30.0}


def run() -> Iterator[dict]:
    train = paper_train()
    monte_carlo(train, 4_096, seed=99)  # warm up BLAS threads and caches
    for samples, target in TARGETS_S.items():
        t = timed(lambda samples=samples: monte_carlo(train, samples, seed=0))
        stats = t.result
        yield {
            "name": f"seed003_montecarlo_{samples}",
            **t.fields(),
            "target": target,
            "ok": t.wall_s < target,
            "mean_arcsec": round(stats.mean_arcsec, 2),
            "std_arcsec": round(stats.std_arcsec, 2),
            "peak_rss_MiB": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        }
