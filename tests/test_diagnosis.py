"""Diagnosis steps on data from the analysis model (exact answers) and from the plant."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from analysis.diagnosis import diagnose
from analysis.diagnosis_data import RunInput, prepare_run, transit_mask
from analysis.diagnosis_fit import build_stack, fit, fit_profile
from analysis.effects import LoopParams, predict_twist_arcmin
from analysis.errors import AnalysisError
from analysis.models.nominal import reference_nominal_model
from rig.validate import cycle_profile, make_case, simulate_campaign
from simulators.plant_config import load_plant_config

UNIT = load_plant_config().unit
NOM = reference_nominal_model(UNIT)


def _run(i: int, params: LoopParams, *, angle: float = 0.0, temp: float = 20.0,
         noise: float = 0.3 / 60, seed: int = 0) -> RunInput:
    n = 2000
    torque = cycle_profile(10.0, n)
    rng = np.random.default_rng(seed + i)
    twist = predict_twist_arcmin(params, torque, input_angle_deg=angle, temperature_C=temp)
    twist = twist + 7.0 * i + rng.normal(0, noise, n)  # arbitrary zero per run
    return RunInput(f"r{i}", np.arange(n) / 200.0, torque + rng.normal(0, 0.003, n), twist,
                    10.0, UNIT, angle, np.full(n, temp))


def test_prepare_run_noise_and_decimation() -> None:
    prep = prepare_run(_run(0, LoopParams(NOM.play_arcmin, NOM.stiffness_Nm_per_arcmin)))
    assert 150 <= prep.twist_arcmin.size <= 320
    # the block-mean noise is the sample noise over sqrt(block) (within estimator scatter)
    assert prep.sigma_arcmin == pytest.approx(0.3 / 60 / math.sqrt(prep.block), rel=0.35)
    with pytest.raises(AnalysisError, match="at least 20"):
        prepare_run(RunInput("x", np.arange(5.0), np.zeros(5), np.zeros(5), 10.0, UNIT))


def test_transit_samples_are_left_out() -> None:
    twist = np.array([0.0, 0.0, 1.0, 2.0, 3.0, 3.0, 3.0])
    torque = np.zeros(7)
    keep, jump = transit_mask(twist, torque, 0.01, 0.1)
    assert jump.tolist() == [False, True, True, True, False, False]
    assert keep.tolist() == [True, True, False, False, True, True, True]


def test_calibration_and_candidate_fits_recover_parameters() -> None:
    truth = LoopParams(NOM.play_arcmin * 1.1, NOM.stiffness_Nm_per_arcmin * 0.9,
                       friction_Nm=0.3)
    stack = build_stack([prepare_run(_run(i, truth, angle=45.0 * i)) for i in range(4)])
    f = fit_profile(stack, ("backlash", "friction"))
    assert f.coef("play") == pytest.approx(truth.play_arcmin, rel=2e-3)
    assert 1 / f.coef("compliance") == pytest.approx(truth.stiffness_Nm_per_arcmin, rel=5e-3)
    assert f.nl["friction_Nm"] == pytest.approx(0.3, abs=0.02)
    # the offset is located by where the flank changes: to within the ramp's torque step
    shifted = LoopParams(NOM.play_arcmin, NOM.stiffness_Nm_per_arcmin, torque_offset_Nm=0.15)
    stack = build_stack([prepare_run(_run(i, shifted, angle=45.0 * i)) for i in range(4)])
    f = fit_profile(stack, ("backlash", "torque_sensor_offset"))
    assert f.nl["torque_offset_Nm"] == pytest.approx(0.15, abs=0.05)
    thermal = LoopParams(NOM.play_arcmin, NOM.stiffness_Nm_per_arcmin,
                         thermal_arcmin_per_K=0.03, thermal_reference_C=30.0)
    stack = build_stack([prepare_run(_run(i, thermal, temp=t))
                         for i, t in enumerate((10.0, 20.0, 40.0, 50.0))])
    f = fit(stack, ("backlash", "thermal_expansion"))
    assert f.coef("thermal") == pytest.approx(0.03, rel=0.01)


def test_null_campaign_from_the_model_is_none() -> None:
    nominal = LoopParams(NOM.play_arcmin, NOM.stiffness_Nm_per_arcmin)
    report = diagnose([_run(i, nominal, angle=60.0 * i) for i in range(5)]).to_dict()
    assert report["verdict"] == "none"
    assert report["gap_before"]["rms_arcsec"] < 0.2
    assert report["predictive_gap"]["rms_arcsec"] < 0.2


def test_runout_from_the_model_is_found_located_and_shrunk() -> None:
    runout = LoopParams(NOM.play_arcmin, NOM.stiffness_Nm_per_arcmin,
                        runout_coeffs_arcmin=(0.6, -0.3, 0.0, 0.0))
    report = diagnose([_run(i, runout, angle=45.0 * i) for i in range(8)]).to_dict()
    assert report["verdict"] == "runout"
    assert report["localization"]["where"] == "position"
    assert report["free_play_fourier"]["dominant_order"] == 1
    # play amplitude of the 1/rev term: hypot(0.6, 0.3) arcmin
    assert report["free_play_fourier"]["amplitude_arcmin"][0] == pytest.approx(
        math.hypot(0.6, 0.3), rel=0.02)
    assert report["shrink"] > 0.9
    assert report["gap_after"]["lost_motion_error_arcsec"] < 1.0 < report["gap_before"][
        "lost_motion_error_arcsec"]


def test_report_keys_and_blindness_to_generator_labels(tmp_path) -> None:
    """The verdict comes from unit, test and samples only: scrambling or removing the
    generator's labels and true parameters changes nothing."""
    from rig.diagnose import diagnose_campaign, report_dict

    case = make_case(0, "bearing_clearance", np.random.default_rng(5), load_plant_config())
    campaign = simulate_campaign(case, samples=1500)
    first = report_dict(campaign, diagnose_campaign(campaign))
    for run in campaign.runs:
        run.meta["generator"] = {"kind": "runout", "truth": {"beta_deg": 99.0}}
    second = report_dict(campaign, diagnose_campaign(campaign))
    for run in campaign.runs:
        del run.meta["generator"]
        run.data.pop("true_torque_Nm", None)
    third = report_dict(campaign, diagnose_campaign(campaign))
    assert first["verdict"] == second["verdict"] == third["verdict"] == "bearing_clearance"
    assert json.dumps(first, sort_keys=True) == json.dumps(third, sort_keys=True)
    for key in ("format", "model_effects", "gap_before", "ranking", "verdict", "localization"):
        assert key in first
    assert first["format"] == "rig-diagnosis/1"
    assert first["ranking"][0]["effect"] == "bearing_clearance"
    assert {"shrink", "gap_after", "params", "evidence"} <= set(first["ranking"][0])


def test_seed000_gap_example_numbers() -> None:
    """examples/seed000_gap.py: the gaps of Table 3 and the bearing term of eqs. (3), (7)."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parent.parent / "examples" / "seed000_gap.py"
    spec = importlib.util.spec_from_file_location("seed000_gap", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    rows = module.gap_rows()
    assert [r["gap_arcsec"] for r in rows] == [32, 27, 16, 23]
    # pair 1: bearings 5 + 6 um -> 2 tan20 (5.5 um) -> 0.6118 arcmin = 36.7 arcsec
    assert rows[0]["bearing_clearance_arcsec"] == pytest.approx(36.7, abs=0.1)
    assert all(r["bearing_clearance_arcsec"] >= r["gap_arcsec"] for r in rows)
    assert all(r["runout_swing_arcsec"] > r["gap_arcsec"] for r in rows)
    assert rows[0]["elastic_band_arcsec"] == pytest.approx(60 * 0.6 / 27.8598, rel=1e-4)
