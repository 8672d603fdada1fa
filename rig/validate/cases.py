"""Grading of labelled campaigns: any folder of campaigns with a ``labels.json``, or our own
generator's cases, diagnosed blind and summarised the same way.

:func:`grade_folder` diagnoses every labelled campaign folder under a directory exactly as
``rig diagnose`` does (:func:`rig.results.diagnose.diagnose_path`; the labels are never passed to
it)
and grades the reports with :mod:`rig.validate.labels`. :func:`summarise_graded` gives the
figures the development sets' graders print: correct verdicts, per-effect confusion, false
alarms on ``none`` cases, ``also`` recall and precision, median shrink of correct verdicts.
Cases run in ``jobs`` worker processes (the order of the results is the cases' order).
"""

from __future__ import annotations

import json
import os
import statistics
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from rig.core.blas import limit_blas_threads, worker_initializer
from rig.core.errors import RigError
from rig.validate.labels import Label, grade, read_labels


def diagnose_report(folder: str) -> dict[str, Any]:
    """The ``rig-diagnosis/1`` report of one campaign folder as ``rig diagnose --json`` writes
    it (non-finite numbers as null); on failure ``{"error": ...}``. Returns also ``seconds``."""
    from rig.core.json_files import finite_for_json as _finite
    from rig.results.diagnose import diagnose_path, report_dict

    t0 = time.perf_counter()
    try:
        camp, result = diagnose_path(folder)
        report = json.loads(json.dumps(_finite(report_dict(camp, result)), allow_nan=False))
    except Exception as exc:  # a crash of one case is a graded failure, not the end
        return {"error": f"{type(exc).__name__}: {exc}", "seconds": time.perf_counter() - t0}
    report["seconds"] = time.perf_counter() - t0
    return report


def parallel_map(fn: Callable[[Any], Any], items: Iterable[Any], jobs: int) -> Iterator[Any]:
    """``map(fn, items)`` in ``jobs`` processes (in order); in this process when jobs <= 1.

    Every call runs with one BLAS thread (rig/core/blas.py): the workers from their initializer,
    this process while it maps; ``jobs`` processes then use ``jobs`` cores, not ``jobs``
    times a thread per core."""
    items = list(items)
    if jobs <= 1 or len(items) <= 1:
        with limit_blas_threads():
            yield from map(fn, items)
        return
    with ProcessPoolExecutor(max_workers=min(jobs, len(items)),
                             initializer=worker_initializer) as pool:
        yield from pool.map(fn, items)


def labelled_cases(cases_dir: str | Path, labels: dict[str, Label]) -> list[tuple[str, Path]]:
    """The labelled case folders under ``cases_dir`` (sorted by id); unlabelled folders are
    left out, a label without its folder is an error naming it."""
    root = Path(cases_dir)
    if not root.is_dir():
        raise RigError(f"{root}: no such folder of cases")
    folders = {p.name: p for p in sorted(root.iterdir()) if p.is_dir()}
    missing = sorted(set(labels) - set(folders))
    if missing:
        raise RigError(f"{root}: no folder for labelled case(s) {', '.join(missing[:5])}"
                       + (" ..." if len(missing) > 5 else ""))
    return [(cid, folders[cid]) for cid in sorted(labels)]


def grade_folder(cases_dir: str | Path, labels_file: str | Path, jobs: int = 1,
                 progress: Callable[[dict[str, Any]], None] | None = None
                 ) -> list[dict[str, Any]]:
    """Diagnose and grade every labelled case; one record per case (see :func:`record`)."""
    labels = read_labels(labels_file)
    cases = labelled_cases(cases_dir, labels)
    out = []
    for (cid, _), report in zip(cases, parallel_map(diagnose_report, [str(p) for _, p in cases],
                                                    jobs), strict=True):
        rec = record(labels[cid], report)
        if progress is not None:
            progress(rec)
        out.append(rec)
    return out


def record(label: Label, report: dict[str, Any]) -> dict[str, Any]:
    """One graded case: the label's truth, the report's verdict / also / candidates, correct,
    false alarm, also counts, shrink, seconds; ``status`` 'ok' or 'crash' (with ``error``)."""
    base = {"case": label.case_id, "truth": label.effect, "truth_also": list(label.also),
            "truth_key": label.key, "category": label.category,
            "expected_min_shrink": label.expected_min_shrink,
            "seconds": report.get("seconds")}
    if "error" in report:
        return {**base, "status": "crash", "error": report["error"], "verdict": None,
                "also": [], "candidates": [], "correct": False,
                "false_alarm": False, "also_hits": 0, "also_reported": 0, "also_reported_ok": 0,
                "shrink": None}
    return {**base, "status": "ok", **grade(label, report)}


def _median(xs: list[float]) -> float | None:
    return float(statistics.median(xs)) if xs else None


def summarise_graded(name: str, records: list[dict[str, Any]]) -> dict[str, Any]:
    """The graders' figures for one generator (JSON-ready)."""
    confusion: dict[str, dict[str, int]] = {}
    per_effect: dict[str, dict[str, int]] = {}
    per_category: dict[str, dict[str, int]] = {}
    for r in records:
        got = (f"<{r['status']}>" if r["status"] != "ok"
               else r["verdict"] + "".join("+" + a for a in r["also"]))
        row = confusion.setdefault(r["truth_key"], {})
        row[got] = row.get(got, 0) + 1
        for table, key in ((per_effect, r["truth_key"]), (per_category, r["category"])):
            d = table.setdefault(key, {"n": 0, "correct": 0})
            d["n"] += 1
            d["correct"] += int(r["correct"])
    also_true = sum(len(r["truth_also"]) for r in records)
    also_hits = sum(r["also_hits"] for r in records)
    also_rep = sum(r["also_reported"] for r in records)
    also_rep_ok = sum(r["also_reported_ok"] for r in records)
    shrinks = [r["shrink"] for r in records if r["correct"] and r["shrink"] is not None]
    secs = [r["seconds"] for r in records if r.get("seconds") is not None]
    n = len(records)
    correct = sum(r["correct"] for r in records)
    return {
        "generator": name, "cases": n, "correct": correct,
        "accuracy": correct / n if n else None,
        "none_cases": sum(r["truth"] == "none" for r in records),
        "false_alarms": sum(r["false_alarm"] for r in records),
        "two_effect_cases": sum(bool(r["truth_also"]) for r in records),
        "also_recall": also_hits / also_true if also_true else None,
        "also_precision": also_rep_ok / also_rep if also_rep else None,
        "also_counts": {"labelled": also_true, "listed": also_hits, "reported": also_rep,
                        "reported_true": also_rep_ok},
        "median_shrink": _median(shrinks), "shrinks": len(shrinks),
        "failures": sum(r["status"] != "ok" for r in records),
        "median_seconds_per_case": _median(secs),
        "per_effect": per_effect, "per_category": per_category, "confusion": confusion,
        "results": records,
    }


def _fmt(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.2f}"


def summary_line(s: dict[str, Any]) -> str:
    """The one-line summary, in the development sets' graders' words."""
    return (f"{s['generator']}: {s['correct']}/{s['cases']} correct, "
            f"also_recall={_fmt(s['also_recall'])}, also_precision={_fmt(s['also_precision'])}, "
            f"false_alarms={s['false_alarms']}, median_shrink={_fmt(s['median_shrink'])}")


def generator_name(cases_dir: str | Path) -> str:
    """A set's name from its folder (``.../devset-a/cases`` -> ``devset-a``)."""
    p = Path(os.path.abspath(cases_dir))
    return p.parent.name if p.name == "cases" and p.parent.name else p.name
