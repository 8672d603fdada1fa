"""Issue 31 item 7: what the gap diagnosis can test on a campaign's runs is said before
anything is measured (the plan preview, ``rig campaign run``, the page's preview), by the
diagnosis's own rules (:func:`analysis.diagnosis.design.untestable`), and it is what the
diagnosis of the measured runs then says (``design.untestable``)."""

from __future__ import annotations

import glob
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from analysis.diagnosis import _prepare
from analysis.diagnosis.policy import POLICY
from rig.plans import CampaignAxes
from rig.plans.campaign_file import load_campaign
from rig.plans.diagnosability import design_effects, effects_of_design
from rig.results.diagnose import run_input
from rig.runformat import read_run_or_campaign
from rig.web.controller import compute_preview
from rig.web.models import RunRequest
from tests.support.paths import REPO

EXAMPLES = REPO / "examples" / "campaigns"
UNIT = json.loads((REPO / "rig" / "examples" / "units" / "seed000-pair1.json").read_text())


def test_the_example_campaign_says_what_its_four_positions_can_test():
    effects = design_effects(load_campaign(EXAMPLES / "seed000-pair1.toml"))
    assert effects is not None
    assert {"runout", "tooth_spacing_error", "friction"} <= set(effects.testable)
    assert effects.untestable["thermal_expansion"].startswith("temperature does not vary by 2 K")
    assert "shaft_compliance" in effects.untestable
    assert design_effects(load_campaign(EXAMPLES / "seed000-pair1-te.toml")) is None


@pytest.mark.parametrize(("axes", "testable", "why"), [
    (CampaignAxes(positions_deg=[0.0]), (), {
        "runout": "only 1 locking position(s): runout needs 3 or more",
        "tooth_spacing_error": "one tooth pair only"}),
    (CampaignAxes(positions_deg=[0.0, 120.0, 240.0], temperatures_C=[20.0, 40.0]),
     ("runout", "thermal_expansion", "tooth_spacing_error"), {}),
    (CampaignAxes(positions_deg=[0.0, 0.0], temperatures_C=[20.0, 21.0]), (), {
        "thermal_expansion": "temperature does not vary by 2 K or more"}),
])
def test_positions_and_temperatures_decide_as_in_the_diagnosis(axes, testable, why):
    effects = effects_of_design(UNIT, 10.0, axes)
    assert set(testable) <= set(effects.testable)
    for name, reason in why.items():
        assert effects.untestable[name] == reason


def test_a_beveloid_of_equal_tooth_counts_cannot_test_tooth_spacing():
    effects = design_effects(load_campaign(EXAMPLES / "beveloid-seed001.toml"))
    assert effects is not None and "20/20" in effects.untestable["tooth_spacing_error"]


@pytest.mark.parametrize("case", sorted(glob.glob(str(REPO / "tests/data/devset/*/cases/*")))[:8])
def test_the_plan_says_what_the_diagnosis_of_its_runs_then_says(case):
    """A recorded campaign's design (its runs' locking angles and temperatures) said before
    measuring gives the same untestable effects as the diagnosis of the runs."""
    campaign = read_run_or_campaign(case)
    inputs = [run_input(r) for r in campaign.runs]
    _, prepared, _, design = _prepare(inputs, 400, POLICY)
    measured = design.why_not
    temps = [r.mean_temperature_C for r in prepared if r.mean_temperature_C is not None]
    axes = CampaignAxes(positions_deg=[i.input_angle_deg for i in inputs],
                        temperatures_C=sorted({round(t) for t in temps}) if
                        temps and max(temps) - min(temps) >= POLICY.temperature_span_K else [])
    planned = effects_of_design(inputs[0].unit, inputs[0].rated_torque_Nm, axes)
    assert set(planned.untestable) == {k for k, v in measured.items() if v}, case


def test_rig_campaign_run_preview_says_it_before_measuring(tmp_path: Path):
    env = {**os.environ, "PYTHONPATH": str(REPO), "COLUMNS": "200"}
    proc = subprocess.run([sys.executable, "-m", "rig", "campaign", "run",
                           str(EXAMPLES / "seed000-pair1.toml"), "--preview"],
                          capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120)
    assert proc.returncode == 0, proc.stderr
    text = proc.stdout + proc.stderr
    assert ("diagnosis: this design can test friction, stiffness_nonlinearity, runout, "
            "bearing_clearance, torque_sensor_offset, tooth_spacing_error") in text
    assert "diagnosis: it cannot test thermal_expansion (temperature does not vary" in text


def test_the_page_preview_of_a_campaign_says_it():
    body = {"kind": "campaign", "unit": {"z_internal": 45, "z_external": 40, "module_mm": 1.0},
            "plan": {"rated_torque_Nm": 10.0, "steps_per_quarter": 2},
            "axes": {"positions_deg": [0, 180]}}
    answer = compute_preview(RunRequest.model_validate(body), {"connected": False})
    design = answer["diagnosis_design"]
    assert "friction" in design["testable"]
    assert design["untestable"]["runout"].startswith("only 2 locking position(s)")
    single = compute_preview(RunRequest.model_validate({**body, "kind": "run"}),
                             {"connected": False})
    assert single["diagnosis_design"] is None
