"""Issue 32 item 6 on the control page's API (no browser, no rig): a planetary unit (seed 003's
3-stage paper train, ``kind`` "planetary") is a kind the page takes, like the cycloid and the
beveloid: its example unit is listed, the preview and the start accept it, its transmission
error test is planned at its own ratio (320, from the unit), a wrong field is a 422 naming
``body.unit.FIELD``, and a planetary unit has no loop model (seed 003 models the TE only), said
as the preview's assumption, never a 500. On ``rig serve --simulated`` without the planetary
plant, the page's restart for a planetary unit runs the example train as made (its errors),
not an error-free train whose TE would be noise only."""

from __future__ import annotations

import json

import pytest
from fastapi.testclient import TestClient

from rig.web.simulated import unit_plant
from simulators.clock import ManualClock
from simulators.plant import GearPlant
from simulators.plant.config import load_plant_config
from tests.rig.web.test_web_api import AUTH, REPO, client, store  # noqa: F401 (the API's fixtures)
from tests.support.simulated_page import identified

UNITS = REPO / "rig" / "examples" / "units"
PLANETARY_PLANT_UNIT = {  # the [unit] of simulators/planetary_plant.toml, as the page sends it
    "kind": "planetary", "design": "seed003-paper-train", "ratio": 320.0, "face_width_mm": 10.0,
    "planets": 3, "backlash_um": [20.0, 20.0, 20.0], "reference_torque_Nm": 20.0}


def body(unit: dict, **extra) -> dict:
    return identified({"unit": unit, "plan": {"rated_torque_Nm": 10.0}, **extra})


def test_the_planetary_example_unit_is_listed_and_is_the_plants_unit(
        client: TestClient):  # noqa: F811
    listed = {u["name"]: u["unit"] for u in client.get("/api/units").json()}
    assert listed["planetary-seed003"] == PLANETARY_PLANT_UNIT
    assert json.loads((UNITS / "planetary-seed003.json").read_text()) == PLANETARY_PLANT_UNIT


def test_a_planetary_te_test_is_previewed_at_the_units_ratio(client: TestClient):  # noqa: F811
    te = {"input_speed_rpm": 3000.0, "brake_torque_fraction": 0.2, "output_revolutions": 1.0}
    r = client.post("/api/plan/preview",
                    json=body(PLANETARY_PLANT_UNIT, test="transmission_error", te=te))
    assert r.status_code == 200, r.text
    p = r.json()
    assert p["amplitude_Nm"] == pytest.approx(2.0)  # the brake: 0.2 of 10 N*m
    steps = " ".join(p["steps"])
    assert "turn input forward at 3000 rpm" in steps and "reverse" in steps, steps
    # one output revolution each way is 320 input turns: 6.4 s each at 3000 rpm
    assert 12.8 <= p["estimated_s"] < 60.0, p["estimated_s"]
    assert p["model"] is None  # a TE test has no loop model (as for every kind)

    # the lost-motion test of a planetary unit: previewed; no loop model, and it says why
    r = client.post("/api/plan/preview", json=body(PLANETARY_PLANT_UNIT))
    assert r.status_code == 200, r.text
    p = r.json()
    assert p["model"] is None and p["batch"] is None
    assert any("planetary" in a and "no model prediction" in a for a in p["assumptions"]), p


def test_a_planetary_unit_is_accepted_at_start(client: TestClient):  # noqa: F811
    r = client.post("/api/control/start", json=body(PLANETARY_PLANT_UNIT,
                                                    test="transmission_error"), headers=AUTH)
    # past validation: refused only because this page has no rig
    assert r.status_code == 409, r.text
    assert "rig" in r.json()["detail"]


U = PLANETARY_PLANT_UNIT


@pytest.mark.parametrize("unit,loc,msg", [
    ({**U, "ratio": 81.0}, ["body", "unit", "ratio"],
     "Value error, the seed 003 paper train's ratio is 320 (got 81)"),
    ({**U, "face_width_mm": 0}, ["body", "unit", "face_width_mm"],
     "Input should be greater than 0"),
    ({k: v for k, v in U.items() if k != "face_width_mm"}, ["body", "unit", "face_width_mm"],
     "Field required"),
    ({**U, "planets": 0}, ["body", "unit", "planets"],
     "Input should be greater than or equal to 1"),
    ({**U, "backlash_um": [20.0, 20.0]}, ["body", "unit", "backlash_um"],
     "List should have at least 3 items after validation, not 2"),
    ({**U, "backlash_um": [20.0, -1.0, 20.0]}, ["body", "unit", "backlash_um", 1],
     "Input should be greater than or equal to 0"),
    ({**U, "z_internal": 40}, ["body", "unit", "z_internal"], "Extra inputs are not permitted"),
    ({**U, "kind": "harmonic"}, ["body", "unit"],
     "unit kind must be one of internal_involute, cycloid, beveloid, planetary (absent: "
     "internal_involute)"),
])
def test_a_wrong_planetary_field_is_named(client: TestClient, unit: dict,  # noqa: F811
                                          loc: list, msg: str):
    for path, headers in (("/api/plan/preview", {}), ("/api/control/start", AUTH)):
        r = client.post(path, json=body(unit, test="transmission_error"), headers=headers)
        assert r.status_code == 422, (path, r.text)
        assert [(d["loc"], d["msg"]) for d in r.json()["detail"]] == [(loc, msg)], path


def test_the_simulated_rig_restarted_for_a_planetary_unit_runs_the_train_as_made():
    plant = unit_plant(PLANETARY_PLANT_UNIT)  # the page's restart (rig/web/controller.py)
    example = load_plant_config(REPO / "simulators" / "planetary_plant.toml")
    assert plant.unit["kind"] == "planetary"
    assert plant.planetary == example.planetary  # seed 003's unit drawn inside its tolerances
    truth = GearPlant(plant, ManualClock()).true_transmission_error(2.0)
    # the example's TE (203" over one output revolution, docs/transmission-error.md), not noise
    assert truth["forward"]["pp_arcsec"] == pytest.approx(203.0, rel=0.02)
