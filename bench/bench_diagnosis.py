"""The diagnosis' cost and the blind validation figures.

* ``diagnosis_12_runs_5000_samples_s``: wall time of the diagnosis (rig.diagnose, from the
  campaign in memory) of a 12-run campaign of 5,000 samples each (runout withheld, 12
  positions). Target: under 10 s on the 2-core box, never over 60 s.
* ``diagnosis_devset_median_s`` / ``diagnosis_devset_max_s``: median and largest wall time of
  ``rig diagnose`` (in process, one case after the other, reading the folder included) per
  development-set case: both unpacked sets under $RIG_DEVSET_DIR or ~/.cache/rig-devset
  (``devset-a``, ``devset-b``: /work/shared/validation/unpack.sh), else the subset in
  tests/data/devset/ (``source`` says which; ``BENCH_DEVSET_CASES`` caps how many, default all).
  Targets: median <= 2 s, max <= 20 s on the 2-core box.
* ``diagnosis_jobs2_wall_s``: wall time of grading both sets as ``rig validate-diagnosis
  --cases-dir A --labels A --cases-dir B --labels B --jobs 2`` does (two worker processes),
  with the slowest case's time; no case may take over 120 s.
The process' environment is left as it is (no BLAS thread variables set here): the figures are
what a user gets.
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

from rig.results.diagnose import diagnose_campaign, diagnose_path
from rig.validate import make_case, run_validation, simulate_campaign, summarise
from simulators.plant.config import load_plant_config


def devset_roots() -> tuple[str, list[Path]]:
    """The development sets (folders with ``cases/`` and ``labels.json``): the unpacked full
    sets first, else the subset in tests/data/devset/."""
    cache = Path(os.environ.get("RIG_DEVSET_DIR") or Path.home() / ".cache" / "rig-devset")
    here = Path(__file__).resolve().parent.parent / "tests" / "data" / "devset"
    for source, root in (("full", cache), ("subset", here)):
        sets = sorted(d for d in root.glob("*") if (d / "labels.json").is_file()
                      and (d / "cases").is_dir()) if root.is_dir() else []
        if sets:
            return f"{source} {root}", sets
    return "none", []


def devset_cases() -> list[Path]:
    """Campaign folders of the development sets (see :func:`devset_roots`)."""
    _, sets = devset_roots()
    return sorted(p.parent for s in sets for p in (s / "cases").rglob("campaign.json"))


def devset_times() -> Iterator[dict]:
    """Median and largest diagnosis time per development-set case (s), one after the other."""
    source, _ = devset_roots()
    cases = devset_cases()
    cap = int(os.environ.get("BENCH_DEVSET_CASES", "0") or 0)
    if cap:
        cases = cases[:cap]
    times = []
    for case in cases:
        t0 = time.perf_counter()
        diagnose_path(case)
        times.append(time.perf_counter() - t0)
    yield {"name": "diagnosis_devset_median_s",
           "value": statistics.median(times) if times else None, "unit": "s",
           "cases": len(times), "source": source, "target": "<= 2 s per case"}
    slowest = max(range(len(times)), key=times.__getitem__) if times else None
    yield {"name": "diagnosis_devset_max_s", "value": max(times) if times else None,
           "unit": "s", "cases": len(times), "source": source,
           "case": None if slowest is None else cases[slowest].name, "target": "<= 20 s"}


def devset_jobs2_wall() -> dict:
    """Wall time of grading both development sets with two worker processes (s)."""
    from rig.validate.cases import grade_folder

    source, sets = devset_roots()
    t0 = time.perf_counter()
    records = [r for s in sets for r in grade_folder(s / "cases", s / "labels.json", jobs=2)]
    wall = time.perf_counter() - t0
    secs = [r["seconds"] for r in records if r.get("seconds") is not None]
    return {"name": "diagnosis_jobs2_wall_s", "value": wall, "unit": "s",
            "cases": len(records), "source": source,
            "correct": sum(r["correct"] for r in records),
            "slowest_case_s": max(secs) if secs else None,
            "over_120_s": sum(s > 120 for s in secs), "target": "no case over 120 s"}


def run() -> Iterator[dict]:
    yield from devset_times()
    yield devset_jobs2_wall()
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
