"""A stored transmission error run on the page's history (issue 33 item 15): ``GET
/api/runs/ID/te`` gives what the TE panel draws (the raw TE against the output angle, each
row of the turns with its direction, decimated) and the run's recorded result, verdict and
limits; never a loop. The run is recorded in the store as the rig records it
(tests/support/te_runs.py: numerics only, no rig)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from rig.results.te_curve import te_arcsec
from rig.store import Store
from rig.web import create_app
from rig.web.settings import resolve_settings
from tests.support.te_runs import store_te_unit


def test_a_stored_te_run_is_drawn_as_te_against_the_output_angle(tmp_path: Path) -> None:
    store = Store(tmp_path / "store")
    store_te_unit(store, "T-1", limits={"te_pp_max_arcsec": 320.0})
    app = create_app(resolve_settings(store_root=store.root, token="te-history"), store=store)
    with TestClient(app) as client:
        (run,) = client.get("/api/runs").json()
        run_id = run["run_id"]
        r = client.get(f"/api/runs/{run_id}/te", params={"max_points": 500})
        assert r.status_code == 200, r.text
        d = r.json()
        stored = store.load_run(run_id)
        assert d["n_samples"] == stored.n_samples
        assert len(d["output_deg"]) == len(d["te_arcsec"]) == len(d["direction"]) == 500
        assert set(d["direction"]) == {1.0, -1.0}  # the turns only, both ways
        # the raw TE of docs/run-format.md, as the page gets it live (rig/web/live_tap.py)
        raw = te_arcsec(stored.output_angle_deg, stored.input_angle_deg, stored.test["ratio"])
        rows = np.flatnonzero(stored.output_angle_deg == d["output_deg"][100])
        assert rows.size and any(d["te_arcsec"][100] == pytest.approx(float(raw[i]), abs=1e-6)
                                 for i in rows)
        assert d["result"]["te_pp_arcsec"] > 0 and d["outcome"] in ("ok", "not_ok")
        assert d["limits"]["te_pp_max_arcsec"] == 320.0 and d["status"] == "completed"
        assert client.get("/api/runs/no-such-run/te").status_code == 404
