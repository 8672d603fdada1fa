"""Issue 31 items 2 and 8: the forms our generator now draws that the candidates do not fit
exactly, and a stiffness departure with nothing else wrong reported as a gap.

The generator's new forms are checked against their closed forms; the diagnosis is checked on
campaigns drawn at random from them (seed 12, the first cases of each form), each measured
through a real rig's measuring system (simulators/offline_rig.py).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rig.validate import FORMS, OUT_OF_VOCABULARY, draw_case, validate_one
from simulators.offline_forms import drifting_zero_Nm, parallel_spring_torque_Nm, thermal_lag_C
from simulators.plant.geometry import reference_nominal


def _first(seed: int, kind: str, form: str, skip: int = 0, min_counts: int = 0) -> int:
    """Index of the ``skip``-th case of ``kind`` drawn in ``form`` (with an output encoder of
    at least ``min_counts`` counts per turn)."""
    hits = (i for i in range(200) if (c := draw_case(seed, i, kind, True)).form == form
            and c.truth["measuring_system"]["encoder_counts_per_rev"] >= min_counts)
    for _ in range(skip):
        next(hits)
    return next(hits)


def test_thermal_lag_follows_the_first_order_law() -> None:
    """``tau dT_m/dt = T_s - T_m`` with the sensor stepped between runs: after one run the
    mesh has closed ``1 - exp(-1/r)`` of the step; the sensor held, it converges on it."""
    mesh = thermal_lag_C([20.0, 40.0, 40.0, 40.0, 40.0, 40.0, 40.0, 40.0], 1.0)
    assert mesh[0] == 20.0
    assert mesh[1] == pytest.approx(40.0 - 20.0 * math.exp(-1.0))
    assert mesh[-1] == pytest.approx(40.0 - 20.0 * math.exp(-7.0))
    down = thermal_lag_C([12.0, 24.0, 36.0, 48.0, 48.0, 36.0, 24.0, 12.0], 2.0)
    assert down[5] > down[2]  # cooling at 36 degC the mesh is warmer than heating at 36


def test_parallel_spring_and_drifting_zero() -> None:
    angle = np.linspace(-1.0, 1.0, 11) / 60.0  # deg: +-1 arcmin
    torque = parallel_spring_torque_Nm(angle, 0.5)
    assert torque[5] == pytest.approx(0.0) and torque[-1] == pytest.approx(0.5)
    zero = drifting_zero_Nm(np.linspace(3.0, 13.0, 6), 0.1)
    assert zero[0] == 0.0 and zero[-1] == pytest.approx(0.1) and np.all(np.diff(zero) > 0)


def test_the_generator_draws_the_new_forms_with_their_truth() -> None:
    assert {"ovality", "lagged", "drifting", "mild"} <= {f for v in FORMS.values() for f in v}
    assert "parallel_spring" in OUT_OF_VOCABULARY
    mild = draw_case(12, _first(12, "shaft_compliance", "mild"), "shaft_compliance", True)
    k_mesh = reference_nominal(mild.config.unit).stiffness_Nm_per_arcmin
    k_series = mild.config.effects.shaft_compliance.stiffness_Nm_per_arcmin
    loaded = 1.0 / (1.0 / k_mesh + 1.0 / k_series)
    assert 1.0 - loaded / k_mesh == pytest.approx(mild.truth["stiffness_deficit"])
    assert 0.03 <= mild.truth["stiffness_deficit"] <= 0.08
    lagged = draw_case(12, _first(12, "thermal_expansion", "lagged"), "thermal_expansion", True)
    assert lagged.truth["mesh_temperature_C"] != lagged.temperatures_C
    assert len(set(np.round(lagged.play_change_um, 4))) > 2
    drift = draw_case(12, _first(12, "torque_sensor_offset", "drifting"),
                      "torque_sensor_offset", True)
    assert drift.offset_drift_Nm == drift.truth["drift_per_run_Nm"] != 0.0
    spring = draw_case(12, 2, "parallel_spring", True)
    assert spring.expected == {"unexplained", "ambiguous"}
    assert 0.01 <= spring.truth["share_of_mesh_stiffness"] <= 0.04


@pytest.mark.timeout(240)
@pytest.mark.parametrize("skip", [0, 1, 2])
def test_a_stiffness_a_few_percent_below_the_model_is_named(skip: int) -> None:
    """A loaded stiffness 3-8 % below seed 004 eq. (8) with nothing else wrong: before this
    round 5 of 5 such campaigns came out ``none`` (the 10 % stiffness tolerance). Now the
    verdict is ``shaft_compliance`` with the softer mesh beside it, the experiment that
    separates them, and the ratio in the report. (Encoders of 2^21 counts per turn or more:
    a coarser one cannot resolve a few percent, the next test.)"""
    index = _first(12, "shaft_compliance", "mild", skip, min_counts=2 ** 21)
    res = validate_one((12, index, "shaft_compliance", True))
    report = res.report
    assert res.verdict == "shaft_compliance", report["reason"]
    assert set(res.candidates) == {"shaft_compliance", "mesh_stiffness"}
    assert "second encoder" in report["next_experiment"]
    k = report["parameter_error"]["stiffness_Nm_per_arcmin"]
    assert k["ratio"] == pytest.approx(1.0 - res.case.truth["stiffness_deficit"], abs=0.015)
    assert k["ratio"] < 1.0 - k["gap_tolerance"]
    assert f"{k['ratio']:.3f} times seed 004 eq. (8)" in report["reason"]


@pytest.mark.timeout(240)
def test_a_coarse_encoder_cannot_resolve_a_mild_compliance() -> None:
    """Case 7 of seed 12: a loaded stiffness 4.3 % below seed 004 eq. (8) read by an output
    encoder of 2^19 counts per turn, whose half count is a larger share of the loaded twist:
    the quantisation (lined up with the loading) could make that much on a null (7 of 14
    such nulls recorded over the wire read 2.2-4.4 % off), so it is no finding: ``none``,
    the tolerance the encoder's."""
    case = draw_case(12, 7, "shaft_compliance", True)
    assert case.form == "mild"
    assert case.truth["measuring_system"]["encoder_counts_per_rev"] == 2 ** 19
    res = validate_one((12, 7, "shaft_compliance", True))
    k = res.report["parameter_error"]["stiffness_Nm_per_arcmin"]
    assert k["quantisation_share"] > case.truth["stiffness_deficit"]
    assert k["gap_tolerance"] == k["quantisation_share"]
    assert abs(k["ratio"] - 1.0) < k["gap_tolerance"]
    assert res.verdict == "none", res.report["reason"]


