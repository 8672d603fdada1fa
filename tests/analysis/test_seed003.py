"""Seed 003: planetary transmission error model and its Monte Carlo, against the paper.

Every comparison with the paper prints the paper's figure, ours and the difference
(``pytest -s`` shows them); docs/seed003.md explains the readings behind the numbers.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tracemalloc

import numpy as np
import pytest
from scipy import integrate, stats

from analysis.errors import AnalysisError
from analysis.models.seed003_montecarlo import (
    PAPER_FIGURES_ARCSEC,
    TransmissionErrorModel,
    draw_phases_rad,
    draw_values_um,
    max_deviation,
    max_deviation_random_phase,
    monte_carlo,
    sensitivity_ranking,
    spectrum,
)
from analysis.models.seed003_planetary import (
    ARCSEC_PER_RAD,
    PaperReading,
    PlanetaryTrain,
    Stage,
    error_sources,
    paper_train,
    stage_coefficients_arcsec_per_um,
)

TOLERANCE = 0.15  # the bound on each mean and std


def _compare(label: str, paper: float, ours: float) -> float:
    diff = (ours - paper) / paper
    print(f"{label:45s} paper {paper:7.1f}  ours {ours:7.1f}  difference {100 * diff:+6.1f} %")
    return diff


@pytest.fixture(scope="module")
def paper_results() -> dict:
    train = paper_train()
    return {
        "monte_carlo": monte_carlo(train, 50_000, seed=0),
        "max_deviation": max_deviation(train),
        "max_deviation_random_phase": max_deviation_random_phase(train, 50_000, seed=1),
    }


def test_table2_base_radii_and_ratios():
    train = paper_train()
    table2 = {(12, "I"): 5.638, (36, "I"): 16.915, (84, "I"): 39.467}
    table2 |= {(21, "III"): 9.867, (31, "III"): 14.565, (84, "III"): 39.467}
    stage_by_name = {stage.name: stage for stage in train.stages}
    for (z, name), r_b in table2.items():
        assert stage_by_name[name].base_radius_mm(z) == pytest.approx(r_b, abs=6e-4)
    assert [stage.ratio for stage in train.stages] == [8.0, 8.0, 5.0]
    assert train.total_ratio == 320.0
    assert [train.carrier_to_output_ratio(j) for j in range(3)] == [40.0, 5.0, 1.0]


def test_speeds_match_section_3_2():
    """w_s = 20 pi rad/s gives w_c = 5 pi/2 and e_Es a frequency of 35 pi/2 rad/s (Sec. 3.2)."""
    sources = {s.name: s for s in error_sources(paper_train())}
    output_rad_per_s = 20 * math.pi / 320
    assert sources["E_s_I"].frequency_per_rev * output_rad_per_s == pytest.approx(35 * math.pi / 2)
    assert -sources["E_I_I"].frequency_per_rev * output_rad_per_s == pytest.approx(5 * math.pi / 2)
    # planet relative to carrier, ring fixed: -(z_s/z_p)(w_s - w_c) = -35 pi/6
    assert sources["E_p_I"].frequency_per_rev * output_rad_per_s == pytest.approx(-35 * math.pi / 6)
    printed = {s.name: s for s in error_sources(paper_train(PaperReading(planet_speed="printed")))}
    # the paper's w_p = -20 pi/3 rad/s minus w_c
    expected = -20 * math.pi / 3 - 5 * math.pi / 2
    assert printed["E_p_I"].frequency_per_rev * output_rad_per_s == pytest.approx(expected)


def test_stage_coefficients_closed_form():
    """Eq. (7) with i^c_sp = -z_p/z_s: k_w = k_n = 1 / (1000 (r_bs + r_bI)) rad/um."""
    for stage in paper_train().stages:
        k_w, k_n = stage_coefficients_arcsec_per_um(stage)
        closed = ARCSEC_PER_RAD / (
            1000 * (stage.base_radius_mm(stage.z_sun) + stage.base_radius_mm(stage.z_ring))
        )
        assert k_w == pytest.approx(closed, rel=1e-12)
        assert k_n == pytest.approx(closed, rel=1e-12)
    sources = {s.name: s for s in error_sources(paper_train())}
    k3 = stage_coefficients_arcsec_per_um(paper_train().stages[2])[0]
    alpha = math.radians(20)
    # the carrier's two line-of-action terms add (section 3.3): 2 cos(alpha) k
    assert sources["A_c_III"].sensitivity_arcsec_per_um == pytest.approx(2 * math.cos(alpha) * k3)
    # printed Table 1: the planet's machining eccentricity nearly cancels, 2 sin(alpha) k
    assert sources["E_p_III"].sensitivity_arcsec_per_um == pytest.approx(2 * math.sin(alpha) * k3)
    consistent = paper_train(PaperReading(table1_signs="consistent"))
    flipped = {s.name: s for s in error_sources(consistent)}
    assert flipped["E_p_III"].sensitivity_arcsec_per_um == pytest.approx(
        2 * math.cos(alpha) * k3
    )
    # stage II reaches the output through the stage III ratio (eq. 11)
    k2 = stage_coefficients_arcsec_per_um(paper_train().stages[1])[0]
    assert sources["E_s_II"].sensitivity_arcsec_per_um == pytest.approx(k2 / 5)


def test_distributions_follow_eqs_16_and_17():
    sources = error_sources(paper_train())
    names = [s.name for s in sources]
    values = draw_values_um(sources, 200_000, np.random.default_rng(3))
    ecc = values[:, names.index("E_s_III")]  # T = 16 um, sigma_0 = 8 um
    sigma0, q = 8.0, math.exp(-2.0)

    def pdf(e: float) -> float:
        return e / ((1 - q) * sigma0**2) * math.exp(-(e**2) / (2 * sigma0**2))

    mean = integrate.quad(lambda e: e * pdf(e), 0, 16)[0]
    assert integrate.quad(pdf, 0, 16)[0] == pytest.approx(1.0)
    assert ecc.min() >= 0 and ecc.max() <= 16.0
    assert ecc.mean() == pytest.approx(mean, rel=0.005)
    tooth = values[:, names.index("f_I_III")]  # T/2 = 13 um = 1.6 sigma
    reference = stats.truncnorm(-1.6, 1.6, scale=13 / 1.6)
    assert tooth.min() >= -13.0 and tooth.max() <= 13.0
    assert tooth.std() == pytest.approx(reference.std(), rel=0.01)
    assert abs(tooth.mean()) < 0.05
    phases = draw_phases_rad(100_000, 1, np.random.default_rng(4))
    assert phases.min() >= 0 and phases.max() < 2 * math.pi
    assert phases.mean() == pytest.approx(math.pi, rel=0.01)


def test_max_abs_against_dense_grid():
    """The coarse-to-fine maximum is never above the truth and short of it by <= 0.25"."""
    sources = error_sources(paper_train())
    model = TransmissionErrorModel(sources)
    rng = np.random.default_rng(5)
    values = draw_values_um(sources, 600, rng)
    phases = draw_phases_rad(600, len(sources), rng)
    psi = np.linspace(0.0, 2 * math.pi, 60_001)
    dense = np.abs(model.transmission_error_arcsec(values, phases, psi)).max(axis=1)
    ours = model.max_abs_arcsec(values, phases)
    shortfall = dense - ours
    print(f"shortfall: max {shortfall.max():.4f} arcsec, min {shortfall.min():.5f} arcsec")
    assert shortfall.max() <= model.grid_error_arcsec + 0.01
    assert shortfall.min() >= -1e-3  # float32 rounding only


