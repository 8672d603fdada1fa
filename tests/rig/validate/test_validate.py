"""Blind validation at small size (rig.validate) and the two CLI commands end to end."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from rig.results.diagnose import diagnose_campaign
from rig.runformat import read_run_or_campaign, write_campaign
from rig.validate import (
    COARSE_COUNTS,
    FORMS,
    KINDS,
    LOADINGS,
    cycle_profile,
    draw_case,
    make_case,
    meets_targets,
    power_law_twist_arcmin,
    simulate_campaign,
    validate_one,
)
from simulators.offline_forms import (
    delayed,
    impact_ringing_arcsec,
    ramp_profile,
    sine_profile,
    smooth_takeup_twist_arcmin,
)
from simulators.plant.config import load_plant_config


def test_cycle_profile_closes_the_loop_and_visits_3_percent() -> None:
    p = cycle_profile(10.0, 3000)
    assert p[0] == 0.0 and p.max() == 10.0 and p.min() == -10.0
    assert np.isclose(p, 0.3).sum() > 10 and np.isclose(p, -0.3).sum() > 10


def test_power_law_stiffening_is_odd_concave_and_sized_at_rated() -> None:
    t = np.array([-10.0, -2.5, 0.0, 2.5, 10.0])
    extra = power_law_twist_arcmin(t, 10.0, 0.3, 0.5)  # 0.3 arcmin * sqrt(|T| / 10 N*m)
    assert extra.tolist() == pytest.approx([-0.3, -0.15, 0.0, 0.15, 0.3])


def test_ramp_and_sine_profiles_close_the_loop() -> None:
    """Constant-rate ramp 0 -> +T -> -T -> +T -> 0 (one |dT/dk| throughout), and a sinusoid
    over 1.5 periods with the same extremes."""
    r = ramp_profile(10.0, 601)
    assert r[0] == 0.0 and r[-1] == pytest.approx(0.0, abs=1e-12)
    assert r.max() == pytest.approx(10.0) and r.min() == pytest.approx(-10.0)
    assert np.allclose(np.abs(np.diff(r)), 0.1)  # 60 N*m of path over 600 steps
    s = sine_profile(10.0, 3001)
    assert s[0] == 0.0 and abs(s[-1]) < 1e-9 and s.max() == pytest.approx(10.0, rel=1e-5)
    assert np.argmax(s) < np.argmin(s) < len(s) - 1 - np.argmax(s[::-1])


def test_takeup_lag_and_impact_ringing() -> None:
    t = np.arange(200) / 250.0
    flange = np.where(t < 0.2, 0.0, 2.0)
    takeup = smooth_takeup_twist_arcmin(np.array([-10.0, 0.0, 0.1, 10.0]), 0.3, 0.5)
    assert takeup[1] == 0.0 and takeup[-1] == pytest.approx(0.3) and takeup[0] == -takeup[-1]
    assert 0.0 < takeup[2] < 0.1
    lagged = delayed(t, flange, 0.02)  # five samples at 250 Hz
    assert np.flatnonzero(lagged)[0] == np.flatnonzero(flange)[0] + 5
    ring = impact_ringing_arcsec(t, flange, 2.0, 40.0, 0.02)
    onset = np.flatnonzero(flange)[0]
    assert not ring[:onset + 1].any() and ring[onset + 1] > 0.5  # into the + flank
    assert abs(ring[-1]) < 1e-6  # decayed


def test_widened_generator_draws_every_form_loading_and_artifact() -> None:
    base = load_plant_config()
    drawn: dict[str, set] = {}
    loadings, counts, lags, impacts = set(), set(), 0, 0
    for kind in KINDS:
        for i in range(30):
            c = make_case(i, kind, np.random.default_rng([9, i, KINDS.index(kind)]), base,
                          widened=True)
            drawn.setdefault(kind, set()).add(c.form)
            loadings.add(c.loading)
            counts.add(c.config.rig.encoder_counts_per_rev)
            lags += c.lag_s > 0.0
            impacts += bool(c.impact)
            assert c.truth["form"] == c.form and c.truth["loading"] == c.loading
    assert drawn == {k: set(v) for k, v in FORMS.items()}
    assert loadings == set(LOADINGS) and set(COARSE_COUNTS) <= counts
    assert 0.2 < lags / (30 * len(KINDS)) < 0.5 and 0.2 < impacts / (30 * len(KINDS)) < 0.5


def test_widened_campaign_keeps_the_label_under_generator_only(tmp_path) -> None:
    """A twice-per-revolution runout on a sine loading with a coarse encoder: the plant's play
    changes with position through the center distance, the unit data written stay nominal,
    the angles sit on the encoder's counts, and the form is written only under generator."""
    base = load_plant_config()
    case = next(c for c in (make_case(i, "runout", np.random.default_rng([4, i]), base,
                                      widened=True) for i in range(60))
                if c.form == "2x" and c.config.rig.encoder_counts_per_rev < 2 ** 23)
    folder = write_campaign(simulate_campaign(case, samples=600), tmp_path / "c")
    camp = read_run_or_campaign(folder)
    step = 360.0 / case.config.rig.encoder_counts_per_rev
    for run in camp.runs:
        assert run.unit == case.config.unit
        assert np.allclose(run.output_angle_deg / step, np.round(run.output_angle_deg / step))
        raw = json.loads((folder / run.run_id / "run.json").read_text())
        assert raw["generator"]["truth"]["form"] == "2x"
        assert "2x" not in json.dumps({k: v for k, v in raw.items() if k != "generator"})
    assert len(set(np.round(case.play_change_um, 3))) > 2


