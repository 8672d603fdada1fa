"""A run being recorded by the engine, and the outcome of a finished run.

Rows go to the store's :class:`rig.store.RunRecorder` as they are merged (on disk within its
flush interval); a copy is kept to analyse the run the moment it ends.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from analysis.errors import AnalysisError
from rig.core.errors import RigError
from rig.core.json_files import json_safe
from rig.engine.merge import MergedRow
from rig.results.analyse import METRIC_KEYS, analyse_run
from rig.results.outcome import plant_mismatch, run_outcome
from rig.runformat import Run
from rig.store import RunRecorder

log = logging.getLogger(__name__)


@dataclass
class RunOutcome:
    """A finished run: ``status`` "completed" or "aborted", ``reason``, the analysis object of
    ``rig analyse --json`` (``analysis``; empty if the run could not be analysed) and
    ``result`` (what the store keeps in run.json ``result``)."""

    run_id: str
    label: str
    status: str
    reason: str | None
    path: Path
    test: dict[str, Any]
    analysis: dict[str, Any] = field(default_factory=dict)
    result: dict[str, Any] = field(default_factory=dict)
    outcome: str = "incomplete"
    """"ok", "not_ok" or "incomplete" against ``limits`` (rig/results/outcome.py)."""
    limits: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        """The ``rig analyse --json`` keys plus status, reason, label, position and path."""
        out: dict[str, Any] = {"run_id": self.run_id}
        for key in METRIC_KEYS:
            out[key] = self.analysis.get(key)
        out.update({k: v for k, v in self.analysis.items() if k not in out})
        out.setdefault("uncertainty", {})
        out.setdefault("errors", {})
        out.setdefault("model", None)
        out["status"] = self.status
        out["reason"] = self.reason
        out["label"] = self.label
        out["input_angle_deg"] = self.test.get("input_angle_deg")
        out["amplitude_pct"] = self.test.get("amplitude_pct")
        out["path"] = str(self.path)
        for key in ("torque_zero", "crosscheck_max_diff_Nm", "engine_notes", "samples_dropped",
                    "plant_mismatch"):
            if key in self.result:
                out[key] = self.result[key]
        out["outcome"] = self.outcome
        out["limits"] = self.limits
        return json_safe(out)


class OpenRun:
    """The run being recorded: appends rows to the store, keeps a copy for the analysis."""

    def __init__(self, recorder: RunRecorder, label: str, t0_mono: float,
                 profile: str | None = None, limits: dict[str, Any] | None = None) -> None:
        self.recorder = recorder
        self.limits = limits
        self.label = label
        self.t0 = t0_mono
        self.profile = profile
        self.columns = list(recorder.columns)
        self.data: dict[str, list[float]] = {c: [] for c in self.columns}
        self.notes: list[str] = []
        self.torque_zero: dict[str, float] = {}
        before = recorder.meta.get("test", {}).get("torque_zero_before_Nm")
        if before is not None:
            self.torque_zero["before"] = float(before)
        self.crosscheck_max_diff_Nm = 0.0
        self.last_t_mono = -math.inf
        self._last_t_s = -math.inf
        self.recording = True
        self.samples_dropped = 0
        """Encoder samples lost during this run (driver queues, merge), set by the engine."""

    def note(self, text: str) -> None:
        self.notes.append(text)

    def note_crosscheck(self, diff_Nm: float) -> None:
        self.crosscheck_max_diff_Nm = max(self.crosscheck_max_diff_Nm, diff_Nm)

    def append(self, rows: list[MergedRow], setpoint_Nm: float, step: int,
               sample_window: int, direction: int = 0) -> None:
        """Append merged rows taken at or after the run's start (t_s ascending), while
        ``recording``."""
        if not self.recording:
            return
        for row in rows:
            t_s = row.t_mono_s - self.t0
            if t_s < 0 or t_s <= self._last_t_s:
                continue
            values = {
                "t_s": t_s, "torque_Nm": row.torque_Nm,
                "output_angle_deg": row.output_angle_deg,
                "input_angle_deg": row.input_angle_deg, "temperature_C": row.temperature_C,
                "torque_command_Nm": setpoint_Nm, "step": float(step),
                "sample_window": float(sample_window), "direction": float(direction),
            }
            record = [values[c] for c in self.columns]
            self.recorder.append([None if (isinstance(v, float) and math.isnan(v)) else v
                                  for v in record])
            for c, v in zip(self.columns, record, strict=True):
                self.data[c].append(v)
            self._last_t_s = t_s
            self.last_t_mono = row.t_mono_s

    def _base_result(self) -> dict[str, Any]:
        result: dict[str, Any] = {"torque_zero": dict(self.torque_zero),
                                  "crosscheck_max_diff_Nm": self.crosscheck_max_diff_Nm,
                                  "samples_dropped": self.samples_dropped}
        mismatch = plant_mismatch(self.recorder.meta)
        if mismatch is not None:  # the simulated rig measured another kind of unit
            result["plant_mismatch"] = mismatch
        if self.notes:
            result["engine_notes"] = list(self.notes)
        return result

    def _run(self) -> Run:
        meta = {k: v for k, v in self.recorder.meta.items()}
        data = {c: np.asarray(v, dtype=float) for c, v in self.data.items()}
        return Run(meta=meta, columns=list(self.columns), data=data, path=self.recorder.path)

    def _verdict(self, status: str, reason: str | None, result: dict[str, Any]) -> str:
        test = self.recorder.meta.get("test", {})
        return run_outcome({"status": status, "reason": reason, "label": self.label,
                            "test": test, "result": result}, self.limits)[0]

    def _outcome(self, status: str, reason: str | None, analysis: dict[str, Any],
                 result: dict[str, Any], verdict: str) -> RunOutcome:
        return RunOutcome(self.recorder.run_id, self.label, status, reason, self.recorder.path,
                          dict(self.recorder.meta.get("test", {})), analysis, result,
                          outcome=verdict, limits=self.limits)

    def finish_completed(self) -> RunOutcome:
        """Analyse the run and close it as completed (metrics in run.json ``result``)."""
        result = self._base_result()
        analysis: dict[str, Any] = {}
        test = self.recorder.meta.get("test", {})
        if test.get("kind") == "transmission_error":
            return self._finish_te(result, test)
        try:
            if len(self.data["t_s"]) < 10:
                raise RigError(f"only {len(self.data['t_s'])} samples recorded")
            analysis = json_safe(analyse_run(self._run(), profile=self.profile).to_dict())
            for key in METRIC_KEYS:
                result[key] = analysis.get(key)
            result["uncertainty"] = analysis.get("uncertainty", {})
            result["model"] = analysis.get("model")
            if analysis.get("encoder_faults"):  # no verdict on them (issue 33 item 1)
                result["encoder_faults"] = analysis["encoder_faults"]
        except (AnalysisError, RigError, ValueError) as exc:
            result["analysis_error"] = str(exc)
            log.warning("run %s: not analysed: %s", self.recorder.run_id, exc)
        verdict = self._verdict("completed", None, result)
        self.recorder.finish("completed", result=json_safe(result), extra={"outcome": verdict})
        return self._outcome("completed", None, analysis, result, verdict)

    def _finish_te(self, result: dict[str, Any], test: dict[str, Any]) -> RunOutcome:
        """A transmission error run: the raw TE figures (rig/results/te_curve.py) under
        ``result.te_raw``, and the analysis of rig/results/te.py (metrics, uncertainties, the model;
        run-format.md's ``result``); closed as completed."""
        from rig.results.te import analyse_te_run
        from rig.results.te_curve import te_summary

        analysis: dict[str, Any] = {}
        try:
            data = {c: np.asarray(v, dtype=float) for c, v in self.data.items()}
            if "direction" not in data or "input_angle_deg" not in data:
                raise RigError("a transmission error run needs input_angle_deg and direction")
            raw = json_safe(te_summary(data, float(test["ratio"])))
            result["te_raw"] = raw
            analysis["te_raw"] = raw
            item = analyse_te_run(self._run())
            record = item.result_record()
            result.update(record)
            metrics = item.metrics_dict()
            analysis.update(json_safe({**metrics, "uncertainty": record["uncertainty"],
                                       "model": record["model"],
                                       "comparison": item.comparison,
                                       "encoder_eccentricity": record["encoder_eccentricity"],
                                       "test_kind": "transmission_error"}))
        except (AnalysisError, RigError, ValueError, KeyError) as exc:
            result["analysis_error"] = str(exc)
            log.warning("run %s: not analysed: %s", self.recorder.run_id, exc)
        verdict = self._verdict("completed", None, result)
        self.recorder.finish("completed", result=json_safe(result), extra={"outcome": verdict})
        return self._outcome("completed", None, analysis, result, verdict)

    def finish_aborted(self, reason: str) -> RunOutcome:
        """Close the run as aborted with ``reason``; every sample recorded is kept."""
        result = json_safe(self._base_result())
        self.recorder.finish("aborted", reason=reason, result=result,
                             extra={"outcome": "incomplete"})
        return self._outcome("aborted", reason, {}, result, "incomplete")
