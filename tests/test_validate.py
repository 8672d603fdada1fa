"""Blind validation at small size (rig.validate) and the two CLI commands end to end."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

from rig.runformat import write_campaign
from rig.validate import (
    KINDS,
    cycle_profile,
    make_case,
    meets_targets,
    run_validation,
    simulate_campaign,
    summarise,
)
from simulators.plant_config import load_plant_config


def test_cycle_profile_closes_the_loop_and_visits_3_percent() -> None:
    p = cycle_profile(10.0, 3000)
    assert p[0] == 0.0 and p.max() == 10.0 and p.min() == -10.0
    assert np.isclose(p, 0.3).sum() > 10 and np.isclose(p, -0.3).sum() > 10


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
