"""The one measurement service of a single run (rig/measurement/single_run.py): its request,
the plant choice, the result and summary; and that the command line, the Python API and the
page measure through it instead of assembling a run themselves. No rig: the runs themselves are
measured by tests/test_measure_cli.py, tests/test_python_api.py and tests/test_web_rig.py."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from rig.core.errors import RigError
from rig.measurement.single_run import (
    LOOP_KIND,
    MeasuredRun,
    MeasureRequest,
    unit_data,
    with_simulated_plant,
)
from rig.plans import TE_KIND, LoopParams, TEParams
from rig.plans.campaign_file import Limits
from tests.support.paths import REPO as ROOT

UNIT = ROOT / "rig/examples/units/seed000-pair1.json"


def test_a_request_is_a_loop_or_a_te_run_and_builds_its_plan():
    with pytest.raises(RigError, match="LoopParams"):
        MeasureRequest()
    loop = MeasureRequest(loop=LoopParams(rated_torque_Nm=10.0), position_deg=30.0)
    assert loop.test == LOOP_KIND and loop.rated_torque_Nm == 10.0
    assert "LockInput" in [type(s).__name__ for s in loop.plan().steps()]
    te = MeasureRequest(loop=LoopParams(rated_torque_Nm=10.0),
                        te=TEParams(rated_torque_Nm=8.0, ratio=-8.0))
    assert te.test == TE_KIND and te.rated_torque_Nm == 8.0
    assert te.plan().name == TE_KIND  # the TE test wins: the loop is not measured


def test_the_simulated_plant_is_the_units_or_the_default_plants():
    request = MeasureRequest(loop=LoopParams(rated_torque_Nm=10.0))
    default = with_simulated_plant(request)
    assert default.plant is not None and default.unit == dict(default.plant.unit)
    mine = with_simulated_plant(MeasureRequest(loop=request.loop, unit=unit_data(UNIT)))
    assert mine.plant is not None
    assert mine.plant.unit["z_internal"] == unit_data(UNIT)["z_internal"]
    assert mine.unit == unit_data(UNIT)


def test_unit_data_is_a_mapping_or_a_json_object(tmp_path: Path):
    assert unit_data(None) == {} and unit_data({"serial": "A"}) == {"serial": "A"}
    (tmp_path / "list.json").write_text("[1]", encoding="utf-8")
    with pytest.raises(RigError, match="must be a JSON object"):
        unit_data(tmp_path / "list.json")


def test_measured_run_result_and_summary():
    limits = Limits(lost_motion_arcmin_max=5.0)
    with pytest.raises(RigError, match="no run was recorded: E-stop"):
        _ = MeasuredRun("aborted", "E-stop", [], limits).result
    run = {"run_id": "r1", "passed": False, "outcome": "not_ok",
           "failures": ["lost motion 6 > 5 arcmin"]}
    summary = MeasuredRun("aborted", "E-stop", [run], limits).summary()
    assert summary["status"] == "aborted" and summary["passed"] is False
    assert summary["failures"] == ["lost motion 6 > 5 arcmin", "run aborted: E-stop"]
    assert summary["limits"]["lost_motion_arcmin_max"] == 5.0 and summary["runs"] == [run]


ASSEMBLY = {"measure_plan", "run_meta", "run_result", "simulated_truth", "EngineOptions",
            "hysteresis_plan", "te_plan"}
"""What assembling a single run takes: the service's business, not a front-end's."""


@pytest.mark.parametrize("path", ["rig/commands/measure.py", "rig/api/connect.py",
                                  "rig/web/controller.py"])
def test_the_front_ends_measure_a_run_through_the_service(path: str):
    tree = ast.parse((ROOT / path).read_text(encoding="utf-8"))
    called = {n.func.id if isinstance(n.func, ast.Name) else getattr(n.func, "attr", "")
              for n in ast.walk(tree) if isinstance(n, ast.Call)}
    assert "measure_run" in called, path
    assert not called & ASSEMBLY, (path, called & ASSEMBLY)
