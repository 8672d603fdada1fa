"""The physics rules of the generalised diagnosis (issue 10), each on a closed form or on
injected ground truth: tooth-pair repeats, the float across the play at zero torque, the
bearing/stiffening split by the loaded slope."""

from __future__ import annotations

import math

import numpy as np
import pytest

from analysis.diagnosis import Candidate, curvature_effect, series_compliance
from analysis.diagnosis.data import PreparedRun
from analysis.diagnosis.fit import LinearFit, censor_floating, flank_band_Nm, run_chain
from analysis.effects import (
    LoopParams,
    play_at_arcmin,
    runout_harmonic_basis,
    tooth_pair_phase,
    tooth_repeat_period_deg,
)


def test_tooth_pair_repeats_after_lcm_mesh_steps() -> None:
    # 45/40 teeth: lcm 360 mesh steps = 2880 deg of input = one output revolution (ratio 8)
    assert tooth_repeat_period_deg(45, 40) == 2880.0
    a = np.array([548.1, 548.1 + 2880.0, 340.85])
    ph = tooth_pair_phase(a, 45, 40)
    assert ph[0] == ph[1] != ph[2]
    # one input turn later the ring tooth repeats but the pinion tooth does not
    assert tooth_pair_phase(548.1 + 360.0, 45, 40) != ph[0]
    # 61/56: lcm 3416 steps -> 360 * 3416 / 61 deg, not one output turn (ratio 11.2)
    assert math.isclose(tooth_repeat_period_deg(61, 56), 360.0 * 3416 / 61)


def test_float_across_the_play_is_censored() -> None:
    play = 4.0
    X = np.array([[0.5], [0.5], [0.5], [0.5], [-0.5]])  # s / 2: kept flank +, +, +, +, -
    beta = np.array([play])
    r = np.array([-1.0, -3.0, 0.5, -3.0, 1.5])  # measured minus kept-flank model
    floating = np.array([True, True, True, False, True])
    out, inside = censor_floating(r, X, beta, floating)
    # drifted towards the centre (up to half the play): free; past it only the excess counts
    assert inside.tolist() == [True, False, False, False, True]
    assert out.tolist() == [0.0, -1.0, 0.5, -3.0, 0.0]


def _take_up_fit(compliance: float) -> Candidate:
    """A saturating take-up fit (play, loaded compliance, extra twist) with a tight
    covariance, as analysis.diagnosis.fit returns it."""
    f = LinearFit(("play", "compliance", "soft_twist"), np.array([3.0, compliance, 0.2]),
                  {"stiffening_torque_Nm": 1.0}, 100.0, 200.0, 200,
                  cov=np.diag([1e-8, (0.002 * compliance) ** 2, 1e-8]))
    return Candidate(("stiffness_nonlinearity",), f, 0.01, 0.01, 4, "leave-one-condition-out")


def test_loaded_slope_names_the_flank_curvature() -> None:
    k_nom = 30.0
    # a clearance taken up at small torque leaves the nominal slope
    name, why = curvature_effect({"stiffness_nonlinearity": _take_up_fit(1 / 30.5)}, k_nom)
    assert name == "bearing_clearance" and "nominal slope" in why
    # a hardening contact is stiffer at load than the linear nominal
    name, _ = curvature_effect({"stiffness_nonlinearity": _take_up_fit(1 / 40.0)}, k_nom)
    assert name == "stiffness_nonlinearity"
    # softer at load than nominal: neither shape, undecided
    assert curvature_effect({"stiffness_nonlinearity": _take_up_fit(1 / 20.0)}, k_nom)[0] is None


def test_take_up_still_going_at_the_amplitude_is_contact_stiffening() -> None:
    k_nom = 30.0
    fit = _take_up_fit(1 / 30.5)  # nominal loaded slope, extra twist 0.2 arcmin over 1 N*m
    # the amplitude (10 N*m) is ten torque scales out: the take-up is over, a clearance
    assert curvature_effect({"stiffness_nonlinearity": fit}, k_nom, 10.0)[0] == \
        "bearing_clearance"
    # the amplitude is one torque scale: 0.2/1 * exp(-1) = 0.074 arcmin/N*m still adds to
    # 1/30.5 at the largest torque, the flank goes on hardening there: a contact
    name, why = curvature_effect({"stiffness_nonlinearity": fit}, k_nom, 1.0)
    assert name == "stiffness_nonlinearity" and "hardening up to the amplitude" in why
    # four torque scales (98 % closed at the amplitude): a clearance, softer tangent or not
    soft_end = _take_up_fit(1 / 30.5)
    soft_end.fit.beta[2] = 5.0  # 5 arcmin of take-up: 5 exp(-4) = 0.09 arcmin/N*m left
    assert curvature_effect({"stiffness_nonlinearity": soft_end}, k_nom, 4.0)[0] == \
        "bearing_clearance"


