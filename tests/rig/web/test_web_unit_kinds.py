"""Issue 23 on the control page's API (no browser, no rig): every unit kind with a nominal
model (analysis/models/by_kind.py) is taken by the plan preview and the start, with the kind's
model and batch band in the preview; a wrong unit field is a 422 naming ``body.unit.FIELD``
with pydantic's words, the same for every kind as for the seed 000 pair."""

from __future__ import annotations

import json

import pytest
from fastapi.testclient import TestClient

from rig.plans.campaign_file import batch_band
from rig.web.simulated import example_plant
from tests.rig.web.test_web_api import AUTH, REPO, client, store  # noqa: F401 (the API's fixtures)
from tests.support.simulated_page import identified

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

UNITS = REPO / "rig" / "examples" / "units"
INVOLUTE = json.loads((UNITS / "seed000-pair1.json").read_text())
CYCLOID = json.loads((UNITS / "cycloid-seed002.json").read_text())
BEVELOID = json.loads((UNITS / "beveloid-seed001.json").read_text())


def body(unit: dict) -> dict:
    return identified({"unit": unit, "plan": {"rated_torque_Nm": 10.0}})


@pytest.mark.parametrize("unit,seed,tolerances", [
    (CYCLOID, "seed 002", "seed 002 modification budget"),
    (BEVELOID, "seed 001", "seed 001 installation error budget"),
])
def test_each_kind_is_previewed_with_its_model_and_band(client: TestClient, unit: dict,  # noqa: F811
                                                        seed: str, tolerances: str):
    r = client.post("/api/plan/preview", json=body(unit))
    assert r.status_code == 200, r.text
    p = r.json()
    assert p["model"]["kind"] == unit["kind"]
    assert p["model"]["model_name"].startswith(seed) and p["model"]["band_source"] == tolerances
    low, high = p["batch"]["band_95_arcmin"]
    assert p["batch"]["kind"] == unit["kind"] and 0 < low < high
    # the band a campaign of this unit stores and its certificate prints (nabtesco: 3 %)
    assert p["batch"]["band_95_arcmin"] == batch_band(unit, 10.0, 3.0)["band_95_arcmin"]


@pytest.mark.parametrize("unit,loc,msg", [
    # the seed 000 pair's words, then the same mistakes in the other kinds
    *[({**unit, "module_mm": 0}, ["body", "unit", "module_mm"],
       "Input should be greater than or equal to 0.01") for unit in (INVOLUTE, CYCLOID, BEVELOID)],
    *[({**unit, "z_internal": 39, "z_external": 40}, ["body", "unit"],
       "Value error, z_internal (39) must exceed z_external (40)") for unit in (INVOLUTE, CYCLOID)],
    ({**CYCLOID, "height_coeff": 0}, ["body", "unit", "height_coeff"],
     "Input should be greater than 0"),
    ({k: v for k, v in CYCLOID.items() if k != "shape_coeff"}, ["body", "unit", "shape_coeff"],
     "Field required"),
    ({**BEVELOID, "pressure_angle_deg": 40.0}, ["body", "unit", "pressure_angle_deg"],
     "Input should be less than or equal to 35"),
    ({**BEVELOID, "z_gear": 4}, ["body", "unit", "z_gear"],
     "Input should be greater than or equal to 5"),
    ({**BEVELOID, "z_internal": 40}, ["body", "unit", "z_internal"],
     "Extra inputs are not permitted"),
    ({**CYCLOID, "kind": "harmonic"}, ["body", "unit"],
     "unit kind must be one of internal_involute, cycloid, beveloid, planetary (absent: "
     "internal_involute)"),
])
def test_a_wrong_unit_field_is_named_for_every_kind(client: TestClient, unit: dict,  # noqa: F811
                                                    loc: list, msg: str):
    for path, headers in (("/api/plan/preview", {}), ("/api/control/start", AUTH)):
        r = client.post(path, json=body(unit), headers=headers)
        assert r.status_code == 422, (path, r.text)
        assert [(d["loc"], d["msg"]) for d in r.json()["detail"]] == [(loc, msg)], path


def test_a_beveloid_unit_is_accepted_at_start(client: TestClient):  # noqa: F811
    r = client.post("/api/control/start", json=body(BEVELOID), headers=AUTH)
    # past validation: refused only because this page has no rig
    assert r.status_code == 409, r.text
    assert "rig" in r.json()["detail"]


def test_the_example_units_and_campaigns_of_every_kind(client: TestClient):  # noqa: F811
    listed = client.get("/api/units").json()
    assert listed[0]["name"] == "seed000-pair1"  # the page's default unit stays the first
    assert [u["unit"].get("kind") for u in listed][-3:] == ["cycloid", "beveloid", "planetary"]
    kinds = {u["name"]: u["unit"].get("kind") for u in listed}
    assert kinds["cycloid-seed002"] == "cycloid" and kinds["beveloid-seed001"] == "beveloid"
    assert kinds["seed000-pair1"] == "internal_involute"
    for name, kind in (("cycloid-seed002", "cycloid"), ("beveloid-seed001", "beveloid")):
        setup = client.get(f"/api/campaign-files/{name}").json()
        assert setup["request"]["unit"]["kind"] == kind, setup
        assert setup["request"]["unit"]["serial"] == name


@pytest.mark.parametrize("name,kind", [("cycloid-seed002", "cycloid"),
                                       ("beveloid-seed001", "beveloid"),
                                       ("seed000-pair1", "internal_involute")])
def test_rig_serve_builds_a_plant_around_every_example_unit(name: str, kind: str):
    plant = example_plant(name)  # rig serve --simulated --unit NAME
    assert plant.unit.get("kind", "internal_involute") == kind
    assert plant.effects.friction.enabled
    # the seed 000 pairs give their runouts, the other examples none (so none is simulated)
    assert plant.effects.runout.enabled == (kind == "internal_involute")
