"""The seeds' TE model beside a measurement (issue 22 item 3): inside the band, or flagged."""

from __future__ import annotations

import math

import numpy as np
import pytest

from analysis.transmission import analyse_te
from analysis.transmission import model_internal as mi
from analysis.transmission.compare import compare
from analysis.transmission.model import internal_prediction, planetary_prediction, predict
from analysis.transmission.synthetic import synthetic_te

UNIT = {"kind": "internal_involute", "z_internal": 45, "z_external": 40, "module_mm": 1.0,
        "pressure_angle_deg": 20.0, "addendum_coeff": 0.55, "clearance_coeff": 0.25,
        "face_width_mm": 10.0, "center_distance_mm": 2.5, "pin_diameter_mm": 1.732,
        "m_value_internal_mm": [42.485, 42.481, 42.481, 42.480, 42.483, 42.479],
        "m_value_external_mm": [42.401, 42.398, 42.402, 42.404, 42.402, 42.404]}


def _internal_unit(runout_int_mm, runout_ext_mm, fpt_um, seed=0):
    rng = np.random.default_rng(seed)
    unit = dict(UNIT, runout_internal_mm=runout_int_mm, runout_external_mm=runout_ext_mm,
                runout_phase_deg=35.0, runout_internal_phase_deg=-60.0)
    unit["pitch_internal_um"] = mi.positions_from_single_pitch(
        rng.uniform(-fpt_um[0], fpt_um[0], 45))[0].tolist()
    unit["pitch_external_um"] = mi.positions_from_single_pitch(
        rng.uniform(-fpt_um[1], fpt_um[1], 40))[0].tolist()
    return unit


def _measure_internal(unit, hysteresis_arcmin=0.0):
    geo = mi.geometry_from_unit(unit)
    errors = mi.unit_errors(geo, unit)

    def te(out, inp, d):
        return mi.unit_curves(geo, errors, inp)[d][0]

    s = synthetic_te(te, ratio=geo.ratio, samples_per_output_rev=30_000, noise_arcsec=0.3,
                     hysteresis_arcsec=60.0 * hysteresis_arcmin)
    return analyse_te(s.output_angle_deg, s.input_angle_deg, s.direction, geo.kinematics(),
                      output_counts_per_rev=2**23, input_counts_per_rev=2**17)


def test_a_unit_inside_table1_is_inside_the_band_and_matches_its_own_curve():
    unit = _internal_unit(0.018, 0.012, (6.0, 4.0))
    pred = internal_prediction(unit, brake_torque_Nm=1.0, samples=600)
    # the play and windup of the reference nominal model, as the plant would give them
    result = _measure_internal(unit, pred.metrics["te_hysteresis_arcmin"])
    cmp = compare(result, pred)
    assert cmp["flagged"] == []
    assert cmp["metrics"]["te_pp_arcsec"]["inside"] is True
    # the unit's own curve: figures within 5 % and the eq. 4 orders at their phases
    for key in ("te_pp_arcsec", "te_total_Fi_arcsec", "te_tooth_fi_arcsec"):
        assert result.metrics[key] == pytest.approx(pred.metrics[key], rel=0.05), key
    ring = next(o for o in cmp["orders"] if o["per"] == "input_rev" and o["order"] == 1
                and o["direction"] == "forward")
    assert ring["measured"] == pytest.approx(ring["model"], rel=0.10)
    assert abs(ring["phase_gap_deg"]) < 10.0
    assert pred.metrics["te_hysteresis_arcmin"] > 0


def test_a_unit_outside_table1_is_flagged():
    unit = _internal_unit(0.080, 0.060, (30.0, 25.0), seed=1)
    result = _measure_internal(unit)
    cmp = compare(result, internal_prediction(UNIT, samples=600))
    assert "te_pp_arcsec" in cmp["flagged"]
    assert cmp["metrics"]["te_pp_arcsec"]["side"] == "above"
    assert any(o["flag"] for o in cmp["orders"])


def _planetary_run(scale):
    from analysis.models.seed003_montecarlo import TransmissionErrorModel, draw_values_um
    from analysis.models.seed003_planetary import error_sources, paper_train

    model = TransmissionErrorModel(error_sources(paper_train()))
    rng = np.random.default_rng(11)
    values = scale * draw_values_um(model.sources, 1, rng)
    # an ordinary unit of the batch: the median draw's size, random phases
    phases = rng.uniform(0, 2 * math.pi, (1, len(model.sources)))

    def te(out, inp, d):
        return model.transmission_error_arcsec(values, phases, np.radians(out))[0]

    pred = planetary_prediction({"kind": "planetary"}, samples=600)
    s = synthetic_te(te, ratio=pred.kinematics.ratio, samples_per_output_rev=40_000,
                     hysteresis_arcsec=30.0)
    return analyse_te(s.output_angle_deg, s.input_angle_deg, s.direction, pred.kinematics,
                      output_counts_per_rev=2**23, input_counts_per_rev=2**17), pred


def test_seed003_train_inside_its_monte_carlo_band_and_a_bad_one_flagged():
    good, pred = _planetary_run(1.0)
    cmp = compare(good, pred)
    assert cmp["metrics"]["te_pp_arcsec"]["inside"] is True
    assert cmp["flagged"] == []
    bad, pred = _planetary_run(4.0)
    cmp = compare(bad, pred)
    assert "te_pp_arcsec" in cmp["flagged"]


def test_beveloid_prediction_is_seed001s_tca_curve():
    from analysis.models.beveloid_nominal import beveloid_pair_from_unit
    from analysis.models.seed001_beveloid import PAPER_CASES, transmission_error

    unit = {"kind": "beveloid", "z_pinion": 20, "z_gear": 20, "module_mm": 3.0,
            "pressure_angle_deg": 20.0, "helix_angle_deg": 9.0, "cone_angle_deg": 6.0,
            "face_width_mm": 15.0, "center_distance_mm": 61.0,
            "installation": {"horizontal_deg": 0.5}}
    pred = predict(unit)
    pair, _, _ = beveloid_pair_from_unit(unit)
    tca = transmission_error(pair, PAPER_CASES["horizontal"], points_per_cycle=24).te_arcsec
    cycle = tca[:-1] - tca[:-1].mean()
    assert pred.kinematics.output_teeth == 20
    assert np.allclose(pred.curve_arcsec[1][:24], cycle, atol=1e-9)
    assert pred.metrics["te_pp_arcsec"] == pytest.approx(np.ptp(cycle))
