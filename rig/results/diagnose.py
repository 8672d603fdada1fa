"""``rig diagnose`` service: read a campaign folder, diagnose the sim-to-real gap, write reports.

Only what a campaign folder says reaches the diagnosis: each run's ``unit``, ``test``,
``started_at`` and samples (:func:`run_input`). Anything else in run.json (a generator's labels,
notes) is never read, so a campaign made by a simulator and the same campaign with those keys
stripped give the same verdict (tests/test_diagnosis_blind.py).
"""

from __future__ import annotations

import json
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from analysis.diagnosis import ALPHA, Diagnosis, diagnose
from analysis.diagnosis.data import RunInput
from analysis.errors import AnalysisError
from analysis.loop import twist_arcmin
from rig.core.errors import RigError
from rig.core.json_files import finite_for_json
from rig.runformat import Campaign, Run, read_run_or_campaign


def run_input(run: Run) -> RunInput:
    """The diagnosis' view of a run: unit, test conditions and samples, nothing else."""
    test = run.test
    rated = test.get("rated_torque_Nm")
    if rated is None:
        rated = float(np.percentile(np.abs(run.torque_Nm), 99.5))
    ratio = test.get("ratio")
    if run.input_angle_deg is not None and ratio:
        twist = twist_arcmin(run.output_angle_deg, run.input_angle_deg, float(ratio))
    else:
        twist = twist_arcmin(run.output_angle_deg)
    angle = test.get("input_angle_deg")
    if angle is None and run.input_angle_deg is not None:
        col = run.input_angle_deg
        if np.isfinite(col).any():
            angle = float(np.nanmedian(col))
    temperature = run.temperature_C
    if temperature is None and test.get("temperature_C") is not None:
        temperature = np.full(run.n_samples, float(test["temperature_C"]))
    start = test.get("start_flank", -1)
    full_scale = run.sensors.get("torque_full_scale_Nm")
    zeros = (run.meta.get("result") or {}).get("torque_zero") or {}
    if not isinstance(zeros, dict):
        zeros = {}
    readings = [zeros.get("before", test.get("torque_zero_before_Nm")), zeros.get("after")]
    return RunInput(
        run_id=run.run_id, t_s=run.t_s, torque_Nm=run.torque_Nm, twist_arcmin=twist,
        rated_torque_Nm=float(rated), unit=dict(run.unit),
        input_angle_deg=None if angle is None else float(angle),
        temperature_C=temperature, start_flank=1 if start == 1 else -1,
        torque_full_scale_Nm=None if full_scale is None else float(full_scale),
        zero_readings_Nm=tuple(float(z) for z in readings
                               if isinstance(z, (int, float)) and not isinstance(z, bool)),
        started_s=started_seconds(run.meta.get("started_at")),
    )


def started_seconds(started_at: Any) -> float | None:
    """run.json ``started_at`` (ISO 8601, UTC) as POSIX seconds; None when absent or not a
    time."""
    if not isinstance(started_at, str):
        return None
    try:
        when = datetime.fromisoformat(started_at.replace("Z", "+00:00"))
    except ValueError:
        return None
    if when.tzinfo is None:
        when = when.replace(tzinfo=UTC)
    return when.timestamp()


def diagnose_campaign(campaign: Campaign, alpha: float = ALPHA) -> Diagnosis:
    """Diagnose a campaign already read; AnalysisError becomes RigError naming the campaign.
    ``alpha``: level of the calibrated decisions (analysis.diagnosis.calibration)."""
    from rig.core.blas import limit_blas_threads

    try:
        # one BLAS thread: the fits are many small least squares, which threads only slow
        # down (13.0 s with a thread per core, 2.7 s with one, a 14-run campaign, 2 cores)
        with limit_blas_threads():
            return diagnose([run_input(r) for r in campaign.runs], alpha=alpha)
    except AnalysisError as exc:
        raise RigError(f"campaign {campaign.path or campaign.name}: {exc}") from exc


def diagnose_path(path: str | Path, alpha: float = ALPHA) -> tuple[Campaign, Diagnosis]:
    """Read a campaign (or one run) folder and diagnose it."""
    campaign = read_run_or_campaign(path)
    return campaign, diagnose_campaign(campaign, alpha)


def report_dict(campaign: Campaign, diagnosis: Diagnosis) -> dict[str, Any]:
    """The ``rig-diagnosis/1`` report with the campaign named."""
    out = {"format": "rig-diagnosis/1", "campaign": campaign.name}
    out.update(diagnosis.to_dict())
    return out


def write_json(report: dict[str, Any], path: str | Path) -> Path:
    """Write the report as JSON (NaN/inf are not JSON: written as null)."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(finite_for_json(report), indent=2, allow_nan=False)
    p.write_text(text + "\n", encoding="utf-8")
    return p
