"""Our generator with a real rig's measuring system (issue 20, point 4): every artefact is
present at its drawn size in the generated samples, checked on the data, not on the config."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from scipy.signal import lfilter

from rig.validate import (
    DURATION_S,
    FULL_SCALE_NM,
    RATED_NM,
    draw_case,
    simulate_campaign,
)
from simulators.offline_forms import path_profile
from simulators.offline_rig import (
    ContactOscillator,
    RigArtifacts,
    contact_transient,
    first_order_lag,
    measure_run,
)

ARCSEC_PER_RAD = 180.0 / math.pi * 3600.0
#: A null case (index 8 of the kinds cycle) and a thermal case, seed 0, with artefacts.
CASES = [(0, 8, "none"), (0, 4, "thermal_expansion"), (3, 5, "torque_sensor_offset")]


def _lagged(t: np.ndarray, x: np.ndarray, tau: float, hold: bool) -> np.ndarray:
    """``x`` (on the uniform grid ``t``) through ``tau y' + y = x``: exact for ``x`` held
    over each interval (``hold``, the drive's command) or linear between the samples (the
    shaft torque the sensor sees)."""
    a = math.exp(-(t[1] - t[0]) / tau)
    if hold:
        b = [0.0, 1.0 - a]
    else:
        beta = tau * (1.0 - a) / (t[1] - t[0])
        b = [1.0 - beta, beta - a]
    y, _ = lfilter(b, [1.0, -a], x, zi=[a * x[0]])
    return y


def _fit_lag_s(measured: np.ndarray, rows: np.ndarray, t: np.ndarray, truth: np.ndarray,
               hold: bool) -> float:
    """The time constant (s) of the first-order lag between the truth and the measured
    values on ``rows`` (least squares over 0.1 ms steps, a constant offset free)."""
    taus = np.arange(2e-4, 0.04, 1e-4)

    def cost(tau: float) -> float:
        r = measured - _lagged(t, truth, tau, hold)[rows]
        return float(np.var(r))

    return float(taus[int(np.argmin([cost(tau) for tau in taus]))])


@pytest.fixture(scope="module")
def campaigns():
    cases = [draw_case(*c, artifacts=True) for c in CASES]
    return [(case, simulate_campaign(case)) for case in cases]


def test_a_null_case_with_every_artefact_is_labelled_none(campaigns) -> None:
    case, camp = campaigns[0]
    assert case.kind == "none" and case.expected == {"none"}
    gen = camp.runs[0].meta["generator"]
    assert gen["kind"] == "none"
    ms = gen["truth"]["measuring_system"]
    assert set(ms) >= {"contact_damping_ratio", "locked_resonance_Hz", "torque_lag_s",
                       "adc_bits", "drive_loop_s", "tare_residual_Nm_rms", "zero_walk_Nm_rms",
                       "ripple_Nm", "ripple_Hz", "coulomb_Nm", "encoder_counts_per_rev",
                       "sample_rate_Hz", "jitter_s", "max_burst", "precycles", "first_sign"}


def test_sampling_grids_jitter_and_dropped_rows_are_in_the_data(campaigns) -> None:
    """Rate 100-1000 Hz, stamps off their instants by at most the drawn jitter (<= 0.4 ms),
    dropped rows in bursts of at most 40 (the gaps in the stamps are the drawn bursts), the
    torque on the drawn ADC grid (18-24 bit over +-full scale: odd counts present, so not a
    coarser one), the twist on the drawn encoder's counts (2^19-2^23)."""
    for case, camp in campaigns:
        art = case.artifacts
        assert isinstance(art, RigArtifacts)
        fs = art.sample_rate_Hz
        assert 100.0 <= fs <= 1000.0
        step = 2.0 * FULL_SCALE_NM / 2.0 ** art.adc_bits
        assert 18 <= art.adc_bits <= 24
        enc = 360.0 / art.encoder_counts_per_rev
        assert 2 ** 19 <= art.encoder_counts_per_rev <= 2 ** 23
        for run in camp.runs:
            t = run.t_s
            assert np.median(np.diff(t)) == pytest.approx(1.0 / fs, rel=0.05)
            k = np.round(t * fs).astype(int)
            off = t - k / fs
            assert np.max(np.abs(off)) <= art.jitter_s + 1e-9 <= 0.0004 + 1e-9
            if art.jitter_s > 2e-5:  # thousands of uniform draws reach near the bound
                assert np.max(np.abs(off)) > 0.8 * art.jitter_s
            gaps = np.diff(k) - 1
            bursts = sorted(int(g) for g in gaps[gaps > 0])
            truth = run.meta["generator"]["measuring_system_run"]
            assert bursts == sorted(truth["dropped_bursts"])
            assert all(1 <= b <= min(40, art.max_burst) for b in bursts)
            assert run.n_samples == int(round(DURATION_S * fs)) - sum(bursts)
            counts = run.torque_Nm / step
            assert np.allclose(counts, np.round(counts), atol=1e-6)
            assert np.any(np.round(counts).astype(np.int64) % 2 == 1)
            ticks = run.output_angle_deg / enc
            assert np.allclose(ticks, np.round(ticks), atol=1e-6)
            assert np.any(np.round(ticks).astype(np.int64) % 2 == 1)
        dropped = [r.meta["generator"]["measuring_system_run"]["dropped_rows"]
                   for r in camp.runs]
        assert sum(dropped) > 0