@pytest.mark.timeout(240)
def test_a_parallel_spring_is_not_none_and_a_null_stays_none() -> None:
    """A spring beside the gear stiffens the unit over the whole range, which no effect of the
    vocabulary does: ``unexplained``; a null campaign of the same generator: ``none``, its
    stiffness within the tolerance."""
    spring = validate_one((12, 3, "parallel_spring", True))
    assert spring.verdict == "unexplained", spring.report["reason"]
    reason = spring.report["reason"]
    # by the torque it carries inside the play, or by the loaded slope it raises
    assert "inside the free play" in reason or "stiffer than the model" in reason, reason
    null = validate_one((12, 1000, "none", True))
    assert null.verdict == "none", null.report["reason"]
    k = null.report["parameter_error"]["stiffness_Nm_per_arcmin"]
    assert abs(k["ratio"] - 1.0) < k["gap_tolerance"]


@pytest.mark.timeout(240)
@pytest.mark.parametrize("index", [1, 4])
def test_a_parallel_spring_is_told_by_the_torque_inside_the_play(index: int) -> None:
    """A spring beside the gear carries torque inside the free play, where no gear effect
    does: the rule ``torque_inside_the_play`` makes it ``unexplained`` and the report reads
    the spring's stiffness there (within 25 % of the truth: the encoder's and the torque
    channel's dynamics stay in the samples). Before this rule 3 of 4 such campaigns (seed 21)
    came out ``none``, ``bearing_clearance`` or ``shaft_compliance``."""
    res = validate_one((42, index, "parallel_spring", True))
    report = res.report
    assert res.verdict == "unexplained", report["reason"]
    assert "torque rises with twist inside the free play" in report["reason"]
    assert "decoupled" in report["next_experiment"]
    slope = report["play_slope"]
    assert slope["slope_Nm_per_arcmin"] == pytest.approx(
        res.case.truth["stiffness_Nm_per_arcmin"], rel=0.25)
    assert slope["share_of_mesh_stiffness"] >= report["decision_policy"]["play_slope_share"]
