"""``rig measure --test transmission-error`` and campaign files with ``test =
"transmission_error"``, through the CLI on the simulated rig (its own process, as a user runs
it), against the plant's truth: the seed 000 pairs 1-4 with their eq. (4) eccentricities and
pitch errors measure a raw peak-to-peak TE within 5 % (or 2 arcsec) of the truth.

Each run: 120 rpm of the input, one output revolution each way (4 s), about 15 s with the
simulated rig's start."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rig.measurement.service import plant_config_for, write_plant_toml
from rig.plans.campaign_file import CampaignError, campaign_from_mapping, load_campaign
from rig.results.te_curve import te_curves
from rig.runformat import read_run
from simulators.clock import ManualClock
from simulators.plant import GearPlant
from tests.support.paths import REPO as ROOT

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

CAMPAIGNS = ROOT / "examples" / "campaigns"


def _rig(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", "from rig.cli import main; main()", *args],
                          capture_output=True, text=True, cwd=cwd, timeout=240)


def _within(measured: float, truth: float) -> bool:
    return abs(measured - truth) <= max(0.05 * truth, 2.0)


@pytest.mark.parametrize("pair", [1, 2, 3, 4])
def test_seed000_pair_te_campaign_measures_the_truth(pair: int, tmp_path: Path) -> None:
    path = CAMPAIGNS / f"seed000-pair{pair}-te.toml"
    camp = load_campaign(path)
    plant = plant_config_for(camp.unit_data(), camp.simulation, camp.source)
    truth = GearPlant(plant, ManualClock()).true_transmission_error(3.0)
    proc = _rig("campaign", "run", str(path), "--simulated", "--store",
                str(tmp_path / "store"), "--json", str(tmp_path / "out.json"), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]  # NO LIMITS: no TE limit set
    out = json.loads((tmp_path / "out.json").read_text())
    (run_info,) = out["runs"]
    assert run_info["status"] == "completed"
    run = read_run(run_info["path"])
    assert run.meta["test"]["kind"] == "transmission_error"
    d = run.data
    curves = te_curves(d["output_angle_deg"], d["input_angle_deg"], d["direction"], -8.0)
    for name in ("forward", "reverse"):
        assert _within(curves[name]["pp_arcsec"], truth[name]["pp_arcsec"]), \
            (pair, name, curves[name]["pp_arcsec"], truth[name]["pp_arcsec"])
    assert _within(run_info["te_raw"]["pp_arcsec"], truth["te_pp_arcsec"])


def test_rig_measure_transmission_error_on_the_simulated_rig(tmp_path: Path) -> None:
    camp = load_campaign(CAMPAIGNS / "seed000-pair1-te.toml")
    plant = plant_config_for(camp.unit_data(), camp.simulation, camp.source)
    plant_toml = write_plant_toml(plant, tmp_path / "plant.toml")
    truth = GearPlant(plant, ManualClock()).true_transmission_error(2.0)
    proc = _rig("measure", "--simulated", "--plant", str(plant_toml), "--test",
                "transmission-error", "--speed", "120", "--brake", "0.2", "--revolutions", "1",
                "--store", str(tmp_path / "store"), "--json", str(tmp_path / "run.json"),
                cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "TE peak-to-peak (raw)" in proc.stderr
    result = json.loads((tmp_path / "run.json").read_text())
    assert result["status"] == "completed" and result["outcome"] == "no_limits"
    run = read_run(result["path"])
    test = run.meta["test"]
    assert (test["input_speed_rpm"], test["brake_torque_fraction"],
            test["output_revolutions"]) == (120.0, 0.2, 1.0)
    assert test["brake_torque_Nm"] == pytest.approx(2.0)
    assert np.ptp(run.data["output_angle_deg"][run.data["direction"] == -1]) >= 360.0
    assert _within(result["te_raw"]["pp_arcsec"], truth["te_pp_arcsec"])


def test_rig_measure_te_preview_and_bad_options(tmp_path: Path) -> None:
    proc = _rig("measure", "--test", "transmission-error", "--preview", "--speed", "60",
                cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "turn input forward at 60 rpm for 1 output rev" in proc.stderr
    assert "turn input reverse" in proc.stderr
    for args, words in ((["--brake", "3"], "--brake"), (["--revolutions", "0.5"],
                                                        "--revolutions"),
                        (["--speed", "-5"], "--speed"), (["--test", "te"], "--test")):
        proc = _rig("measure", "--test", "transmission-error", "--preview", *args,
                    cwd=tmp_path)
        assert proc.returncode == 2 and words in proc.stderr, (args, proc.stderr)
    unit = tmp_path / "unit.json"
    unit.write_text(json.dumps({"kind": "beveloid", "serial": "b1"}))
    proc = _rig("measure", "--test", "transmission-error", "--preview", "--unit", str(unit),
                cwd=tmp_path)
    assert proc.returncode == 2 and "--ratio" in proc.stderr
    proc = _rig("measure", "--test", "transmission-error", "--preview", "--unit", str(unit),
                "--ratio", "-50", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr


def test_te_campaign_file_keys_are_checked() -> None:
    base = {"name": "te", "test": "transmission_error",
            "unit": {"file": str(ROOT / "rig/examples/units/seed000-pair1.json")},
            "plan": {"rated_torque_Nm": 10.0}}
    camp = campaign_from_mapping(base, "te.toml")
    assert camp.te_params().ratio == -8.0
    assert camp.build_plan().name == "transmission_error-campaign"
    with pytest.raises(CampaignError, match="te.toml: te.brake_torque_fraction"):
        campaign_from_mapping({**base, "te": {"brake_torque_fraction": 2.0}}, "te.toml")
    with pytest.raises(CampaignError, match="positions"):
        campaign_from_mapping({**base, "axes": {"positions_deg": [0.0, 90.0]}}, "te.toml")
    with pytest.raises(CampaignError, match="test"):
        campaign_from_mapping({**base, "test": "transmission-errors"}, "te.toml")
    with pytest.raises(CampaignError, match="te.ratio"):
        campaign_from_mapping({**base, "unit": {"kind": "beveloid", "serial": "x"}},
                              "te.toml")


def test_the_page_opens_a_te_campaign_file_as_a_te_request() -> None:
    from rig.web.campaign_files import example_setup
    from rig.web.controller import build_plan
    from rig.web.models import RunRequest

    setup = example_setup("seed000-pair2-te")
    request = setup["request"]
    assert request["test"] == "transmission_error"
    assert request["te"]["input_speed_rpm"] == 120.0
    assert request["te"]["brake_torque_fraction"] == 0.3
    req = RunRequest.model_validate({k: v for k, v in request.items() if v is not None})
    plan = build_plan(req)
    assert plan.name == "transmission_error-campaign"
    assert any("turn input reverse at 120 rpm" in line for line in plan.listing())
    loop = example_setup("seed000-pair2")["request"]
    assert loop["test"] == "lost_motion" and "te" not in loop
