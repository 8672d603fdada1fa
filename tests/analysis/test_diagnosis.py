"""Diagnosis steps on data from the analysis model (exact answers) and from the plant."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from analysis.diagnosis import (
    diagnose,
    heldout_separation,
    play_tiebreak,
    quantisation_floor_arcmin,
    separated,
)
from analysis.diagnosis.data import RunInput, landed_blocks, prepare_run, transit_mask
from analysis.diagnosis.fit import build_stack, fit, fit_profile
from analysis.effects import (
    LoopParams,
    bearing_play_arcmin,
    flank_sign,
    predict_twist_arcmin,
)
from analysis.errors import AnalysisError
from analysis.models.nominal import reference_nominal_model
from rig.validate import cycle_profile, make_case, simulate_campaign
from simulators.plant.config import load_plant_config
from tests.support.paths import REPO

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
    # the samples at the start and end of the flight are partly in flight: left out too
    assert keep.tolist() == [True, False, False, False, False, True, True]


def test_the_first_block_after_a_play_crossing_is_where_the_switch_is_unsure() -> None:
    """A crossing: kept rows 0-9, in flight 10-12 (jumps), kept again from 13. With blocks of
    4 the rows 13-16 are the landing block; the first segment (no crossing before it) and
    the rest of the second are not."""
    keep = np.ones(30, dtype=bool)
    keep[9:14] = False
    jump = np.zeros(29, dtype=bool)
    jump[9:13] = True
    segments = [(0, 9), (14, 30)]
    got = landed_blocks(segments, keep, jump, 4)
    assert np.flatnonzero(got).tolist() == [14, 15, 16, 17]
    assert not landed_blocks([(0, 30)], np.ones(30, dtype=bool), np.zeros(29, dtype=bool),
                             4).any()


def test_the_quantisation_floor_is_one_encoder_count_over_sqrt_12() -> None:
    """A run read through an encoder of 2^20 counts per turn (1.236 arcsec): the floor under
    which a systematic gap is the encoder's own error is q / sqrt(12) = 0.357 arcsec; an
    unquantised run has none."""
    q = 360.0 * 60.0 / 2**20  # arcmin
    base = _run(0, LoopParams(NOM.play_arcmin, NOM.stiffness_Nm_per_arcmin), noise=0.0)
    coarse = dataclasses.replace(base, twist_arcmin=np.round(base.twist_arcmin / q) * q)
    floor = quantisation_floor_arcmin([prepare_run(coarse)])
    assert floor * 60.0 == pytest.approx(q * 60.0 / math.sqrt(12.0), rel=0.02)
    assert quantisation_floor_arcmin([prepare_run(_run(1, LoopParams(
        NOM.play_arcmin, NOM.stiffness_Nm_per_arcmin)))]) < 1e-3 * floor


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
    from rig.results.diagnose import diagnose_campaign, report_dict

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

    path = REPO / "examples" / "seed000_gap.py"
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


def _hertz_run(i: int, eta: float, p: float, *, angle: float, noise: float = 0.3 / 60
               ) -> RunInput:
    """A run whose flank twist is ``(1 - eta) T / K + eta (T_r / K) (T / T_r)^p`` (Hertz-like
    blend, same twist as the nominal at T_r = 10 N*m) on the nominal play."""
    n = 2000
    torque = cycle_profile(10.0, n)
    rng = np.random.default_rng(40 + i)
    s = flank_sign(torque, 0.0, -1)
    tau = np.abs(torque)
    k = NOM.stiffness_Nm_per_arcmin
    h = (1 - eta) * tau / k + eta * (10.0 / k) * (tau / 10.0) ** p
    twist = s * (NOM.play_arcmin / 2 + h) + 7.0 * i + rng.normal(0, noise, n)
    return RunInput(f"r{i}", np.arange(n) / 200.0, torque + rng.normal(0, 0.003, n), twist,
                    10.0, UNIT, angle, np.full(n, 20.0))


def _stiffening_and_bearing(params: LoopParams):
    d = diagnose([_run(i, params, angle=45.0 * i) for i in range(6)])
    return d, d.models["stiffness_nonlinearity"], d.models["bearing_clearance"]


def test_kink_and_smooth_curve_are_told_apart_on_held_out_runs() -> None:
    """A bearing soft stage (a kink at T_b) is fitted better by its own law on held-out runs
    and leaves the nominal slope at load: bearing clearance; Hertzian contact stiffening (a
    power law over the whole range) is stiffer than nominal at load: stiffening."""
    budget = bearing_play_arcmin(UNIT["bearing_clearance_mm"], 20.0, 1.0, 45)
    bearing = LoopParams(NOM.play_arcmin, NOM.stiffness_Nm_per_arcmin,
                         bearing_extra_play_arcmin=budget,
                         bearing_compliance_arcmin_per_Nm=1 / 5.0, bearing_stage_torque_Nm=1.2)
    d, stiff, bear = _stiffening_and_bearing(bearing)
    ratio, wins = heldout_separation(d.stack, bear, stiff)
    assert ratio > 1.5 and wins == 1.0
    assert separated(d.stack, bear, stiff) and not separated(d.stack, stiff, bear)
    assert heldout_separation(d.stack, bear, bear)[0] == pytest.approx(1.0)
    assert not separated(d.stack, bear, bear)
    assert d.report["verdict"] == "bearing_clearance"
    # the extra play of the inspected clearances (seed 000 eqs. 3 + 7) is found in both fits
    winner, why = play_tiebreak(["stiffness_nonlinearity", "bearing_clearance"], d.models,
                                NOM.play_arcmin)
    assert winner == "bearing_clearance" and "eqs. 3 + 7" in why
    # Hertzian contact: 80 % of the nominal compliance becomes a power law of the torque
    # (deflection ~ load^(2/3)) with the same twist at 10 N*m: stiffer than nominal at load
    d = diagnose([_hertz_run(i, 0.8, 2.0 / 3.0, angle=45.0 * i) for i in range(6)])
    assert d.report["verdict"] == "stiffness_nonlinearity"
    assert "stiffer at load" in " ".join(d.models["stiffness_nonlinearity"].notes)
    # only that pair is settled by the play
    assert play_tiebreak(["friction", "torque_sensor_offset"], d.models, NOM.play_arcmin) == (
        None, "")


def test_offset_and_friction_are_told_apart_by_where_the_flank_changes() -> None:
    """An offset shifts the loop in torque (both branches switch at +T0), friction separates
    the branches (switches at +-F): a small offset is not called friction or ambiguous."""
    shifted = LoopParams(NOM.play_arcmin, NOM.stiffness_Nm_per_arcmin, torque_offset_Nm=0.07)
    report = diagnose([_run(i, shifted, angle=45.0 * i, noise=0.7 / 60)
                       for i in range(6)]).to_dict()
    assert report["verdict"] == "torque_sensor_offset"
    params = report["ranking"][0]["params"]
    # the data bound the offset to the torques between the flank switches seen
    lo, hi = params.get("offset_interval_Nm", [params["offset_Nm"]] * 2)
    assert lo - 0.01 <= 0.07 <= hi + 0.01 and hi - lo < 0.25
    assert lo <= params["offset_Nm"] <= hi