def test_generator_varies_laws_units_and_noise() -> None:
    """Not one simulator's forms: friction Coulomb/Dahl/LuGre, stiffening exponential or power
    law, units around seed 000 pairs 1 and 2, noise 0.1-0.8 arcsec."""
    rng = np.random.default_rng(4)
    base = load_plant_config()
    friction = {make_case(0, "friction", rng, base).truth["law"] for _ in range(20)}
    laws = {bool(make_case(0, "stiffness_nonlinearity", rng, base).post) for _ in range(12)}
    cases = [make_case(0, "none", rng, base) for _ in range(12)]
    m_values = {c.config.unit["m_value_external_mm"][0] for c in cases}
    noise = [c.config.noise.twist_arcsec_rms for c in cases]
    assert friction == {"coulomb", "dahl", "lugre"} and laws == {True, False}
    assert len(m_values) > 6 and min(noise) >= 0.1 and max(noise) <= 0.8
    runout = make_case(0, "runout", rng, base)
    assert runout.config.unit["runout_internal_mm"] == pytest.approx(
        runout.truth["internal_mm"], rel=0.26)
    power = next(c for c in (make_case(0, "stiffness_nonlinearity", rng, base)
                             for _ in range(20)) if c.post)
    assert not power.config.effects.stiffness_nonlinearity.enabled
    assert power.post["stiffening_power_law"]["exponent"] < 0.7
    # the analysis' exponential law is not the generator's power law, and still names it
    report = diagnose_campaign(simulate_campaign(power, samples=1500)).to_dict()
    assert report["verdict"] == "stiffness_nonlinearity", report["reason"]
    assert report["shrink"] > 0.7


@pytest.mark.timeout(300)  # 12 campaigns diagnosed (CPU-bound, two processes)
@pytest.mark.alone
def test_small_validation_meets_the_targets(tmp_path) -> None:
    """One case of every kind (13 cases) from the widened generator without a real rig's
    artefacts, through ``rig validate-diagnosis --jobs 2 --no-artifacts``: every
    in-vocabulary effect, null, out of vocabulary, graded as a labelled folder is. The
    larger runs' figures are in docs/diagnosis.md."""
    out = _rig("validate-diagnosis", "--cases", str(len(KINDS) + 1), "--seed", "3",
               "--jobs", "2", "--no-artifacts", "--json", str(tmp_path / "s.json"))
    assert out.returncode == 0, out.stderr
    summary = json.loads((tmp_path / "s.json").read_text())
    n = len(KINDS) + 1
    assert summary["generator"] == "ours" and summary["cases"] == n
    assert f"ours: {summary['correct']}/{n} correct" in out.stdout
    assert meets_targets(summary["figures"]), summary["confusion"]
    assert summary["false_alarms"] == 0 and summary["figures"]["false_alarm_share"] == 0.0
    assert {k.split()[0] for k in summary["by_form"]} == {"form", "loading"}


def test_nulls_adds_null_campaigns_of_their_own_draws(tmp_path) -> None:
    """``--nulls N`` appends N null campaigns (cases n..n+N-1, their own draws) so that the
    false-alarm rate is measured on 20 nulls, not on the few of the effect cycle."""
    out = _rig("validate-diagnosis", "--cases", "1", "--nulls", "2", "--seed", "5",
               "--no-artifacts", "--json", str(tmp_path / "s.json"))
    assert out.returncode == 0, out.stderr
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["cases"] == 3 and summary["nulls_added"] == 2
    cases = [r["case"] for r in summary["results"]]
    assert cases == ["case000", "case001", "case002"]
    assert [r["truth"] for r in summary["results"][1:]] == ["none", "none"]
    assert summary["none_cases"] == 2 + (summary["results"][0]["truth"] == "none")


@pytest.mark.parametrize(("kind", "form"), [
    ("runout", "2x"), ("thermal_expansion", "quadratic"),
    ("stiffness_nonlinearity", "exponential")])
def test_other_functional_forms_are_named(kind: str, form: str) -> None:
    """Our generator's other forms (seed 0, the first case of that form): a play twice per
    crank turn is runout (the family's order-2 harmonic), a play quadratic in temperature
    thermal expansion, an exponential hardening spread over the whole range contact
    stiffening."""
    index = next(i for i in range(100) if draw_case(0, i, kind).form == form)
    res = validate_one((0, index, kind))
    assert (res.case.kind, res.case.form) == (kind, form)
    assert res.verdict == kind, res.report["reason"]


def _rig(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rig", *args], capture_output=True,
                          text=True, timeout=300)


def test_rig_diagnose_writes_json_and_self_contained_html(tmp_path) -> None:
    case = make_case(0, "thermal_expansion", np.random.default_rng(2), load_plant_config())
    folder = write_campaign(simulate_campaign(case, samples=1500), tmp_path / "campaign")
    out = _rig("diagnose", str(folder), "--json", str(tmp_path / "r.json"), "--html",
               str(tmp_path / "r.html"))
    assert out.returncode == 0, out.stderr
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["format"] == "rig-diagnosis/1"
    assert report["verdict"] == "thermal_expansion"
    assert report["localization"]["where"] == "temperature"
    page = (tmp_path / "r.html").read_text()
    assert "data:image/png;base64," in page and "http://" not in page and "https://" not in page


def test_rig_diagnose_names_a_missing_folder(tmp_path) -> None:
    out = _rig("diagnose", str(tmp_path / "nope"))
    assert out.returncode == 2
    assert "nope" in out.stderr and "no such" in out.stderr
