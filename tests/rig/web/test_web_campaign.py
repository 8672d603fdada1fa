"""A campaign set up and run from the page on the simulated rig: runs at two input angles,
lost motion against position, pass/fail with the cause, the campaign in the history,
and every sample on disk also handed to the live stream."""

from __future__ import annotations

import functools

import pytest

from rig.web.live import LiveHub
from rig.web.simulated import example_unit
from tests.support.simulated_page import identified, page_on
from tests.support.simulated_page import wait_for as page_wait_for

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(240)]

TOKEN = "campaign-operator"
AUTH = {"Authorization": f"Bearer {TOKEN}"}


wait_for = functools.partial(page_wait_for, poll_s=0.2)
"""Poll /api/status every 0.2 s until ``done(status)`` (tests/support/simulated_page.py)."""


def test_campaign_from_the_page(simulated_rig, tmp_path):
    hub = LiveHub()
    body = {
        "kind": "campaign", "name": "page-campaign",
        "unit": {**example_unit("seed000-pair1"), "serial": "pair1-web"},
        "plan": {"rated_torque_Nm": 10.0, "steps_per_quarter": 2, "pre_cycles": 0},
        "axes": {"positions_deg": [0.0, 180.0]},
        "limits": {"lost_motion_arcmin_max": 0.01},  # impossible: the cause is named
    }
    with page_on(simulated_rig, tmp_path / "store", TOKEN, hub) as (client, store, _):
        wait_for(client, lambda s: s["state"] == "idle", 90.0)
        preview = client.post("/api/plan/preview", json=body).json()
        assert preview["n_runs"] == 2 and preview["fits"] is True
        assert client.post("/api/devices/input-lock", json={"confirm": True},
                           headers=AUTH).status_code == 200
        r = client.post("/api/control/start", json=identified(body), headers=AUTH)
        assert r.status_code == 200, r.text
        done = wait_for(client, lambda s: s["state"] in ("completed", "aborted"), 150.0)
        assert done["state"] == "completed", done["fault"]
        result = done["last_result"]
        campaigns = client.get("/api/campaigns").json()

    assert result["kind"] == "campaign" and result["n_completed"] == 2
    by_position = result["lost_motion_by_position"]
    assert [p["input_angle_deg"] for p in by_position] == [0.0, 180.0]
    assert all(0.5 < p["lost_motion_arcmin"] < 10.0 for p in by_position)
    assert result["passed"] is False
    low, high = result["batch"]["band_95_arcmin"]  # the design's production-batch band
    assert 0 < low < high
    assert all("lost_motion_arcmin" in f and "above the limit 0.01" in f
               for f in result["failures"])
    assert campaigns[0]["campaign_id"] == result["campaign_id"]
    assert campaigns[0]["status"] == "completed" and len(campaigns[0]["runs"]) == 2
    assert {r["unit_serial"] for r in campaigns[0]["runs"]} == {"pair1-web"}

    # every row written to disk went to the live stream too (decimated only for display)
    assert hub.rows_in == sum(store.load_run(r["run_id"]).n_samples
                              for r in campaigns[0]["runs"])
