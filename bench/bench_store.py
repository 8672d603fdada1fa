"""The store's index at production scale: 1,000,000 runs in SQLite and in PostgreSQL.

Generated metadata only (no sample files): 50,000 units of 5 designs, 20 runs each, spread
over two years, 4 % failed. For each back-end: the insert rate (bulk load into the indexed
table: SQLite ``executemany`` in one transaction, PostgreSQL ``COPY``) and p50/p99 of the
history page's query (``Store.list_runs(..., limit=200)``, the page's default page size) by
unit serial, by a one-day date range, and by outcome (newest failures before a random day).

PostgreSQL: ``$BENCH_PG_URL`` if set (an empty database), else a throw-away cluster of
Debian's ``postgresql`` (tests/support/pg_server.py). ``BENCH_RUNS`` changes the count;
``BENCH_QUERIES`` the queries per kind (default 200).
"""

from __future__ import annotations

import os
import random
import tempfile
import time
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np

DESIGNS = ("RV-20E", "RV-40E", "RV-80E", "RV-110E", "RV-160E")
START = datetime(2025, 1, 1, tzinfo=UTC)
SPAN_S = 2 * 365 * 86400


def generated_runs(n: int, seed: int = 0) -> Iterator[dict[str, Any]]:
    """``n`` finished runs: serial, design, start time (in order), outcome, metrics."""
    rng = random.Random(seed)
    n_units = max(1, n // 20)
    step = SPAN_S / n
    for i in range(n):
        unit = rng.randrange(n_units)
        serial = f"U{unit:06d}"
        design = DESIGNS[unit % len(DESIGNS)]
        t = START + timedelta(seconds=int(i * step))
        stamp = t.strftime("%Y%m%dT%H%M%SZ")
        iso = t.strftime("%Y-%m-%dT%H:%M:%SZ")
        outcome = "fail" if rng.random() < 0.04 else "pass"
        lm = round(rng.gauss(2.0, 0.15), 4)
        run_id = f"{serial}-{stamp}-{i}"
        yield {
            "run_id": run_id, "campaign_id": None, "unit_serial": serial,
            "operator": f"op{unit % 7}", "rig_id": f"rig-{i % 8}", "calibration": [],
            "software_version": "0.1.0", "plan_name": "gbt", "plan_version": "1",
            "status": "completed", "reason": None, "started_at": iso, "finished_at": iso,
            "n_samples": 4001, "path": f"runs/{run_id}",
            "metrics": {"lost_motion_arcmin": lm}, "writer_pid": 1, "writer_host": "bench",
            "outcome": outcome, "design": design,
            "meta": {"unit": {"serial": serial, "design": design}, "outcome": outcome},
        }


def _percentiles(times_s: list[float]) -> tuple[float, float]:
    a = np.asarray(times_s) * 1000.0
    return float(np.percentile(a, 50)), float(np.percentile(a, 99))


def _bench_backend(name: str, store: Any, n: int, n_queries: int) -> Iterator[dict[str, Any]]:
    t0 = time.perf_counter()
    inserted = store._index.bulk_insert_runs(generated_runs(n))
    load_s = time.perf_counter() - t0
    if name == "postgresql":
        store._index._call(lambda c, _: c.execute("ANALYZE runs"))
    yield {"name": f"store_{name}_insert_rate", "value": round(inserted / load_s),
           "unit": "runs/s", "runs": inserted, "seconds": round(load_s, 1)}
    rng = random.Random(1)
    n_units = max(1, n // 20)
    kinds = {
        "serial": lambda: {"serial": f"U{rng.randrange(n_units):06d}"},
        "date_range": lambda: _day(rng),
        "outcome": lambda: {"outcome": "fail", "until": _day(rng)["until"]},
    }
    for kind, args in kinds.items():
        times, sizes = [], []
        for _ in range(n_queries):
            kw = args()
            t = time.perf_counter()
            rows = store.list_runs(limit=200, **kw)
            times.append(time.perf_counter() - t)
            sizes.append(len(rows))
        p50, p99 = _percentiles(times)
        yield {"name": f"store_{name}_history_by_{kind}_p99", "value": round(p99, 2),
               "unit": "ms", "p50_ms": round(p50, 2), "queries": n_queries,
               "mean_rows": round(float(np.mean(sizes)), 1), "runs": inserted}


def _day(rng: random.Random) -> dict[str, str]:
    day = START + timedelta(days=rng.randrange(729))
    return {"since": day.strftime("%Y-%m-%d"),
            "until": (day + timedelta(days=1)).strftime("%Y-%m-%d")}


def run() -> Iterator[dict[str, Any]]:
    from rig.store import Store

    n = int(os.environ.get("BENCH_RUNS", "1000000"))
    n_queries = int(os.environ.get("BENCH_QUERIES", "200"))
    with tempfile.TemporaryDirectory(prefix="bench-store-") as tmp:
        st = Store(Path(tmp) / "sqlite")
        yield from _bench_backend("sqlite", st, n, n_queries)
        url = os.environ.get("BENCH_PG_URL")
        server = None
        if not url:
            from tests.support.pg_server import PgServer, find_bin_dir

            bin_dir = find_bin_dir()
            if bin_dir is None:
                raise RuntimeError("no PostgreSQL binaries (Debian postgresql) and no "
                                   "BENCH_PG_URL")
            server = PgServer(bin_dir)
            server.start()
            url = server.url()
        try:
            pg = Store(url, samples=Path(tmp) / "pg-samples")
            yield from _bench_backend("postgresql", pg, n, n_queries)
            pg.close()
        finally:
            if server is not None:
                server.destroy()
