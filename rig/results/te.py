"""Analyse transmission error runs (``test.kind = "transmission_error"``): the application
service behind ``rig analyse`` of a TE run, ``run.te()``, the certificate's TE section and what
the rig records in run.json ``result``.

It reads what the run says about itself (``test.ratio``, the encoders' counts, the unit's
geometry, the output encoder's calibrated eccentricity) and calls the pure numerics of
:mod:`analysis.transmission` (docs/transmission-error.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from analysis.errors import AnalysisError
from analysis.transmission import METRIC_KEYS, TEResult, analyse_te
from analysis.transmission.compare import compare
from analysis.transmission.curve import direction_curve
from analysis.transmission.eccentricity import EncoderEccentricity, reversal
from analysis.transmission.model import TEPrediction, kinematics_for_unit, predict
from analysis.transmission.orders import fit_orders, standard_orders
from rig.core.errors import RigError
from rig.core.json_files import finite_for_json
from rig.runformat import Run

TE_KIND = "transmission_error"
ECCENTRICITY_KEYS = ("eccentricity_arcsec", "eccentricity_phase_deg", "eccentricity_u_arcsec")
"""The output encoder's calibration keys (rig configuration ``[calibration.encoder]``, run.json
``calibration`` entry of sensor ``encoder``): its mounting eccentricity by reversal."""
MIN_TE_SAMPLES = 100


def is_te_run(run: Run | dict[str, Any]) -> bool:
    """Is this a transmission error run (run.json ``test.kind``)?"""
    meta = run.meta if isinstance(run, Run) else run
    test = meta.get("test") if isinstance(meta, dict) else None
    return isinstance(test, dict) and test.get("kind") == TE_KIND


def _where(run: Run) -> str:
    return str(run.path / "run.json") if run.path is not None else run.run_id


def encoder_eccentricity_of(run: Run) -> EncoderEccentricity | None:
    """The output encoder's calibrated eccentricity recorded with the run (its
    ``calibration`` entry of sensor ``encoder``), None when there is none."""
    for entry in run.meta.get("calibration") or []:
        if isinstance(entry, dict) and entry.get("sensor") == "encoder" and \
                entry.get("eccentricity_arcsec") is not None:
            try:
                values = [float(entry.get(k) or 0.0) for k in ECCENTRICITY_KEYS]
            except (TypeError, ValueError):
                raise RigError(f"{_where(run)}: calibration of encoder: eccentricity keys must "
                               "be numbers") from None
            source = f"calibration {entry.get('id', '?')} ({entry.get('certificate', '?')})"
            return EncoderEccentricity(*values, source=source)
    return None


def _number(run: Run, where: dict[str, Any], key: str, *, required: bool = True
            ) -> float | None:
    value = where.get(key)
    if value is None:
        if required:
            raise RigError(f"{_where(run)}: test.{key} missing: a transmission error run needs it")
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise RigError(f"{_where(run)}: {key} must be a finite number, got {value!r}")
    return float(value)


@dataclass
class TERunAnalysis:
    """A TE run's metrics, model and comparison (``rig analyse`` of a TE run)."""

    run: Run
    result: TEResult
    prediction: TEPrediction | None
    comparison: dict[str, Any] | None
    assumptions: list[str] = field(default_factory=list)

    def metrics_dict(self) -> dict[str, Any]:
        """The metrics, each with ``<name>_u`` (run-format.md; ``--json`` ``metrics``)."""
        out: dict[str, Any] = {}
        for key in METRIC_KEYS:
            out[key] = self.result.metrics.get(key)
            out[f"{key}_u"] = self.result.uncertainty.get(key)
        out["te_orders"] = self.result.orders_list()
        out["te_orders_u"] = self.result.orders_u_list()
        return out

    def to_dict(self) -> dict[str, Any]:
        """The JSON object of ``rig analyse --json`` for this run."""
        test = self.run.test
        return finite_for_json({
            "run_id": self.run.run_id,
            "test_kind": TE_KIND,
            "metrics": self.metrics_dict(),
            "uncertainty": dict(self.result.uncertainty),
            "model": None if self.prediction is None else self.prediction.to_dict(),
            "comparison": self.comparison,
            "encoder_eccentricity": self.result.encoder_eccentricity,
            "ratio": test.get("ratio"),
            "brake_torque_Nm": test.get("brake_torque_Nm"),
            "input_speed_rpm": test.get("input_speed_rpm"),
            "output_teeth": self.result.output_teeth,
            "grid_points_per_rev": self.result.grid_points,
            "te_evaluation": dict(self.result.evaluation),
            "revolutions": {c.name: c.revolutions for c in self.result.curves.values()},
            "n_samples": self.run.n_samples,
            "errors": dict(self.result.errors),
            "assumptions": list(self.assumptions) + list(self.result.notes),
            "notes": list(self.run.notes) + [n for n in self.result.notes
                                             if "dropped" in n or "hole" in n
                                             or "left out" in n or "stalled" in n],
        })

    def result_record(self) -> dict[str, Any]:
        """run.json ``result`` of a TE run (run-format.md): the metrics flat, ``uncertainty``,
        ``model`` (the same names), ``encoder_eccentricity``."""
        record: dict[str, Any] = {k: self.result.metrics.get(k) for k in METRIC_KEYS}
        record["te_orders"] = self.result.orders_list()
        record["uncertainty"] = {**self.result.uncertainty,
                                 "te_orders": self.result.orders_u_list()}
        record["model"] = None if self.prediction is None else self.prediction.to_dict()
        record["encoder_eccentricity"] = self.result.encoder_eccentricity
        record["errors"] = dict(self.result.errors)
        record["te_evaluation"] = dict(self.result.evaluation)
        record["notes"] = list(self.result.notes)
        return finite_for_json(record)

    def te_frame(self) -> pd.DataFrame:
        """TE against the output angle (deg), revolution-averaged, per direction (arcsec)."""
        fwd, rev = self.result.curves[1], self.result.curves[-1]
        return pd.DataFrame({"output_angle_deg": fwd.grid_deg,
                             "te_forward_arcsec": fwd.mean_arcsec,
                             "te_reverse_arcsec": rev.mean_arcsec})


