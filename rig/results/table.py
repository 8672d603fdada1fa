"""The tidy results table of the Python API: one row per run (``rig.open(...).results()``).

A row holds the run's conditions (label, input angle in deg, amplitude in % of rated,
temperature in °C, repeat), every loop metric of ``rig analyse`` with its standard
uncertainty (``<metric>`` and ``<metric>_u``), the reference nominal model's values
(``model_<metric>``), the limits in force, the recorded outcome and its displayed word
(``verdict``: OK / NOT OK / INCOMPLETE / NO LIMITS, rig/results/outcome.py). Metrics are computed
now from the samples (:func:`rig.results.analyse.analyse_run`, the ``rig analyse`` service), so a
run read from any rig-run/1 folder gets the same columns. A metric that cannot be negative and
came out below zero (no measurement, rig/results/outcome.py ``below_zero_text``) is left empty
(NaN) and ``error`` says so, with the likely cause.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from rig.core.errors import RigError
from rig.core.json_files import finite_for_json
from rig.results.analyse import (
    METRIC_KEYS,
    RunAnalysis,
    resolve_profile,
    run_twist_arcmin,
)
from rig.results.outcome import (
    LIMIT_KEYS,
    below_zero_keys,
    below_zero_note,
    outcome_word,
    recorded_outcome,
    run_outcome,
)
from rig.runformat import Campaign, Run

__all__ = [
    "CONDITION_COLUMNS", "COUNT_COLUMNS", "LIMIT_COLUMNS", "MODEL_KEYS", "TEXT_COLUMNS",
    "result_row", "results_frame", "rows_frame", "run_limits", "run_twist_arcmin",
]

CONDITION_COLUMNS = ("run_id", "label", "input_angle_deg", "amplitude_pct", "temperature_C",
                     "repeat")
"""The first columns of a results row: what the run was measured at."""
MODEL_KEYS = ("lost_motion_arcmin", "backlash_arcmin", "stiffness_Nm_per_arcmin",
              "play_arcmin")
"""The model values of ``rig analyse --json`` ``model``, as ``model_<key>`` columns."""
LIMIT_COLUMNS = tuple(LIMIT_KEYS)
"""The limit keys of run.json / campaign.json (None: not checked)."""


def _number(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) \
        else None


def _conditions(run: Run) -> dict[str, Any]:
    test = run.test
    temperature = _number(test.get("temperature_C"))
    column = run.temperature_C
    if temperature is None and column is not None and np.isfinite(column).any():
        temperature = float(np.nanmedian(column))
    repeat = test.get("repeat")
    return {
        "run_id": run.run_id,
        "label": run.meta.get("label") or run.run_id,
        "input_angle_deg": _number(test.get("input_angle_deg")),
        "amplitude_pct": _number(test.get("amplitude_pct")),
        "temperature_C": temperature,
        "repeat": repeat if isinstance(repeat, int) and not isinstance(repeat, bool) else None,
    }


def run_limits(run: Run, campaign_meta: dict[str, Any] | None = None) -> dict[str, Any]:
    """The limits in force for a run: its run.json ``limits``, else its campaign's."""
    limits = run.meta.get("limits")
    if not isinstance(limits, dict):
        limits = (campaign_meta or {}).get("limits")
    limits = limits if isinstance(limits, dict) else {}
    return {key: _number(limits.get(key)) for key in LIMIT_COLUMNS}


def result_row(run: Run, analysis: RunAnalysis | None, *,
               campaign_meta: dict[str, Any] | None = None,
               error: str | None = None) -> dict[str, Any]:
    """One tidy row (see the module doc). ``analysis`` None: the run could not be analysed
    (``error`` says why); its metric columns are then missing (NaN in the table)."""
    from rig.results.te import TERunAnalysis, is_te_run

    if isinstance(analysis, TERunAnalysis) or (analysis is None and is_te_run(run)):
        return te_result_row(run, analysis, campaign_meta=campaign_meta, error=error)
    row = _conditions(run)
    d = finite_for_json(analysis.to_dict()) if analysis is not None else {}
    uncertainty = d.get("uncertainty") or {}
    keys = list(METRIC_KEYS) + [k for k in (d.get("units") or {}) if k not in METRIC_KEYS]
    keys += [k for k in uncertainty if k not in keys]
    for key in keys if analysis is not None else METRIC_KEYS:
        row[key] = _number(d.get(key))
        row[f"{key}_u"] = _number(uncertainty.get(key))
    model = d.get("model") or {}
    for key in MODEL_KEYS:
        row[f"model_{key}"] = _number(model.get(key))
    for key in ("profile", "lost_motion_pct", "rated_torque_Nm", "n_samples", "n_cycles"):
        row[key] = d.get(key)
    limits = run_limits(run, campaign_meta)
    row.update(limits)
    row["status"] = run.meta.get("status")
    below = below_zero_note(d) if analysis is not None else None
    for key in below_zero_keys(d) if analysis is not None else ():
        row[key] = row[f"{key}_u"] = None  # no measurement: never shown as a figure
    outcome = run.meta.get("outcome")
    if outcome is None and analysis is not None:  # none recorded: judged on today's analysis
        flat = {**d, "status": run.meta.get("status", "completed"), "label": row["label"],
                "amplitude_pct": row["amplitude_pct"]}
        outcome = run_outcome(flat, limits)[0]
    else:  # as recorded, read as every view reads it (rig/results/outcome.py)
        outcome = recorded_outcome(run.meta, limits)
    return _closed_row(row, run, outcome, d, error, below)