def test_lags_loading_and_zero_are_in_the_data() -> None:
    """On one run of each case measured again with its truth: the torque sensor's lag (1-8 ms)
    and the drive loop (5-30 ms), each the first-order lag that best maps the truth on the
    data; the drive's torque
    the reversals of the loading (pre-cycles, first sign); the zero's tare residual and walk.
    (The ripple, whose phase a first-order lag turns rather than delays, is left out here and
    checked by :func:`test_ripple_is_a_torque_on_the_unit`.)"""
    for index, c in enumerate(CASES):
        case = draw_case(*c, artifacts=True)
        art = replace(case.artifacts, ripple_Nm=0.0)
        n = int(round(DURATION_S * art.sample_rate_Hz))
        profile = path_profile(case.loading, RATED_NM, n, art.precycles, art.first_sign)
        res = measure_run(case.config, profile, art, twist_noise_arcsec=0.1,
                          torque_noise_Nm=0.001, rng=np.random.default_rng(index),
                          input_angle_deg=case.positions_deg[0],
                          temperature_C=case.temperatures_C[0])
        cols, truth = res["columns"], res["truth"]
        keep, t_true = truth["keep"], truth["t_true_s"]
        shaft = truth["shaft_torque_Nm"]
        # the torque sensor: measured minus its zero, against the shaft torque on the loaded
        # rows (away from the impacts) of the kept rows
        on = np.flatnonzero(keep)
        on = on[np.abs(shaft[on]) > 1.0]
        lag = _fit_lag_s((cols["torque_Nm"] - truth["zero_Nm"][keep])[np.abs(shaft[keep]) > 1.0],
                         on, t_true, shaft, hold=False)
        assert 0.001 <= art.torque_lag_s <= 0.008
        # (the truth is known at the samples only: linear between them, to a part of one)
        assert lag == pytest.approx(art.torque_lag_s,
                                    abs=0.1 * art.torque_lag_s + 0.15 / art.sample_rate_Hz)
        # the drive's integral loop: the shaft torque behind the command (held per sample)
        on = np.flatnonzero(np.abs(shaft) > 1.0)
        drive = _fit_lag_s(shaft[on], on, t_true, profile, hold=True)
        assert 0.005 <= art.drive_loop_s <= 0.030
        assert drive == pytest.approx(art.drive_loop_s, abs=0.1 * art.drive_loop_s + 2e-4)
        # reversals of the loading: 3 + 2 pre-cycles, the first toward first_sign
        peaks = np.sign(shaft[np.abs(shaft) > 0.95 * RATED_NM])
        runs_of_sign = peaks[np.r_[True, peaks[1:] != peaks[:-1]]]
        assert runs_of_sign.size == 3 + 2 * art.precycles
        assert runs_of_sign[0] == art.first_sign
        # the zero: a residual of the tare at t = 0, then a walk of the drawn rms size
        zero = truth["zero_Nm"]
        assert abs(zero[0]) < 5 * art.tare_residual_Nm_rms
        assert np.std(np.diff(zero)) * math.sqrt(zero.size) == pytest.approx(
            art.zero_walk_Nm_rms, rel=0.1)


def test_ripple_is_a_torque_on_the_unit() -> None:
    """The ripple of a drawn size and frequency is in the shaft torque and moves the twist:
    a least-squares sinusoid at its frequency on a loaded stretch of a none case."""
    case = draw_case(0, 8, "none", artifacts=True)
    art = replace(case.artifacts, sample_rate_Hz=1000.0, ripple_Hz=117.0, ripple_Nm=0.015,
                  jitter_s=0.0, dropped_bursts_mean=0.0)
    n = int(DURATION_S * 1000)
    profile = path_profile("ramp", RATED_NM, n)
    res = measure_run(case.config, profile, art, twist_noise_arcsec=0.0, torque_noise_Nm=0.0,
                      rng=np.random.default_rng(1), input_angle_deg=0.0, temperature_C=20.0)
    t, shaft = res["truth"]["t_true_s"], res["truth"]["shaft_torque_Nm"]
    on = (t > 1.0) & (t < 1.5)  # loaded, rising at constant rate
    w = 2 * math.pi * art.ripple_Hz
    X = np.column_stack([np.sin(w * t[on]), np.cos(w * t[on]), np.ones(on.sum()), t[on]])
    beta, *_ = np.linalg.lstsq(X, shaft[on], rcond=None)
    osc = ContactOscillator(1e5, art.locked_resonance_Hz, art.contact_damping_ratio, 0.0,
                            art.ripple_Nm, art.ripple_Hz, 0.0)
    k, J, c = osc.stiffness_Nm_per_rad, osc.inertia_kgm2, osc.damping_Nms
    gain = abs((k + 1j * c * w) / (k - J * w * w + 1j * c * w))
    assert math.hypot(beta[0], beta[1]) == pytest.approx(art.ripple_Nm * gain, rel=0.05)


