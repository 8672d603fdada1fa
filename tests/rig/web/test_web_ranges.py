"""Issue 33 items 5 and 7e on the page's API: the OpenAPI schema states the physical ranges
the server enforces (one table, rig/core/ranges.py), a value outside is a 422 naming the
field and the range, and a plan longer than 8 h does not fit unless ``confirm_long``."""

from __future__ import annotations

import json

import pytest
from fastapi.testclient import TestClient

from rig.core import ranges
from rig.store import Store
from rig.web import create_app
from rig.web.settings import TOKEN_ENV, resolve_settings
from tests.support.paths import REPO

UNIT = json.loads((REPO / "rig" / "examples" / "units" / "seed000-pair1.json").read_text())


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory):
    root = tmp_path_factory.mktemp("ranges-store")
    with pytest.MonkeyPatch.context() as mp:
        mp.delenv(TOKEN_ENV, raising=False)
        settings = resolve_settings(store_root=root, token="operator-token-for-tests")
        with TestClient(create_app(settings, store=Store(root))) as c:
            yield c


STATED = [
    ("PlanSettings", "rated_torque_Nm", ranges.RATED_TORQUE_NM),
    ("PlanSettings", "rate_Nm_per_s", ranges.RATE_NM_PER_S),
    ("PlanSettings", "dwell_s", ranges.DWELL_S),
    ("PlanSettings", "settle_hold_s", ranges.SETTLE_HOLD_S),
    ("PlanSettings", "settle_timeout_s", ranges.SETTLE_TIMEOUT_S),
    ("PlanSettings", "sample_s", ranges.SAMPLE_S),
    ("PlanSettings", "twist_step_arcmin", ranges.TWIST_STEP_ARCMIN),
    ("PlanSettings", "zero_band_Nm", ranges.ZERO_BAND_NM),
    ("PlanSettings", "zero_rate_Nm_per_s", ranges.RATE_NM_PER_S),
    ("TESettings", "input_speed_rpm", ranges.INPUT_SPEED_RPM),
    ("AxesSettings", "positions_deg", ranges.POSITION_DEG),
    ("AxesSettings", "temperatures_C", ranges.TEMPERATURE_SETPOINT_C),
    ("RunRequest", "position_deg", ranges.POSITION_DEG),
    ("RunRequest", "torque_limit_Nm", ranges.TORQUE_LIMIT_NM),
    ("InputLockRequest", "angle_deg", ranges.POSITION_DEG),
    ("LimitSettings", "lost_motion_arcmin_max", ranges.LIMIT_ARCMIN),
    ("LimitSettings", "stiffness_Nm_per_arcmin_min", ranges.LIMIT_STIFFNESS_NM_PER_ARCMIN),
    ("LimitSettings", "te_pp_max_arcsec", ranges.LIMIT_ARCSEC),
]


def _number_schema(prop: dict) -> dict:
    """The number alternative of a property (``anyOf`` with null, or a list's items)."""
    for alt in prop.get("anyOf", [prop]):
        if alt.get("type") == "array":
            return alt["items"]
        if alt.get("type") == "number":
            return alt
    raise AssertionError(prop)


@pytest.mark.parametrize(("model", "field", "rng"), STATED,
                         ids=[f"{m}.{f}" for m, f, _ in STATED])
def test_the_schema_states_the_range_the_server_enforces(client: TestClient, model: str,
                                                        field: str, rng) -> None:
    spec = client.get("/openapi.json").json()
    number = _number_schema(spec["components"]["schemas"][model]["properties"][field])
    low = "exclusiveMinimum" if rng.low_open else "minimum"
    assert (number.get(low), number.get("maximum")) == (rng.low, rng.high), number


def _body(**change: object) -> dict:
    return {"unit": UNIT, "plan": {"rated_torque_Nm": 10.0}, **change}


@pytest.mark.parametrize(("body", "loc", "message"), [
    (_body(test="transmission_error", te={"input_speed_rpm": 0.01}),
     ["body", "te", "input_speed_rpm"], "expected from 1 to 6000 rpm"),
    (_body(plan={"rated_torque_Nm": 10.0, "dwell_s": 1e9}), ["body", "plan", "dwell_s"],
     "expected from 0 to 3600 s"),
    (_body(plan={"rated_torque_Nm": 1e308}), ["body", "plan", "rated_torque_Nm"],
     "expected greater than 0 and at most 1e+07 N·m"),
    (_body(kind="campaign", axes={"temperatures_C": [-300.0]}),
     ["body", "axes", "temperatures_C", 0], "expected from -40 to 150 °C"),
])
def test_a_value_outside_its_range_is_a_422_naming_field_and_range(
        client: TestClient, body: dict, loc: list, message: str) -> None:
    r = client.post("/api/plan/preview", json=body)
    assert r.status_code == 422, r.text
    detail = r.json()["detail"][0]
    assert detail["loc"] == loc and message in detail["msg"], detail


def test_a_long_plan_fits_only_when_confirmed(client: TestClient) -> None:
    long = _body(plan={"rated_torque_Nm": 10.0, "dwell_s": 3600.0, "steps_per_quarter": 4})
    r = client.post("/api/plan/preview", json=long)
    assert r.status_code == 200, r.text
    preview = r.json()
    assert preview["estimated_s"] > ranges.PLAN_CONFIRM_S and not preview["fits"]
    assert any("more than 8 h: confirm it with confirm_long" in p
               for p in preview["problems"]), preview["problems"]
    confirmed = client.post("/api/plan/preview", json={**long, "confirm_long": True}).json()
    assert not any("8 h" in p for p in confirmed["problems"]), confirmed["problems"]
