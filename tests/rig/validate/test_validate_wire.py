"""``rig validate-diagnosis --over-the-wire``: campaigns recorded through the real sequencer,
drivers and simulated devices (``rig sim`` around the time-domain plant with the rig's
dynamics on and one withheld effect or none), diagnosed blind and graded; the recordings
kept for ``--cases-dir/--labels``.

Two short cases (a null campaign and a friction campaign) on real simulated rigs, recorded
at the same time (``--jobs 2``: the test runs alone, so it has both cores; the pool's path
is the one a lab's validation run takes). The verdicts' quality is not judged here (the
grading is); the truth, the recorded artefacts and the report's structure are.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from rig.runformat import read_run_or_campaign
from rig.validate.wire import SCHEDULE, make_case, mesh_stiffness_Nm_per_arcmin

pytestmark = [pytest.mark.realtime, pytest.mark.alone, pytest.mark.timeout(900)]


def rig(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", "from rig.cli import main; main()", *args],
                          cwd=cwd, capture_output=True, text=True, timeout=850,
                          env={**os.environ, "COLUMNS": "200"})


def test_cases_draw_the_rigs_dynamics_at_the_issues_sizes():
    assert SCHEDULE[0] == "none" and SCHEDULE[1] == "friction"
    for k in range(len(SCHEDULE)):
        case = make_case(k, seed=3)
        t = case.truth
        assert 350 <= t["locked_resonance_Hz"] <= 1500
        assert 0.03 <= t["contact_damping_ratio"] <= 0.15
        assert 0.001 <= t["torque_lag_s"] <= 0.008 and 18 <= t["torque_adc_bits"] <= 24
        assert 0.005 <= t["drive_time_constant_s"] <= 0.030
        assert 25 <= t["drive_ripple_Hz"] <= 300
        assert 0.0005 * 10 <= t["drive_ripple_Nm"] <= 0.002 * 10
        assert 2 ** 19 <= t["encoder_counts_per_rev"] <= 2 ** 23
        plant = case.campaign["simulation"]["plant"]
        assert plant["effects"]["friction"]["enabled"]  # every unit has a little friction
        if case.effect == "thermal_expansion":
            assert case.campaign["axes"]["temperatures_C"] == [20.0, 45.0]
        if case.effect not in ("none", "friction"):
            assert plant["effects"][case.effect]["enabled"]


def test_a_series_compliance_is_drawn_mild_or_strong():
    """Issue 31 item 8 over the wire: half the series compliances leave the loaded stiffness
    only 3-8 % below seed 004 eq. (8)'s (the form that came out ``none`` at the 10 %
    tolerance), the others 26-40 % below."""
    forms = {}
    for k in range(SCHEDULE.index("shaft_compliance"), 200, len(SCHEDULE)):
        t = make_case(k, seed=5).truth
        forms.setdefault(t["form"], []).append(t["stiffness_deficit"])
        k_s = t["effect_params"]["stiffness_Nm_per_arcmin"]
        assert t["stiffness_deficit"] == pytest.approx(
            mesh_stiffness_Nm_per_arcmin() / (mesh_stiffness_Nm_per_arcmin() + k_s))
    assert set(forms) == {"mild", "linear"}
    assert all(0.03 <= d <= 0.08 for d in forms["mild"])
    assert all(d > 0.2 for d in forms["linear"])


def test_two_cases_recorded_over_the_wire_are_diagnosed_blind_and_graded(tmp_path):
    keep, out = tmp_path / "kept", tmp_path / "otw.json"
    res = rig("validate-diagnosis", "--over-the-wire", "--cases", "2", "--short", "--jobs", "2",
              "--keep", str(keep), "--json", str(out), "--verbose", cwd=tmp_path)
    assert res.returncode == 0, res.stderr[-3000:]
    summary = json.loads(out.read_text())
    assert summary["generator"] == "over-the-wire"
    assert [r["status"] for r in summary["recordings"]] == ["completed", "completed"], \
        summary["recordings"]
    assert summary["cases"] == 2 and summary["recording_errors"] == 0
    by_case = {r["case"]: r for r in summary["results"]}
    assert by_case["otw-s0-c000"]["truth"] == "none"
    assert by_case["otw-s0-c001"]["truth"] == "friction"
    for r in summary["results"]:
        assert r["status"] == "ok", r
        assert r["verdict"] in {"none", "unexplained", "ambiguous", "friction", "runout",
                                "stiffness_nonlinearity", "bearing_clearance",
                                "thermal_expansion", "torque_sensor_offset",
                                "shaft_compliance", "tooth_spacing_error", "backlash",
                                "mesh_stiffness"}
        assert isinstance(r["correct"], bool) and r["seconds"] > 0
    assert summary["none_cases"] == 1
    assert set(summary["confusion"]) == {"none", "friction"}
    assert "over-the-wire: " in res.stdout and "correct" in res.stdout

    # the recordings are campaigns as `rig campaign run --simulated` writes them, with the
    # rig's dynamics and artefacts on in the plant they were measured on
    labels = json.loads((keep / "labels.json").read_text())
    assert labels["otw-s0-c000"]["effect"] == "none"
    assert labels["otw-s0-c001"]["effect"] == "friction"
    camp = read_run_or_campaign(keep / "cases" / "otw-s0-c001")
    assert len(camp.runs) == 2
    for run in camp.runs:
        assert run.n_samples > 200
        plant = run.meta["simulation"]["plant"]
        assert 0.03 <= plant["rig"]["contact_damping_ratio"] <= 0.15
        assert plant["measurement"]["torque_lag_s"] > 0
        assert plant["effects"]["friction"]["coulomb_torque_Nm"] >= 0.15

    # and they grade again from the folder, as any labelled set does (in this process, not
    # the pool: the same verdicts whichever way they are diagnosed)
    again = tmp_path / "again.json"
    res = rig("validate-diagnosis", "--cases-dir", str(keep / "cases"),
              "--labels", str(keep / "labels.json"), "--json", str(again), cwd=tmp_path)
    assert res.returncode == 0, res.stderr[-3000:]
    regraded = json.loads(again.read_text())
    assert {r["case"]: r["verdict"] for r in regraded["results"]} == {
        c: r["verdict"] for c, r in by_case.items()}
