"""``Store.runs()``: the store's run index as a pandas DataFrame (the production history).

One row per run, newest first, with the keys of ``rig runs --json`` (:meth:`RunInfo.to_dict`)
as columns, ``started_at``/``finished_at`` as UTC timestamps, the headline metrics of the
run's recorded ``result`` (lost motion, backlash, stiffness ...) as their own columns, and
``verdict``: the displayed word of ``outcome`` (OK / NOT OK / INCOMPLETE / NO LIMITS,
rig/results/outcome.py).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import pandas as pd

from rig.results.analyse import METRIC_KEYS
from rig.results.outcome import outcome_word, parse_outcome
from rig.store.records import RUN_DICT_KEYS

if TYPE_CHECKING:
    from rig.store import Store

__all__ = ["RUN_COLUMNS", "runs_frame"]

RUN_COLUMNS = (*RUN_DICT_KEYS[:-1], "verdict", RUN_DICT_KEYS[-1])
"""The keys of one run of ``rig runs --json``, in order: :meth:`RunInfo.to_dict`'s with
``verdict`` before the last (``design``)."""


def runs_frame(store: Store, *, serial: str | None = None, since: str | None = None,
               outcome: str | None = None, **filters: Any) -> pd.DataFrame:
    """The runs of ``store`` (:meth:`rig.store.Store.list_runs`: ``serial``, ``since`` an
    ISO 8601 UTC date or time, and its other filters: ``campaign_id``, ``status``,
    ``design``, ``until``, ``limit``). ``outcome``: a code ("ok", "not_ok", "incomplete",
    "no_limits") or its displayed word ("NOT OK", "no limits" ...), any case; ValueError
    naming the valid values for anything else. The filter is on the outcome as shown (an
    older record's "ok" without limits is NO LIMITS: rig/results/outcome.py
    ``recorded_outcome``)."""
    if outcome is None:
        infos = store.list_runs(serial=serial, since=since, **filters)
    else:
        code = parse_outcome(outcome)
        limit = filters.pop("limit", None)
        if limit is not None and (isinstance(limit, bool) or not isinstance(limit, int)
                                  or limit < 1):
            raise ValueError(f"limit must be a positive int, got {limit!r}")
        infos = [i for i in store.list_runs(serial=serial, since=since, **filters)
                 if i.outcome == code][:limit]
    rows = []
    for info in infos:
        row = info.to_dict()
        row["verdict"] = outcome_word(info.outcome) if info.outcome is not None else None
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