def test_single_sinusoid_closed_form():
    """Only the stage III carrier eccentricity at its bound: max |dtheta| = 2 cos(a) k A_c."""
    stage = Stage("III", 21, 31, 84, {("A", "c"): 15.0})
    train = PlanetaryTrain((stage,))
    k = stage_coefficients_arcsec_per_um(stage)[0]
    expected = 2 * math.cos(math.radians(20)) * k * 15.0
    result = max_deviation(train, n_phases=16)
    assert result.min_arcsec == pytest.approx(expected, abs=0.26)
    assert result.max_arcsec <= expected + 1e-3
    print(f"closed form {expected:.3f} arcsec, ours {result.mean_arcsec:.3f} arcsec")


def _assert_mean_and_std_as_paper(paper_results: dict, method: str, label: str) -> None:
    """The ``method``'s mean and std (arcsec) each within :data:`TOLERANCE` of the paper's
    (every figure printed beside the paper's)."""
    ours = paper_results[method].as_dict()
    paper = PAPER_FIGURES_ARCSEC[method]
    diffs = {key: _compare(f"{label} {key}", paper[key], ours[key]) for key in paper}
    assert abs(diffs["mean"]) <= TOLERANCE
    assert abs(diffs["std"]) <= TOLERANCE


def test_monte_carlo_against_paper(paper_results):
    """Fig. 10: mean 191", std 53", range 42"-444"; the mean and std within 15 %."""
    _assert_mean_and_std_as_paper(paper_results, "monte_carlo", "Monte Carlo")