def _closed_row(row: dict[str, Any], run: Run, outcome: Any, d: dict[str, Any],
                error: str | None, below: str | None = None) -> dict[str, Any]:
    """A row's outcome and its word, the analysis's errors (or ``error``; ``below``: which
    metrics came out below zero, rig/results/outcome.py ``below_zero_note``) and the run's
    path."""
    row["outcome"] = outcome if isinstance(outcome, str) else None
    row["verdict"] = None if row["outcome"] is None else outcome_word(row["outcome"])
    problems = [f"{k}: {v}" for k, v in (d.get("errors") or {}).items()]
    problems += [below] if below else []
    row["error"] = error or ("; ".join(problems) or None)
    row["path"] = None if run.path is None else str(run.path)
    return row


def te_result_row(run: Run, analysis: Any, *, campaign_meta: dict[str, Any] | None = None,
                  error: str | None = None) -> dict[str, Any]:
    """The tidy row of a transmission error run: its TE metrics with ``_u``, the model's
    (``model_<metric>``), the limits, the outcome (as :func:`result_row`)."""
    from analysis.transmission import METRIC_KEYS as TE_KEYS

    row = _conditions(run)
    row["test_kind"] = "transmission_error"
    d = analysis.to_dict() if analysis is not None else {}
    metrics, model = d.get("metrics") or {}, d.get("model") or {}
    for key in TE_KEYS:
        row[key] = _number(metrics.get(key))
        row[f"{key}_u"] = _number(metrics.get(f"{key}_u"))
    for key in TE_KEYS:
        row[f"model_{key}"] = _number(model.get(key))
    row["n_samples"] = d.get("n_samples", run.n_samples)
    limits = run_limits(run, campaign_meta)
    row.update(limits)
    row["status"] = run.meta.get("status")
    if run.meta.get("outcome") is None and analysis is not None:
        flat = {**{k: row[k] for k in TE_KEYS}, "test": run.test,
                "status": run.meta.get("status", "completed"), "label": row["label"]}
        outcome = run_outcome(flat, limits)[0]
    else:
        outcome = recorded_outcome(run.meta, limits)
    return _closed_row(row, run, outcome, d, error)


TEXT_COLUMNS = ("run_id", "label", "test_kind", "profile", "status", "outcome", "verdict",
                "error", "path")
COUNT_COLUMNS = ("repeat", "n_samples", "n_cycles")


def rows_frame(rows: list[dict[str, Any]]) -> pd.DataFrame:
    """The rows as a DataFrame, columns in the order they first appear: text columns as
    objects (None if unknown), counts as nullable integers, every other column float64."""
    columns: list[str] = []
    for row in rows:
        columns += [k for k in row if k not in columns]
    frame = pd.DataFrame(rows, columns=columns)
    for col in columns:
        if col in COUNT_COLUMNS:
            frame[col] = frame[col].astype("Int64")
        elif col not in TEXT_COLUMNS:
            frame[col] = frame[col].astype("float64")
    return frame


def results_frame(campaign: Campaign, **options: Any) -> pd.DataFrame:
    """One row per run of ``campaign`` (a run that cannot be analysed gets a row with its
    ``error`` and no metrics). ``options``: those of :func:`rig.results.analyse.analyse_run`."""
    resolve_profile(options.get("profile"), options.get("percent"))  # bad options: raise now
    rows = []
    for run in campaign.runs:
        try:
            from rig.results.any_run import analyse_any_run

            analysis, error = analyse_any_run(run, **options), None
        except RigError as exc:
            analysis, error = None, str(exc)
        rows.append(result_row(run, analysis, campaign_meta=campaign.meta, error=error))
    return rows_frame(rows)