def test_contact_oscillator_bounces_rings_at_the_locked_resonance_and_decays() -> None:
    """The output crossing a 1 arcmin play under a 6 N*m/s ramp: it hits the flank, bounces
    off it at least once, then rings at the damped locked resonance with the drawn damping
    ratio (logarithmic decrement); a torque below the Coulomb friction does not move it."""
    k = 28.0 * 60.0 * ARCSEC_PER_RAD / 3600.0  # 28 N*m/arcmin in N*m/rad
    h = 0.5 / 60.0 * math.pi / 180.0
    for f_n, zeta in ((400.0, 0.05), (1200.0, 0.12)):
        osc = ContactOscillator(k, f_n, zeta, 0.0, 0.0, 100.0, 0.0)
        dt = osc.step_s()
        t = np.arange(0.0, 1.6, dt)
        g = np.interp(t, [0.0, 2.0], [-6.0, 6.0])
        dy, df, stats = contact_transient(t, g, h, osc, start_side=-1)
        assert stats["impacts"] >= 2 and stats["bounces"] >= 1
        # after the output last left the flank (the departure below -G/k on the + flank):
        # the ringing of the departure about its (zero) steady state
        off = np.flatnonzero(dy < -g / k)
        ring = dy[int(off[-1]) + 1:]
        peaks = [i for i in range(1, ring.size - 1)
                 if ring[i] > ring[i - 1] and ring[i] >= ring[i + 1] and ring[i] > 1e-12]
        assert len(peaks) >= 3
        period = np.median(np.diff(peaks)) * dt
        assert 1.0 / period == pytest.approx(f_n * math.sqrt(1 - zeta ** 2), rel=0.05)
        delta = math.log(ring[peaks[0]] / ring[peaks[1]])
        assert delta / math.sqrt(4 * math.pi ** 2 + delta ** 2) == pytest.approx(zeta, rel=0.15)
        assert np.abs(df).max() > 0.1  # the impact passes a torque spike to the shaft
    # Coulomb friction: a torque below it leaves the output on the flank it rested on, while
    # the quasi-static reference has crossed to the other one
    osc = ContactOscillator(k, 500.0, 0.1, 0.02, 0.0, 100.0, 0.0)
    t = np.arange(0.0, 0.2, osc.step_s())
    g = np.linspace(0.0, 0.015, t.size)
    dy, _, stats = contact_transient(t, g, h, osc, start_side=-1)
    assert stats["impacts"] == 0
    assert np.allclose(dy[1:], -2 * h - g[1:] / k, atol=1e-12)


def test_first_order_lag_is_exact_for_held_input() -> None:
    t = np.arange(0.0, 0.05, 1e-4)
    y = first_order_lag(t, np.r_[0.0, np.ones(t.size - 1)], 0.004)
    assert y[40] == pytest.approx(1.0 - math.exp(-40 * 1e-4 / 0.004), rel=1e-9)


@pytest.mark.timeout(300)
def test_cli_reports_confusion_and_false_alarms_with_and_without_artifacts(tmp_path) -> None:
    """``rig validate-diagnosis`` runs our generator with the artefacts by default (the JSON
    says so, with the per-effect confusion and the false alarms on null cases) and without
    them on ``--no-artifacts``."""
    for flag, expect in (([], True), (["--no-artifacts"], False)):
        out = subprocess.run([sys.executable, "-m", "rig", "validate-diagnosis", "--cases", "1",
                              "--seed", "5", *flag, "--json", str(tmp_path / "s.json")],
                             capture_output=True, text=True, timeout=280)
        assert out.returncode == 0, out.stderr
        s = json.loads((tmp_path / "s.json").read_text())
        assert s["artifacts"] is expect
        assert ("with a real rig's" if expect else "without a real rig's") in out.stdout
        assert set(s["per_effect"]) == {"friction"} and "false_alarms" in s
        assert "none_cases" in s and s["confusion"]["friction"]
        truth = s["results"][0]
        assert truth["truth"] == "friction"