def test_runout_and_thermal_families_hold_higher_orders() -> None:
    theta = np.array([0.0, 45.0, 90.0])
    b = runout_harmonic_basis(theta)
    assert b.shape == (3, 2)
    assert np.allclose(b[:, 0], [1.0, 0.0, -1.0], atol=1e-12)  # cos 2 theta
    params = LoopParams(play_arcmin=3.0, stiffness_Nm_per_arcmin=30.0,
                        runout_order2_arcmin=(0.5, 0.0), thermal_arcmin_per_K=0.01,
                        thermal_arcmin_per_K2=0.001, thermal_reference_C=20.0)
    assert math.isclose(play_at_arcmin(params, 90.0, None, 45, 40), 2.5, abs_tol=1e-12)
    assert math.isclose(float(play_at_arcmin(params, None, 30.0, 45, 40)),
                        3.0 + 0.1 + 0.1, abs_tol=1e-12)


def test_series_compliance_is_listed_only_when_the_loaded_slope_is_soft() -> None:
    k_nom = 30.0
    soft = _take_up_fit(1 / 20.0).fit  # 33 % softer at load than seed 004 eq. (8)
    entry = series_compliance(soft, k_nom)
    assert entry is not None and entry["effect"] == "shaft_compliance"
    # series spring: 1/K_load = 1/K_nom + 1/K_s -> K_s = 1 / (1/20 - 1/30) = 60
    assert math.isclose(entry["params"]["stiffness_Nm_per_arcmin"], 60.0, rel_tol=1e-9)
    assert series_compliance(_take_up_fit(1 / 29.0).fit, k_nom) is None


def test_lag_between_channels_is_found() -> None:
    """Sinusoidal loading of the nominal loop (play + linear flanks, injected): a torque
    channel 3 samples late is found (the rate-proportional branch split), and no lag is found
    without it."""
    from analysis.channels.lag import channel_lag_samples
    from analysis.effects import LoopParams, predict_twist_arcmin

    n = 3000
    t = np.arange(n) / 250.0
    torque = 10.0 * np.sin(2 * np.pi * t / 4.0)
    rng = np.random.default_rng(3)
    # a torque channel late by 3 samples: the twist is 3 samples ahead of it (lag -3)
    for friction, lag, expected in ((0.0, 3, -3), (0.0, 0, 0)):
        twist = predict_twist_arcmin(LoopParams(3.0, 25.0, friction_Nm=friction), torque)
        twist = twist + rng.normal(0, 0.2 / 60, n)
        measured = np.concatenate([np.full(lag, torque[0]), torque[:n - lag]])
        assert channel_lag_samples(t, measured, twist, 0.2 / 60) == expected


def test_flank_residual_folded_in_chunks_is_one_least_squares_fit(monkeypatch) -> None:
    """The lag search's flank residual (analysis.channels.artefacts._flank_rss) is folded
    chunk by chunk (issue 21 item 8: no design matrix of a 5.5 M-sample run in memory): it
    equals one least-squares fit of every row at once, with and without friction's order,
    for a twist far from its zero (an encoder's 6730')."""
    from analysis.channels import artefacts as measurement
    from analysis.channels.lag import direction_and_reversal
    from analysis.effects import LoopParams, predict_twist_arcmin

    rng = np.random.default_rng(7)
    n = 5000
    t = np.arange(n) / 250.0
    torque = 10.0 * np.sin(2 * np.pi * t / 4.0) + rng.normal(0, 0.01, n)
    direction, _ = direction_and_reversal(t, torque, 0.2)
    for friction in (0.0, 0.8):
        twist = 6730.0 + predict_twist_arcmin(LoopParams(3.0, 25.0, friction_Nm=friction),
                                              torque) + rng.normal(0, 0.2 / 60, n)
        shifted = np.interp(t - 2 / 250.0, t, torque)
        for order in (True, False):
            on = np.abs(shifted) > 0.2 * 10.0
            cols = []
            for sign in (1.0, -1.0):
                m = (np.sign(shifted) == sign).astype(float)
                cols += [m, m * shifted, m * shifted**2, m * direction]
            x, y = np.column_stack(cols)[on], twist[on]
            free = list(range(8))
            for _ in range(3):
                beta = np.zeros(8)
                beta[free] = np.linalg.lstsq(x[:, free], y, rcond=None)[0]
                wrong = [j for j in (3, 7) if order and j in free and beta[j] > 0]
                if not wrong:
                    break
                free = [j for j in free if j not in wrong]
            direct = float((y - x @ beta) @ (y - x @ beta)) / (0.2 / 60) ** 2
            monkeypatch.setattr(measurement, "RSS_CHUNK_ROWS", 333)
            folded = measurement._flank_rss(shifted, twist, direction, 10.0, 0.2 / 60,
                                            None, order)
            assert folded == pytest.approx(direct, rel=1e-9), (friction, order)