TE_COLUMN = "te_arcsec"
"""The per-sample TE column of an exported TE run (``rig export``)."""


def sample_te_arcsec(run: Run) -> np.ndarray:
    """Each sample's TE (arcsec): ``3600 (output - input / ratio) - c_d`` with ``c_d`` its
    direction's mean over the output-angle grid (run-format.md); NaN on the rows of no
    direction (stopping, turning round)."""
    item = analyse_te_run(run, with_model=False)
    out, inp, direction, _ = _columns(run)
    if direction is None:
        from analysis.transmission.analyse import directions_from_input
        direction = directions_from_input(inp)
    te = 3600.0 * (out - inp / float(run.test["ratio"]))
    ecc = encoder_eccentricity_of(run)
    if ecc is not None:
        te = te - ecc.arcsec(out)
    values = np.full(te.shape, np.nan)
    for code, curve in item.result.curves.items():
        m = direction == code
        values[m] = te[m] - curve.offset_arcsec
    return values


def _columns(run: Run) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, list[str]]:
    notes = []
    if run.input_angle_deg is None:
        raise RigError(f"{_where(run)}: samples.csv has no input_angle_deg: a transmission "
                       "error run records both encoders")
    direction = run.data.get("direction")
    if not isinstance(direction, np.ndarray):
        direction = None
        notes.append("no direction column: taken from the sign of the input's motion")
    return run.output_angle_deg, run.input_angle_deg, direction, notes


def analyse_te_run(run: Run, *, with_model: bool = True, model_samples: int | None = None
                   ) -> TERunAnalysis:
    """TE metrics of a run and the seeds' prediction for its unit beside them."""
    if not is_te_run(run):
        raise RigError(f"{_where(run)}: test.kind is not {TE_KIND!r}")
    if run.n_samples < MIN_TE_SAMPLES:
        raise RigError(f"{_where(run)}: {run.n_samples} samples; a transmission error run "
                       f"needs at least {MIN_TE_SAMPLES}")
    test, sensors = run.test, run.sensors
    ratio = _number(run, test, "ratio")
    if ratio == 0:
        raise RigError(f"{_where(run)}: test.ratio must not be 0")
    out, inp, direction, notes = _columns(run)
    unit = {k: v for k, v in (run.unit or {}).items() if k not in ("serial", "design", "name")}
    try:
        kin = kinematics_for_unit(unit, float(ratio))
    except AnalysisError as exc:
        kin = kinematics_for_unit({}, float(ratio))
        notes.append(f"unit geometry not usable for the orders: {exc}")
    ecc = encoder_eccentricity_of(run)
    bound = sensors.get("encoder_eccentricity_max_arcsec")
    counts_out = sensors.get("encoder_counts_per_rev")
    counts_in = sensors.get("input_encoder_counts_per_rev")
    for key, value in (("encoder_counts_per_rev", counts_out),
                       ("input_encoder_counts_per_rev", counts_in)):
        if not value:
            notes.append(f"sensors.{key} unknown: that encoder's resolution is not in the "
                         "uncertainty")
    try:
        result = analyse_te(out, inp, direction, kin,
                            output_counts_per_rev=float(counts_out) if counts_out else None,
                            input_counts_per_rev=float(counts_in) if counts_in else None,
                            encoder_eccentricity=ecc,
                            eccentricity_bound_arcsec=float(bound) if bound else None)
    except AnalysisError as exc:
        raise RigError(f"{_where(run)}: {exc}") from None
    prediction = comparison = None
    if with_model and unit:
        try:
            kwargs: dict[str, Any] = {"ratio": ratio,
                                      "brake_torque_Nm": test.get("brake_torque_Nm")}
            if model_samples:
                kwargs["samples"] = model_samples
            prediction = predict(unit, **kwargs)
            comparison = compare(result, prediction)
        except (AnalysisError, KeyError, TypeError, ValueError) as exc:
            notes.append(f"no model prediction: {exc}")
    elif with_model:
        notes.append("run.json has no unit data: no model prediction")
    return TERunAnalysis(run, result, prediction, comparison, notes)


