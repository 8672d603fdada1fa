"""The diagnosis' cost and the blind validation figures.

* ``diagnosis_12_runs_5000_samples_s``: wall time of the diagnosis (rig.diagnose, from the
  campaign in memory) of a 12-run campaign of 5,000 samples each (runout withheld, 12
  positions). Target: under 10 s on the 2-core box, never over 60 s.
* ``diagnosis_devset_median_s``: median wall time of ``rig diagnose`` (in process, reading
  the folder included) per development-set case: the cases under tests/data/devset/ when
  present, else the unpacked sets under $RIG_DEVSET_DIR or ~/.cache/rig-devset
  (``BENCH_DEVSET_CASES`` caps how many, default all). Target: <= 2 s on the 2-core box.
* ``validation_<N>_cases_s``: wall time of generating and diagnosing N cases
  (``BENCH_CASES``, default 100; target: 100 cases under 600 s), with the four figures of the
  issue (correct verdicts, false alarms, out-of-vocabulary handling, median shrink).
"""

from __future__ import annotations

import os
import statistics
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from rig.diagnose import diagnose_campaign, diagnose_path
from rig.validate import make_case, run_validation, simulate_campaign, summarise
from simulators.plant.config import load_plant_config


def devset_cases() -> list[Path]:
    """Campaign folders of the development sets: tests/data/devset/ first, else the cache."""
    here = Path(__file__).resolve().parent.parent / "tests" / "data" / "devset"
    roots = [here] if here.is_dir() else []
    cache = Path(os.environ.get("RIG_DEVSET_DIR") or Path.home() / ".cache" / "rig-devset")
    if not roots and cache.is_dir():
        roots = [cache]
    return sorted(p.parent for root in roots for p in root.rglob("campaign.json"))


def devset_median_s() -> dict:
    """Median diagnosis time per development-set case (s)."""
    cases = devset_cases()
    cap = int(os.environ.get("BENCH_DEVSET_CASES", "0") or 0)
    if cap:
        cases = cases[:cap]
    times = []
    for case in cases:
        t0 = time.perf_counter()
        diagnose_path(case)
        times.append(time.perf_counter() - t0)
    return {"name": "diagnosis_devset_median_s",
            "value": statistics.median(times) if times else None, "unit": "s",
            "cases": len(times), "max_s": max(times) if times else None,
            "target": "<= 2 s per case"}


def run() -> Iterator[dict]:
    yield devset_median_s()
    case = make_case(0, "runout", np.random.default_rng(12), load_plant_config())
    case.positions_deg = [30.0 * k for k in range(12)]
    case.temperatures_C = [20.0] * 12
    campaign = simulate_campaign(case, samples=5000)
    t0 = time.perf_counter()
    report = diagnose_campaign(campaign).to_dict()
    yield {"name": "diagnosis_12_runs_5000_samples_s", "value": time.perf_counter() - t0,
           "unit": "s", "verdict": report["verdict"], "target": "< 10 s"}
    n = int(os.environ.get("BENCH_CASES", "100"))
    t0 = time.perf_counter()
    summary = summarise(run_validation(n, seed=1))
    yield {"name": f"validation_{n}_cases_s", "value": time.perf_counter() - t0, "unit": "s",
           "target": "100 cases < 600 s"}
    for key in ("correct_share", "false_alarm_share", "oov_unexplained_or_ambiguous_share",
                "median_shrink"):
        yield {"name": f"validation_{key}", "value": summary[key], "unit": "1",
               "target": summary["targets"][key]}
