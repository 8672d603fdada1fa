"""``Store.runs()``: the store's run index as a pandas DataFrame (the production history).

One row per run, newest first, with the keys of ``rig runs --json`` (:meth:`RunInfo.to_dict`)
as columns, ``started_at``/``finished_at`` as UTC timestamps, and the headline metrics of
the run's recorded ``result`` (lost motion, backlash, stiffness ...) as their own columns.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import pandas as pd

from rig.analyse import METRIC_KEYS

if TYPE_CHECKING:
    from rig.store import Store

__all__ = ["RUN_COLUMNS", "runs_frame"]

RUN_COLUMNS = (
    "run_id", "campaign_id", "status", "reason", "unit_serial", "operator", "rig_id",
    "plan_name", "plan_version", "software_version", "started_at", "finished_at",
    "n_samples", "path", "calibration", "calibration_warnings", "metrics", "writer_pid",
    "writer_host", "outcome", "design",
)
"""The keys of one run of ``rig runs --json``, in order."""


def runs_frame(store: Store, *, serial: str | None = None, since: str | None = None,
               outcome: str | None = None, **filters: Any) -> pd.DataFrame:
    """The runs of ``store`` (:meth:`rig.store.Store.list_runs`: ``serial``, ``since`` an
    ISO 8601 UTC date or time, ``outcome`` "ok"/"not_ok"/"incomplete", and its other
    filters: ``campaign_id``, ``status``, ``design``, ``until``, ``limit``)."""
    infos = store.list_runs(serial=serial, since=since, outcome=outcome, **filters)
    rows = []
    for info in infos:
        row = info.to_dict()
        metrics = row.get("metrics") or {}
        uncertainty = metrics.get("uncertainty") or {}
        for key in METRIC_KEYS:
            row[key] = metrics.get(key)
            row[f"{key}_u"] = uncertainty.get(key)
        rows.append(row)
    columns = [*RUN_COLUMNS, *(c for k in METRIC_KEYS for c in (k, f"{k}_u"))]
    frame = pd.DataFrame(rows, columns=columns)
    for key in ("started_at", "finished_at"):
        frame[key] = pd.to_datetime(frame[key], utc=True, format="ISO8601")
    for key in METRIC_KEYS:
        frame[key] = frame[key].astype("float64")
        frame[f"{key}_u"] = frame[f"{key}_u"].astype("float64")
    return frame