def _two_measurements(run_a: Run, run_b: Run) -> None:
    """Refuse one run given twice (the same folder, run id or samples): the reversal needs a
    second measurement, with the coupling indexed by 180 deg."""
    same_folder = (run_a.path is not None and run_b.path is not None
                   and run_a.path.resolve() == run_b.path.resolve())
    same_samples = run_a.n_samples == run_b.n_samples and all(
        np.array_equal(run_a.data[k], run_b.data.get(k), equal_nan=True) for k in run_a.data)
    if same_folder or run_a.run_id == run_b.run_id or same_samples:
        raise RigError(f"{_where(run_b)}: the same run as {_where(run_a)}; the reversal needs "
                       "a second TE run of the unit with the encoder's coupling indexed by "
                       "180 deg")


INDEX_TOLERANCE_DEG = 5.0
"""How far from 180 deg the second run's coupling index may be: an error of ``d`` deg
leaves ``sin(d)`` of the unit's order 1 in the encoder's term (9 % at 5 deg)."""


def _indexed_by_half_turn(run_a: Run, run_b: Run, indexed_by_deg: float | None) -> float:
    """The index (deg) of run B's coupling against run A's: from their
    ``test.coupling_index_deg``, else as stated (``indexed_by_deg``, ``rig te-calibrate
    --indexed-by``). RigError unless it is 180 +- :data:`INDEX_TOLERANCE_DEG` deg."""
    recorded = [run.test.get("coupling_index_deg") for run in (run_a, run_b)]
    if all(isinstance(v, (int, float)) and math.isfinite(v) for v in recorded):
        index = (float(recorded[1]) - float(recorded[0])) % 360.0
        source = (f"{_where(run_b)} records its coupling at {float(recorded[1]):g} deg, "
                  f"{_where(run_a)} at {float(recorded[0]):g} deg")
    elif indexed_by_deg is not None:
        index = float(indexed_by_deg) % 360.0
        source = f"--indexed-by {indexed_by_deg:g}"
    else:
        missing = _where(run_a if not isinstance(recorded[0], (int, float)) else run_b)
        raise RigError(f"{missing}: records no coupling index (test.coupling_index_deg); the "
                       "reversal needs the second run's coupling indexed by 180 deg: measure "
                       "with --coupling-index-deg, or state it with --indexed-by 180")
    if abs(index - 180.0) > INDEX_TOLERANCE_DEG:
        raise RigError(f"{source}: indexed by {index:g} deg; the reversal needs 180 +- "
                       f"{INDEX_TOLERANCE_DEG:g} deg")
    return index


def reversal_calibration(run_a: Run, run_b: Run, *, indexed_by_deg: float | None = None
                         ) -> dict[str, float]:
    """The output encoder's mounting eccentricity from two TE runs of one unit, the second
    with the coupling indexed by 180 deg (:func:`analysis.transmission.eccentricity.reversal`):
    the ``[calibration.encoder]`` keys :data:`ECCENTRICITY_KEYS` and ``unit_order1_arcsec``
    (the unit's own once-per-output-turn TE), from both directions' order-1 fits averaged.
    Run B's coupling must be indexed by 180 deg against run A's (recorded in both runs'
    ``test.coupling_index_deg``, or stated as ``indexed_by_deg``)."""
    _two_measurements(run_a, run_b)
    _indexed_by_half_turn(run_a, run_b, indexed_by_deg)
    phasors = []
    for run in (run_a, run_b):
        if not is_te_run(run):
            raise RigError(f"{_where(run)}: test.kind is not {TE_KIND!r}")
        out, inp, direction, _ = _columns(run)
        ratio = float(_number(run, run.test, "ratio") or 0.0)
        d = direction if direction is not None else np.sign(np.gradient(inp))
        fits = []
        order1 = [o for o in standard_orders(ratio, crank_per_input=None, mesh_per_input=None)
                  if o.per == "output_rev"]
        for code in (1, -1):
            mask = d == code
            te_all = 3600.0 * (out - inp / ratio)
            curve = direction_curve(out[mask], te_all[mask], code, 3600)
            lo, hi = curve.span_deg
            m = mask & (out >= lo) & (out < hi)  # whole revolutions: no leakage
            te = te_all[m]
            f, _ = fit_orders(out[m], inp[m], te, order1, ratio=ratio)
            fits.append(f[0])
        z = np.mean([f.phasor() for f in fits])
        u = float(np.hypot(*[f.amplitude_u_arcsec for f in fits]) / 2.0)
        phasors.append((complex(z), u))
    ecc, unit = reversal(phasors[0][0], phasors[0][1], phasors[1][0], phasors[1][1])
    return {"eccentricity_arcsec": ecc.amplitude_arcsec, "eccentricity_phase_deg": ecc.phase_deg,
            "eccentricity_u_arcsec": ecc.u_arcsec, "unit_order1_arcsec": float(abs(unit))}
