"""A small generator of transmission error run folders (run-format.md "A transmission error
run") for the tests: samples from :func:`analysis.transmission.synthetic.synthetic_te` (numerics
only: no rig, no plant), run.json with the keys the rig writes. The truth they were made from
is written under ``generator`` (like the bundled example runs)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from analysis.transmission import model_internal as mi
from analysis.transmission.synthetic import synthetic_te
from rig.runformat import Run, write_run

SEED000_UNIT: dict[str, Any] = {
    "kind": "internal_involute", "serial": "TE-0001", "z_internal": 45, "z_external": 40,
    "module_mm": 1.0, "pressure_angle_deg": 20.0, "addendum_coeff": 0.55,
    "clearance_coeff": 0.25, "face_width_mm": 10.0, "center_distance_mm": 2.5,
    "pin_diameter_mm": 1.732,
    "m_value_internal_mm": [42.485, 42.481, 42.481, 42.480, 42.483, 42.479],
    "m_value_external_mm": [42.401, 42.398, 42.402, 42.404, 42.402, 42.404],
    "runout_internal_mm": 0.018, "runout_external_mm": 0.012,
    "runout_phase_deg": 35.0, "runout_internal_phase_deg": -60.0,
}


def te_run(run_id: str = "te-1", *, unit: dict[str, Any] | None = None, scale: float = 1.0,
           hysteresis_arcmin: float | None = None, ecc_arcsec: float = 0.0,
           ecc_phase_deg: float = 0.0, index_deg: float = 0.0,
           calibration: list[dict[str, Any]] | None = None, limits: dict[str, Any] | None = None,
           status: str = "completed", samples_per_output_rev: int = 12_000,
           seed: int = 0) -> Run:
    """A seed 000 pair's TE run: the model's own curve of ``unit`` (its eccentricities, times
    ``scale``) plus the reference model's hysteresis, through 2^23 / 2^17-count encoders."""
    unit = dict(unit or SEED000_UNIT)
    geo = mi.geometry_from_unit(unit)
    errors = mi.unit_errors(geo, {**unit,
                                  "runout_internal_mm": scale * unit["runout_internal_mm"],
                                  "runout_external_mm": scale * unit["runout_external_mm"]})

    def te(out, inp, d):
        return mi.unit_curves(geo, errors, inp)[d][0]

    if hysteresis_arcmin is None:  # the reference nominal model's play + 2 T / K
        from analysis.models.nominal import reference_nominal_model

        ref = reference_nominal_model({k: v for k, v in unit.items() if k not in (
            "serial", "runout_phase_deg", "runout_internal_phase_deg")})
        hysteresis_arcmin = ref.play_arcmin + 2.0 * 1.0 / ref.stiffness_Nm_per_arcmin
    hyst = hysteresis_arcmin
    s = synthetic_te(te, ratio=geo.ratio, samples_per_output_rev=samples_per_output_rev,
                     hysteresis_arcsec=60.0 * hyst, ecc_amplitude_arcsec=ecc_arcsec,
                     ecc_phase_deg=ecc_phase_deg, index_deg=index_deg, noise_arcsec=0.2,
                     seed=seed)
    meta: dict[str, Any] = {"status": status, "generator": {
        "name": "tests/support/te_runs.py", "scale": scale, "hysteresis_arcmin": hyst,
        "encoder_eccentricity_arcsec": ecc_arcsec}}
    if calibration is not None:
        meta["calibration"] = calibration
    if limits is not None:
        meta["limits"] = limits
    return Run.from_arrays(
        run_id, s.t_s, s.torque_Nm, s.output_angle_deg, input_angle_deg=s.input_angle_deg,
        unit=unit,
        test={"kind": "transmission_error", "ratio": geo.ratio, "input_speed_rpm": 60.0,
              "brake_torque_Nm": 1.0, "brake_torque_fraction": 0.1,
              "directions": ["forward", "reverse"], "output_revolutions": 1.1,
              "rated_torque_Nm": 10.0, "temperature_C": 20.0,
              "coupling_index_deg": index_deg % 360.0},
        sensors={"encoder_counts_per_rev": 2**23, "input_encoder_counts_per_rev": 2**17},
        extra_meta=meta,
        extra_columns={"direction": s.direction.astype(float),
                       "torque_command_Nm": s.torque_Nm})


def write_te_run(folder: Path, **kw: Any) -> Path:
    """:func:`te_run` written as a run folder; returns the folder."""
    run = te_run(**kw)
    return write_run(run, folder)


def truth_pp_arcsec(unit: dict[str, Any] | None = None) -> float:
    """The larger direction's peak-to-peak of the truth (arcsec), on a dense grid."""
    unit = dict(unit or SEED000_UNIT)
    geo = mi.geometry_from_unit(unit)
    errors = mi.unit_errors(geo, unit)
    curves = mi.unit_curves(geo, errors, mi.input_angles_deg(geo, per_mesh=16))
    return max(float(np.ptp(c)) for c in curves.values())


__all__ = ["SEED000_UNIT", "te_run", "truth_pp_arcsec", "write_te_run", "math"]


def store_te_unit(store: Any, serial: str, *, scale: float = 1.0, design: str = "TE-DESIGN",
                  limits: dict[str, Any] | None = None, seed: int = 0) -> str:
    """One unit's TE test recorded in ``store`` as the rig records it: a campaign of one run,
    the samples appended, ``result`` the TE analysis (:func:`rig.results.te.analyse_te_run`), the
    outcome against ``limits``; returns the campaign id."""
    from rig.results.outcome import LIMIT_KEYS, campaign_outcome, run_outcome
    from rig.results.te import analyse_te_run

    run = te_run(f"{serial}-te", scale=scale, samples_per_output_rev=4000, seed=seed)
    unit = {**run.unit, "serial": serial, "design": design}
    in_force = {k: (limits or {}).get(k) for k in LIMIT_KEYS}
    campaign_id = store.create_campaign(f"{design}-{serial}", {"unit": unit,
                                                               "limits": limits or {}})
    meta = {"unit": unit, "test": run.test, "sensors": run.sensors, "limits": in_force,
            "operator": "tests"}
    with store.begin_run(meta, list(run.columns), campaign_id=campaign_id) as rec:
        for row in np.column_stack([run.data[c] for c in run.columns]).tolist():
            rec.append(row)
        record = analyse_te_run(run, model_samples=200).result_record()
        outcome, causes, _ = run_outcome({"status": "completed", "test": run.test,
                                          "result": record}, in_force)
        rec.finish(result=record, extra={"outcome": outcome})
    store.finish_campaign(campaign_id, "completed",
                          {"n_runs": 1, "limits": in_force, "outcome": outcome,
                           "failures": causes},
                          extra={"outcome": campaign_outcome([outcome], "completed")})
    return campaign_id
