"""`rig analyse` end to end on files: the bundled example runs, campaigns and bad input."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from analysis.models.nominal import reference_nominal_model
from rig.examples import RUNS_DIR
from rig.results.analyse import METRIC_KEYS, analyse_run
from rig.runformat import Run, read_run, write_run

RIG = [sys.executable, "-c", "from rig.cli import main; main()"]


def rig(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*RIG, *args], capture_output=True, text=True, timeout=120)


def test_single_run_json_keys_and_truth(tmp_path: Path) -> None:
    out = tmp_path / "m.json"
    png = tmp_path / "loop.png"
    res = rig("analyse", str(RUNS_DIR / "pair1-pos000"), "--json", str(out), "--plot", str(png))
    assert res.returncode == 0, res.stderr
    d = json.loads(out.read_text())
    for key in ("run_id", *METRIC_KEYS, "model"):
        assert key in d
    for key in ("lost_motion_arcmin", "backlash_arcmin", "stiffness_Nm_per_arcmin"):
        assert isinstance(d["model"][key], float)
    assert d["run_id"] == "pair1-pos000"
    truth = read_run(RUNS_DIR / "pair1-pos000").meta["generator"]
    u = d["uncertainty"]
    # the generator's injected truth, within 3 standard uncertainties
    assert abs(d["lost_motion_arcmin"] - truth["true_lost_motion_arcmin"]) <= 3 * u[
        "lost_motion_arcmin"
    ]
    assert abs(d["backlash_arcmin"] - truth["true_backlash_arcmin"]) <= 3 * u["backlash_arcmin"]
    assert abs(d["stiffness_Nm_per_arcmin"] - truth["true_stiffness_Nm_per_arcmin"]) <= 3 * u[
        "stiffness_Nm_per_arcmin"
    ]
    # the model is the reference nominal model of the run's unit data (run-format.md)
    model = reference_nominal_model(read_run(RUNS_DIR / "pair1-pos000").unit)
    assert d["model"]["backlash_arcmin"] == pytest.approx(model.play_arcmin)
    assert d["model"]["lost_motion_arcmin"] == pytest.approx(
        model.play_arcmin + 2 * 0.03 * 10.0 / model.stiffness_Nm_per_arcmin
    )
    assert d["model"]["stiffness_Nm_per_arcmin"] == pytest.approx(model.stiffness_Nm_per_arcmin)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000


def test_campaign_lists_runs_and_shows_runout(tmp_path: Path) -> None:
    out = tmp_path / "c.json"
    res = rig("analyse", str(RUNS_DIR / "campaign-pair1-positions"), "--json", str(out))
    assert res.returncode == 0, res.stderr
    d = json.loads(out.read_text())
    runs = d["runs"]
    assert [r["run_id"] for r in runs] == [
        "pair1-pos000", "pair1-pos090", "pair1-pos180", "pair1-pos270"
    ]
    lost = np.array([r["lost_motion_arcmin"] for r in runs])
    truth = []
    for r in runs:
        meta = read_run(RUNS_DIR / "campaign-pair1-positions" / r["run_id"]).meta
        truth.append(meta["generator"]["true_lost_motion_arcmin"])
    assert np.max(np.abs(lost - np.array(truth))) < 0.02  # arcmin
    assert np.ptp(lost) > 1.0  # the runout makes the play vary with the locking position


def test_harmonic_drive_profile_uses_4_percent() -> None:
    run = read_run(RUNS_DIR / "pair1-pos000")
    nab = analyse_run(run, profile="nabtesco").to_dict()
    hd = analyse_run(run, profile="harmonic-drive").to_dict()
    assert nab["lost_motion_pct"] == 3.0 and hd["lost_motion_pct"] == 4.0
    k = nab["model"]["stiffness_Nm_per_arcmin"]
    assert hd["model"]["lost_motion_arcmin"] - nab["model"]["lost_motion_arcmin"] == pytest.approx(
        2 * 0.01 * 10.0 / k
    )
    assert hd["lost_motion_arcmin"] > nab["lost_motion_arcmin"]


def test_run_short_of_rated_torque_gets_metric_error_not_number(tmp_path: Path) -> None:
    run = read_run(RUNS_DIR / "pair1-pos000")
    keep = np.abs(run.torque_Nm) <= 6.0  # the run reaches only 60 % of rated
    data = {k: (v[keep] if isinstance(v, np.ndarray) else v) for k, v in run.data.items()}
    short = Run(meta=dict(run.meta), columns=list(run.columns), data=data)
    write_run(short, tmp_path / "short")
    out = tmp_path / "s.json"
    res = rig("analyse", str(tmp_path / "short"), "--json", str(out))
    assert res.returncode == 0, res.stderr
    d = json.loads(out.read_text())
    assert d["stiffness_Nm_per_arcmin"] is None
    assert "100 % of rated" in d["errors"]["stiffness_Nm_per_arcmin"]
    assert isinstance(d["lost_motion_arcmin"], float)  # the others are still computed


def test_malformed_csv_is_one_line_with_file_line_column(tmp_path: Path) -> None:
    folder = tmp_path / "bad"
    shutil.copytree(RUNS_DIR / "pair1-pos000", folder)
    lines = (folder / "samples.csv").read_text().splitlines()
    fields = lines[7].split(",")
    fields[1] = "12..5"
    lines[7] = ",".join(fields)
    (folder / "samples.csv").write_text("\n".join(lines) + "\n")
    res = rig("analyse", str(folder))
    assert res.returncode == 2
    message = res.stderr.strip()
    assert len(message.splitlines()) == 1
    assert "samples.csv:8:2" in message and "torque_Nm" in message


def test_missing_path_and_missing_rated_torque(tmp_path: Path) -> None:
    res = rig("analyse", str(tmp_path / "nowhere"))
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1
    run = read_run(RUNS_DIR / "pair1-pos000")
    meta = dict(run.meta)
    meta["test"] = {k: v for k, v in run.test.items() if k != "rated_torque_Nm"}
    write_run(Run(meta=meta, columns=list(run.columns), data=dict(run.data)), tmp_path / "nr")
    res = rig("analyse", str(tmp_path / "nr"))
    assert res.returncode == 2 and "rated_torque_Nm" in res.stderr
    res = rig("analyse", str(tmp_path / "nr"), "--rated-torque", "10")
    assert res.returncode == 0, res.stderr


def test_unknown_unit_keys_and_missing_face_width_are_reported(tmp_path: Path) -> None:
    run = read_run(RUNS_DIR / "pair1-pos000")
    meta = json.loads(json.dumps(run.meta))
    meta["unit"]["surface_finish_um"] = 0.4
    del meta["unit"]["face_width_mm"]
    write_run(Run(meta=meta, columns=list(run.columns), data=dict(run.data)), tmp_path / "u")
    out = tmp_path / "u.json"
    res = rig("analyse", str(tmp_path / "u"), "--json", str(out))
    assert res.returncode == 0, res.stderr
    d = json.loads(out.read_text())
    text = " ".join(d["assumptions"])
    assert "surface_finish_um" in text and "face_width_mm" in text
    assert d["model"]["stiffness_Nm_per_arcmin"] is None  # unknown, never a made-up number


def _analyse_on_the_kinds_model(unit_file: str, model_of: Any, rated_Nm: float,
                                offset_deg: float, seed: int, name: str) -> tuple[dict, Any]:
    """A GB/T step run (``rated_Nm``) whose twist is the unit kind's own model plus 0.002'
    of noise, analysed: its model and backlash are the kind's play. Returns (result, model)."""
    from rig.examples import UNITS_DIR
    from rig.examples.generate import gbt_step_profile

    unit = json.loads((UNITS_DIR / unit_file).read_text())
    model, _ = model_of(unit)
    t_s, torque = gbt_step_profile(rated_Nm)
    twist = model.twist_arcmin(torque) + np.random.default_rng(seed).normal(0, 0.002, t_s.size)
    run = Run.from_arrays(
        name, t_s, torque, offset_deg + twist / 60.0, unit=unit,
        test={"rated_torque_Nm": rated_Nm},
    )
    d = analyse_run(run).to_dict()
    assert d["model"]["backlash_arcmin"] == pytest.approx(model.play_arcmin)
    assert d["backlash_arcmin"] == pytest.approx(model.play_arcmin, abs=0.02)
    return d, model


def test_cycloid_unit_gets_the_seed002_model() -> None:
    """Unit kind `cycloid` is compared with the seed 002 compound-cycloid loop model."""
    from analysis.models.cycloid_nominal import cycloid_nominal_model

    d, model = _analyse_on_the_kinds_model(
        "cycloid-seed002.json", lambda u: cycloid_nominal_model(u, reference_torque_Nm=200.0),
        200.0, 50.0, 5, "cycloid-demo")
    assert d["stiffness_Nm_per_arcmin"] == pytest.approx(model.stiffness_Nm_per_arcmin, rel=0.05)


def test_beveloid_unit_gets_the_seed001_model() -> None:
    """Unit kind `beveloid`: play set by the axial shift (seed 001), loop from its model."""
    from analysis.models.beveloid_nominal import beveloid_nominal_model

    _analyse_on_the_kinds_model("beveloid-seed001.json", beveloid_nominal_model, 20.0, 10.0, 6,
                                "beveloid-demo")
