"""Transmission error numerics (issue 22 item 2): closed-form checks of analysis.transmission."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.ndimage import maximum_filter1d, minimum_filter1d

from analysis.errors import AnalysisError
from analysis.transmission import Kinematics, analyse_te
from analysis.transmission.eccentricity import reversal
from analysis.transmission.model_internal import geometry_from_unit
from analysis.transmission.synthetic import synthetic_te

SEED000 = {"kind": "internal_involute", "z_internal": 45, "z_external": 40, "module_mm": 1.0}
KIN = Kinematics(ratio=-8.0, output_teeth=40, mesh_per_input=45.0)


def _run(te, **kw):
    s = synthetic_te(te, **kw)
    return s, analyse_te(s.output_angle_deg, s.input_angle_deg, s.direction, KIN,
                         output_counts_per_rev=kw.get("output_counts", 2**23),
                         input_counts_per_rev=kw.get("input_counts", 2**17))


def _order(result, per, order, direction=1):
    return next(f for d, f in result.orders if d == direction and f.order.per == per
                and f.order.order == order)


def test_sinusoids_of_known_order_amplitude_and_phase_are_recovered_on_a_non_integer_record():
    def te(out, inp, d):
        return (25.0 * np.sin(np.radians(out) + math.radians(40.0))
                + 8.0 * np.sin(np.radians(inp) - math.radians(110.0))
                + 2.5 * np.sin(45.0 * np.radians(inp) + math.radians(75.0)))

    _, r = _run(te, revolutions=1.0, margin=0.37, samples_per_output_rev=40_000)
    # A sin(x + p) = A cos(x + p - 90): the phases of the cosine convention
    for per, order, amp, phase in (("output_rev", 1, 25.0, -50.0), ("input_rev", 1, 8.0, -200.0),
                                   ("mesh", 1, 2.5, -15.0)):
        for d in (1, -1):
            f = _order(r, per, order, d)
            assert f.amplitude_arcsec == pytest.approx(amp, abs=0.02), (per, d)
            assert (f.phase_deg - phase + 180) % 360 - 180 == pytest.approx(0.0, abs=0.5)
            assert f.amplitude_u_arcsec < 0.05
    assert _order(r, "output_rev", 2).amplitude_arcsec < 0.05


def test_F_i_and_f_i_equal_a_direct_computation_on_the_truth():
    rng = np.random.default_rng(3)
    steps = rng.normal(0.0, 6.0, 40)  # a per-tooth pattern of the output: 40 teeth

    def truth(out):
        tooth = np.floor(np.mod(out, 360.0) / 9.0).astype(int)
        return 30.0 * np.sin(np.radians(out) * 2.0) + steps[tooth] + 4.0 * np.sin(
            np.radians(out) * 360.0)

    _, r = _run(lambda out, inp, d: truth(out), samples_per_output_rev=100_000)
    dense = np.arange(36_000) * 0.01
    t = truth(dense)
    direct_F = float(np.ptp(t))
    w = 901  # 9 deg at 0.01 deg
    direct_f = float(np.max(maximum_filter1d(t, w, mode="wrap")
                            - minimum_filter1d(t, w, mode="wrap")))
    assert r.metrics["te_total_Fi_arcsec"] == pytest.approx(direct_F, rel=0.02)
    assert r.metrics["te_tooth_fi_arcsec"] == pytest.approx(direct_f, rel=0.02)
    assert r.metrics["te_pp_arcsec"] == pytest.approx(direct_F, rel=0.02)


def test_the_seed000_output_pitch_is_the_pinions():
    kin = geometry_from_unit(SEED000).kinematics()
    assert kin.output_teeth == 40 and kin.ratio == -8.0 and kin.mesh_per_input == 45.0
    assert {o.frequency for o in kin.extra_orders} == {7.0, 9.0}


@pytest.mark.parametrize("hysteresis_arcmin", [0.5, 3.7])
def test_hysteresis_equals_an_injected_offset(hysteresis_arcmin):
    _, r = _run(lambda out, inp, d: 12.0 * np.sin(np.radians(inp) * 2.0),
                hysteresis_arcsec=60.0 * hysteresis_arcmin)
    assert r.metrics["te_hysteresis_arcmin"] == pytest.approx(hysteresis_arcmin, abs=0.002)
    assert r.uncertainty["te_hysteresis_arcmin"] < 0.01


def test_encoder_eccentricity_is_separated_by_the_reversal_and_removed_from_later_runs():
    unit_amp, unit_phase = 15.0, 30.0

    def te(out, inp, d):
        return unit_amp * np.sin(np.radians(out) + math.radians(unit_phase))

    kw = {"ecc_amplitude_arcsec": 20.0, "ecc_phase_deg": -70.0, "noise_arcsec": 0.5}
    _, a = _run(te, index_deg=0.0, **kw)
    _, b = _run(te, index_deg=180.0, seed=1, **kw)
    fa, fb = _order(a, "output_rev", 1), _order(b, "output_rev", 1)
    # in one run the two are inseparable: the fitted order 1 is their sum
    assert fa.amplitude_arcsec == pytest.approx(abs(
        15 * np.exp(1j * np.radians(30)) + 20 * np.exp(1j * np.radians(-70))), abs=0.1)
    ecc, unit = reversal(fa.phasor(), fa.amplitude_u_arcsec, fb.phasor(), fb.amplitude_u_arcsec)
    assert ecc.amplitude_arcsec == pytest.approx(20.0, abs=0.1)
    assert ecc.phase_deg == pytest.approx(-160.0, abs=0.5)  # sin(x - 70) = cos(x - 160)
    assert abs(unit) == pytest.approx(unit_amp, abs=0.1)
    s = synthetic_te(te, seed=2, **kw)
    c = analyse_te(s.output_angle_deg, s.input_angle_deg, s.direction, KIN,
                   output_counts_per_rev=2**23, input_counts_per_rev=2**17,
                   encoder_eccentricity=ecc)
    fc = _order(c, "output_rev", 1)
    assert fc.amplitude_arcsec == pytest.approx(unit_amp, abs=0.15)
    assert fc.phase_deg == pytest.approx(unit_phase - 90.0, abs=1.0)
    assert c.metrics["te_pp_arcsec"] == pytest.approx(2 * unit_amp, abs=1.0)
    assert c.encoder_eccentricity["removed"] is True
    assert c.encoder_eccentricity["amplitude_arcsec"] == pytest.approx(20.0, abs=0.1)


def test_resolution_quantised_data_keep_the_truth_within_their_uncertainty():
    # a 2^14-count output encoder: one count is 79 arcsec, more than the TE's own size
    counts = 2**14
    q = 1_296_000 / counts

    def te(out, inp, d):
        return 30.0 * np.sin(np.radians(out) + 0.4) + 10.0 * np.sin(np.radians(inp))

    s, r = _run(te, output_counts=counts, input_counts=2**20, samples_per_output_rev=60_000)
    assert np.unique(np.diff(np.unique(s.output_angle_deg))).size <= 3  # really quantised
    u = r.uncertainty["te_pp_arcsec"]
    assert u >= q / math.sqrt(6.0) * 0.99  # the resolution is in the budget
    assert abs(r.metrics["te_pp_arcsec"] - np.ptp(te(np.arange(3600) / 10, 0 * np.arange(
        3600), 1) + 10 * np.sin(np.radians(-8 * np.arange(3600) / 10)))) < 3 * u
    f = _order(r, "output_rev", 1)
    assert abs(f.amplitude_arcsec - 30.0) < 3 * max(f.amplitude_u_arcsec, 1.0)


def test_a_run_without_a_full_revolution_each_way_is_refused():
    with pytest.raises(AnalysisError, match="full output revolution"):
        _run(lambda out, inp, d: 0 * out, revolutions=0.5, margin=0.0)


def test_tooth_windows_wrap_where_the_te_repeats_every_output_revolution() -> None:
    """f'_i on one revolution: a tooth whose rise straddles the record's cut (0 -> 50 arcsec
    over the last 4.5 deg, 50 -> 100 over the first 4.5 deg, then slowly back) is read whole
    (100) when the windows wrap, and by halves (50) when they do not: the 7-12 % low f'_i of
    2026-11-29."""
    from analysis.transmission.evaluate import figures

    n, teeth = 3600, 40
    theta = np.arange(n) * 360.0 / n
    te = np.zeros(n)
    start, fall, end = theta < 4.5, (theta >= 4.5) & (theta < 90.0), theta >= 355.5
    te[start] = 50.0 + 50.0 * theta[start] / 4.5
    te[fall] = 100.0 - 100.0 * (theta[fall] - 4.5) / 85.5
    te[end] = 50.0 * (theta[end] - 355.5) / 4.5
    values = te.reshape(1, n)
    wrapped = figures(values, teeth, periodic=True)["fi"]
    cut = figures(values, teeth, periodic=False)["fi"]
    assert wrapped == pytest.approx(100.0, abs=0.2)
    assert cut == pytest.approx(50.0, abs=0.5)  # one half of the rise either side of the cut
