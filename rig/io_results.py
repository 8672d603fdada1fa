"""The tidy results table of a campaign (``rig export CAMPAIGN``): one row per run.

Columns: ``run_id``, ``label``, the conditions (``input_angle_deg`` in deg, ``amplitude_pct``
in % of rated, ``temperature_C`` in °C, ``repeat``), each metric of ``rig analyse`` with its
standard uncertainty (``<metric>``, ``<metric>_u``), the reference nominal model's values
(``model_<metric>``), the limits in force, ``status`` and ``outcome``. The metrics are
computed from the samples now (:func:`rig.analyse.analyse_run`), so a campaign from any
rig-run/1 folder gets the same columns; a run that cannot be analysed keeps its row, with
empty metrics and the reason in ``error``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from analysis.errors import AnalysisError
from rig.analyse import METRIC_KEYS, analyse_run
from rig.errors import RigError
from rig.json_files import finite_for_json
from rig.outcome import LIMIT_KEYS, run_outcome
from rig.runformat import Campaign, Run

__all__ = ["TEXT_COLUMNS", "results_table", "run_row"]

MODEL_KEYS = ("lost_motion_arcmin", "backlash_arcmin", "stiffness_Nm_per_arcmin",
              "play_arcmin")
TEXT_COLUMNS = ("run_id", "label", "status", "outcome", "error")
"""The columns holding text; ``repeat`` is a whole number; every other column is a float
(NaN: unknown)."""


def _number(value: Any) -> float:
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    return float(value) if ok else float("nan")


def _temperature(run: Run) -> float:
    value = _number(run.test.get("temperature_C"))
    column = run.temperature_C
    if np.isnan(value) and column is not None and np.isfinite(column).any():
        value = float(np.nanmedian(column))
    return value


def run_row(run: Run, campaign_meta: dict[str, Any] | None = None) -> dict[str, Any]:
    """One row of the table (see the module doc)."""
    test = run.test
    row: dict[str, Any] = {
        "run_id": run.run_id,
        "label": run.meta.get("label") or run.run_id,
        "input_angle_deg": _number(test.get("input_angle_deg")),
        "amplitude_pct": _number(test.get("amplitude_pct")),
        "temperature_C": _temperature(run),
        "repeat": _number(test.get("repeat")),
    }
    error = None
    try:
        d = finite_for_json(analyse_run(run).to_dict())
    except (RigError, AnalysisError) as exc:
        d, error = {}, str(exc)
    uncertainty = d.get("uncertainty") or {}
    for key in METRIC_KEYS:
        row[key] = _number(d.get(key))
        row[f"{key}_u"] = _number(uncertainty.get(key))
    model = d.get("model") or {}
    for key in MODEL_KEYS:
        row[f"model_{key}"] = _number(model.get(key))
    limits = run.meta.get("limits")
    if not isinstance(limits, dict):
        limits = (campaign_meta or {}).get("limits")
    limits = limits if isinstance(limits, dict) else {}
    for key in LIMIT_KEYS:
        row[key] = _number(limits.get(key))
    status = run.meta.get("status", "completed")
    row["status"] = status
    outcome = run.meta.get("outcome")
    if not isinstance(outcome, str) and d and any(limits.get(k) is not None
                                                   for k in LIMIT_KEYS):
        outcome = run_outcome({**d, "status": status, "label": row["label"],
                               "test": test}, limits)[0]
    row["outcome"] = outcome if isinstance(outcome, str) else None
    problems = [f"{k}: {v}" for k, v in (d.get("errors") or {}).items()]
    row["error"] = error or ("; ".join(problems) or None)
    return row


def results_table(campaign: Campaign) -> pd.DataFrame:
    """One row per run of ``campaign``, in its order."""
    rows = [run_row(run, campaign.meta) for run in campaign.runs]
    frame = pd.DataFrame(rows)
    for name in frame.columns:
        kind = object if name in TEXT_COLUMNS else "Int64" if name == "repeat" else "float64"
        frame[name] = frame[name].astype(kind)
    return frame