def test_max_deviation_against_paper(paper_results):
    """Fig. 11: mean 539", std 36", range 469"-598"; the mean and std within 15 %."""
    _assert_mean_and_std_as_paper(paper_results, "max_deviation", "max deviation")


def test_max_deviation_random_phase_against_paper(paper_results):
    """Fig. 12: mean 477", std 71", range 300"-644"; the mean and std within 15 %."""
    _assert_mean_and_std_as_paper(paper_results, "max_deviation_random_phase",
                                  "max deviation, random phase")


def test_paper_conclusions_hold(paper_results):
    """Sec. 3.3: random values cut the mean by about 65 % against the maximum deviation
    method, and random phases lower the mean of the all-at-bound case."""
    mc = paper_results["monte_carlo"].mean_arcsec
    md = paper_results["max_deviation"].mean_arcsec
    rp = paper_results["max_deviation_random_phase"].mean_arcsec
    _compare("MC mean / max deviation mean (x100)", 100 * 191 / 539, 100 * mc / md)
    assert mc < 0.45 * md
    assert rp < md


def test_other_readings_as_documented():
    """The numbers docs/seed003.md gives for the readings not chosen (20,000 samples)."""
    e_f = paper_train(PaperReading(stage3_planet_row="E_f"))
    upper = sum(s.sensitivity_arcsec_per_um * s.bound_um for s in error_sources(e_f))
    print(f"E_f reading: largest possible |dtheta| {upper:.0f} arcsec < paper's 644")
    assert upper < PAPER_FIGURES_ARCSEC["max_deviation_random_phase"]["max"]
    random_phase = max_deviation_random_phase(e_f, 20_000, seed=1)
    d = _compare("E_f: random phase std", 71.0, random_phase.std_arcsec)
    assert d < -TOLERANCE
    consistent = paper_train(PaperReading(table1_signs="consistent"))
    common = max_deviation(consistent)
    d = _compare("consistent signs: max deviation mean", 539.0, common.mean_arcsec)
    assert d < -TOLERANCE
    mc = monte_carlo(consistent, 20_000, seed=0)
    d = _compare("consistent signs: Monte Carlo mean", 191.0, mc.mean_arcsec)
    assert abs(d) <= TOLERANCE


def test_spectrum_names_stage_iii_carrier():
    """Fig. 13: the strongest line is the stage III carrier installation eccentricity."""
    lines = spectrum(n_samples=16, seed=2)
    print(
        f"dominant line {lines.dominant_frequency_per_rev} cycle/rev, "
        f"{lines.dominant_amplitude_arcsec:.1f} arcsec: {lines.dominant_sources}"
    )
    assert lines.dominant_frequency_per_rev == pytest.approx(1.0)
    assert lines.dominant_sources[0] == "A_c_III"
    ranking = sensitivity_ranking(n_samples=2_000, seed=2)
    assert ranking[0].name == "A_c_III"
    stage1 = [item for item in ranking if item.name.endswith("_I")]
    assert all(item.mean_reduction_arcsec < 1.0 for item in stage1)