def test_no_lag_is_read_from_a_coarse_encoders_staircase() -> None:
    """A constant-rate ramp read by a 2^19-count encoder (2.47 arcsec counts, 0.1 arcsec of
    noise: no dither): the quantisation error holds for many samples, so a shift that fits
    the staircase a little better is no evidence of a lag."""
    from analysis.channels.lag import channel_lag_samples
    from analysis.diagnosis.data import resolution_of
    from analysis.effects import LoopParams, predict_twist_arcmin

    n = 2500
    t = np.arange(n) / 250.0
    u = np.linspace(0.0, 6.0, n)
    torque = 10.0 * np.interp(u, [0.0, 1.0, 3.0, 5.0, 6.0], [0.0, 1.0, -1.0, 1.0, 0.0])
    rng = np.random.default_rng(4)
    twist = predict_twist_arcmin(LoopParams(3.0, 22.0), torque) + rng.normal(0, 0.1 / 60, n)
    q = 360.0 * 60.0 / 2**19
    twist = np.round(twist / q) * q
    sigma = math.hypot(0.1 / 60, resolution_of(twist) / math.sqrt(12.0))
    assert channel_lag_samples(t, torque + rng.normal(0, 0.005, n), twist, sigma) == 0


def _falling_run(torque: list[float], sigma_torque: float = 1e-4) -> PreparedRun:
    """A prepared run whose torque falls through zero from the upper flank (block means)."""
    n = len(torque)
    t = np.arange(n, dtype=float)
    return PreparedRun(
        run_id="falling", torque_Nm=np.array(torque), twist_arcmin=np.zeros(n),
        temperature_C=None, t_s=t, branch=-np.ones(n), since_reversal_s=t,
        sigma_arcmin=0.01, sigma_torque_Nm=sigma_torque, raw_sigma_arcmin=0.01, block=1,
        n_raw=n, n_transit=0, rated_torque_Nm=20.0, amplitude_Nm=1.0, input_angle_deg=None,
        mean_temperature_C=None, start_flank=1, nominal=None, lost_motion_arcmin=math.nan,
        raw=None)  # type: ignore[arg-type]


def test_a_run_with_less_friction_than_the_campaigns_floats_where_its_flank_is_unknown() -> None:
    # coming down from the upper flank with the campaign's friction F = 0.05 N*m the chain
    # torque is T + F (the stop operator); a run's own friction may be as low as F - spread
    torque = [1.0, 0.5, 0.03, 0.001, -0.001, -0.01, -0.03, -0.06, -0.5, -1.0]
    run = _falling_run(torque)
    band = flank_band_Nm(run)
    assert band == pytest.approx(3 * 1e-4 + 1e-4 * 20.0)  # three torque sigmas + 1e-4 rated
    plain = run_chain(run, {"friction_Nm": 0.05})
    np.testing.assert_allclose(plain.chain_torque_Nm, np.array(torque) + 0.05, atol=1e-12)
    # one friction known exactly: the unit floats only where T + F is inside the band
    assert np.flatnonzero(plain.floating).tolist() == []
    assert plain.flank.tolist() == [1, 1, 1, 1, 1, 1, 1, -1, -1, -1]
    assert not plain.across.any()
    spread = run_chain(run, {"friction_Nm": 0.05, "friction_spread_Nm": 0.05})
    # with no friction the chain torque is T itself: from T < band the flank kept by F is no
    # longer certain (floating), and from T < -band the unit may already lie on the lower
    # flank (across); the model's flank and chain torque stay those of F
    assert np.flatnonzero(spread.floating).tolist() == [3, 4, 5, 6]
    assert np.flatnonzero(spread.across).tolist() == [5, 6]
    assert spread.flank.tolist() == plain.flank.tolist()
    # a spread larger than the friction goes no lower than no friction
    wide = run_chain(run, {"friction_Nm": 0.05, "friction_spread_Nm": 1.0})
    assert wide.floating.tolist() == spread.floating.tolist()
