"""Blind validation at small size (rig.validate) and the two CLI commands end to end."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from rig.diagnose import diagnose_campaign
from rig.runformat import write_campaign
from rig.validate import (
    KINDS,
    cycle_profile,
    make_case,
    meets_targets,
    power_law_twist_arcmin,
    run_validation,
    simulate_campaign,
    summarise,
)
from simulators.plant_config import load_plant_config


def test_cycle_profile_closes_the_loop_and_visits_3_percent() -> None:
    p = cycle_profile(10.0, 3000)
    assert p[0] == 0.0 and p.max() == 10.0 and p.min() == -10.0
    assert np.isclose(p, 0.3).sum() > 10 and np.isclose(p, -0.3).sum() > 10


def test_power_law_stiffening_is_odd_concave_and_sized_at_rated() -> None:
    t = np.array([-10.0, -2.5, 0.0, 2.5, 10.0])
    extra = power_law_twist_arcmin(t, 10.0, 0.3, 0.5)  # 0.3 arcmin * sqrt(|T| / 10 N*m)
    assert extra.tolist() == pytest.approx([-0.3, -0.15, 0.0, 0.15, 0.3])


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


def test_small_validation_meets_the_targets() -> None:
    """One case of every kind (12 cases): every in-vocabulary effect, null, out of
    vocabulary. The full 100-case figures are in docs/diagnosis.md and bench_diagnosis."""
    results = run_validation(len(KINDS) + 1, seed=3)
    summary = summarise(results)
    assert summary["cases"] == 12
    assert meets_targets(summary), summary
    assert summary["false_alarm_share"] == 0.0


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
