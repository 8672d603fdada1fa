"""End to end for each unit kind (issue 23 items 1 and 4): the shipped example campaigns of a
cycloid (seed 002) and a beveloid (seed 001) unit, run as `rig campaign run FILE --simulated`
does (its own simulated rig process over the real protocols), slimmed to two positions and
the shortest loop: each run's lost motion within 2 % of the plant's truth recorded in its
run.json ``generator`` block, and the campaign passes or fails as its catalogue-class limit
says (cycloid: 1 arcmin, NOT OK, exit 1; beveloid: 3 arcmin, OK, exit 0).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from analysis.models.by_kind import MODEL_NAMES
from rig.reports.certificate import resolve_subject, write_certificate
from rig.runformat import read_campaign
from tests.support.hostile import page_text
from tests.support.paths import REPO as ROOT

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)


def slim_campaign(name: str, positions: list[float], folder: Path) -> Path:
    """The shipped campaign with two positions and the shortest loop (2 steps a quarter, no
    pre-cycle, no dwell); the unit file path made absolute."""
    source = ROOT / "examples" / "campaigns" / f"{name}.toml"
    text = source.read_text(encoding="utf-8")
    unit_file = tomllib.loads(text)["unit"]["file"]
    changes = {
        r'^file = .*$': f'file = "{(source.parent / unit_file).resolve().as_posix()}"',
        r'^positions_deg = .*$': f"positions_deg = {positions!r}",
        r'^steps_per_quarter = .*$': "steps_per_quarter = 2",
        r'^pre_cycles = .*$': "pre_cycles = 0",
        r'^dwell_s = .*$': "dwell_s = 0.0",
        r'^zero_rate_Nm_per_s = .*$': "zero_rate_Nm_per_s = 0.5",
    }
    for pattern, line in changes.items():
        text, count = re.subn(pattern, line, text, count=1, flags=re.MULTILINE)
        assert count == 1, pattern
    path = folder / f"{name}.toml"
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize("name, positions, exit_code, outcome", [
    ("cycloid-seed002", [0.0, 2.25], 1, "not_ok"),
    ("beveloid-seed001", [0.0, 9.0], 0, "ok"),
])
def test_example_campaign_of_each_kind(name, positions, exit_code, outcome, tmp_path):
    campaign = slim_campaign(name, positions, tmp_path)
    out = tmp_path / "result.json"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    res = subprocess.run(
        [sys.executable, "-m", "rig", "campaign", "run", str(campaign), "--simulated",
         "--store", str(tmp_path / "store"), "--json", str(out)],
        capture_output=True, text=True, timeout=600, env=env, cwd=tmp_path)
    assert res.returncode == exit_code, res.stdout[-3000:] + res.stderr[-3000:]
    result = json.loads(out.read_text())
    assert result["status"] == "completed", result["reason"]
    assert result["outcome"] == outcome
    kind = name.split("-")[0]
    runs = read_campaign(result["path"]).runs
    assert len(runs) == len(positions)
    lines = []
    for run_json, run in zip(result["runs"], runs, strict=True):
        generator = run.meta["generator"]
        assert generator["kind"] == kind
        truth = generator["true_lost_motion_arcmin"]
        measured = run_json["lost_motion_arcmin"]
        lines.append(f"{name} at {run_json['input_angle_deg']:g} deg: measured {measured:.4f}, "
                     f"true {truth:.4f} arcmin")
        assert measured == pytest.approx(truth, rel=0.02), lines[-1]
        section = generator["injected"][kind]
        assert section, "the kind's injected deviations are recorded"
        assert run.meta["unit"]["kind"] == kind
    print("\n" + "\n".join(lines))
    # the campaign's batch band is the kind's own (seed 002 / seed 001 budget), with advice
    assert result["unit_kind"] == kind and result["model_name"] == MODEL_NAMES[kind][0]
    printed = " ".join((res.stdout + res.stderr).split())
    assert f"unit kind {kind}; model ({MODEL_NAMES[kind][0]})" in printed
    assert f"production batch of this design ({MODEL_NAMES[kind][1]}, 95 %)" in printed
    assert "compensation advice:" in printed
    batch = result["batch"]
    assert batch is not None and batch["kind"] == kind
    low, high = batch["band_95_arcmin"]
    assert 0.0 < low < high
    # the certificate names the kind, its model and its band
    write_certificate(resolve_subject(result["path"], tmp_path / "store"),
                      pdf=tmp_path / "cert.pdf", html=tmp_path / "cert.html")
    text = " ".join(page_text((tmp_path / "cert.html").read_text()).split())
    model_name, band_source = MODEL_NAMES[kind]
    assert f"Unit kind {kind}" in text
    assert f"Nominal model ({model_name}): {result['model']['lost_motion_arcmin']:.3f}" in text
    assert f"({band_source}, worst position, 95 %): {low:.3f} .. {high:.3f} arcmin" in text
    assert "Compensation advice:" in text
    assert ("NOT OK" if outcome == "not_ok" else "OK") in text
    assert (tmp_path / "cert.pdf").stat().st_size > 1000