def test_seed_reproducible_and_chunking_invisible():
    a = monte_carlo(n_samples=5_000, seed=11)
    b = monte_carlo(n_samples=5_000, seed=11)
    c = monte_carlo(n_samples=5_000, seed=12)
    assert a == b
    assert a != c
    sources = error_sources(paper_train())
    model = TransmissionErrorModel(sources)
    rng = np.random.default_rng(7)
    values = draw_values_um(sources, 1_000, rng)
    phases = draw_phases_rad(1_000, len(sources), rng)
    whole = model.max_abs_arcsec(values, phases)
    pieces = np.concatenate([model.max_abs_arcsec(values[i : i + 97], phases[i : i + 97])
                             for i in range(0, 1_000, 97)])
    np.testing.assert_array_equal(whole, pieces)


def test_memory_does_not_grow_with_samples():
    """Chunked evaluation: peak memory grows only by the per-sample result (8 bytes each)."""
    def peak(n: int) -> int:
        tracemalloc.start()
        monte_carlo(n_samples=n, seed=0)
        size = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        return size

    small, large = peak(8_192), peak(98_304)
    print(f"peak traced memory: {small / 2**20:.1f} MiB (8k), {large / 2**20:.1f} MiB (98k)")
    assert large - small < 3 * 8 * (98_304 - 8_192)
    # so 1,000,000 samples stay within about small + 24 MB
    assert small < 64 * 2**20


def test_bad_input_raises_analysis_error():
    with pytest.raises(AnalysisError, match="at least 2"):
        monte_carlo(n_samples=1)
    with pytest.raises(AnalysisError, match="integer"):
        monte_carlo(n_samples=2.5)  # type: ignore[arg-type]
    with pytest.raises(AnalysisError, match="z_ring"):
        Stage("X", 30, 10, 20, {})
    with pytest.raises(AnalysisError, match="tolerance"):
        Stage("X", 12, 36, 84, {("E", "s"): -1.0})
    with pytest.raises(AnalysisError, match="no term"):
        error_sources(PlanetaryTrain((Stage("X", 12, 36, 84, {("E", "c"): 5.0}),)))


def _rig(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", "from rig.cli import main; main()", *args],
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_cli_writes_json(tmp_path):
    out = tmp_path / "mc.json"
    done = _rig("montecarlo", "--samples", "3000", "--seed", "4", "--json", str(out))
    assert done.returncode == 0, done.stderr
    assert "max_deviation_random_phase" in done.stdout  # the comparison table
    assert "Monte Carlo" in done.stderr  # rich progress
    report = json.loads(out.read_text())
    for key in ("monte_carlo", "max_deviation", "max_deviation_random_phase"):
        assert set(report[key]) >= {"mean", "std", "min", "max"}
        assert report[key]["min"] <= report[key]["mean"] <= report[key]["max"]
    assert report["monte_carlo"]["samples"] == 3000
    assert report["sensitivity_ranking"][0]["source"] == "A_c_III"
    assert report["spectrum"]["dominant_sources"][0] == "A_c_III"
    assert report["reading"]["stage3_planet_row"] == "E_A_f10"


def test_cli_errors_are_one_line_exit_2(tmp_path):
    done = _rig("montecarlo", "--samples", "1", "-q")
    assert done.returncode == 2
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith("rig: error: Invalid value for '--samples' / '-n': expected from 2 "
                           "to 1e+07 samples (got 1)"), line
    done = _rig("montecarlo", "-q", "--json", str(tmp_path / "missing" / "x.json"))
    assert done.returncode == 2
    assert len(done.stderr.strip().splitlines()) == 1
    assert "missing" in done.stderr
