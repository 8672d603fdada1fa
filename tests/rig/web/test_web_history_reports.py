"""History's reports of a campaign and the names of its runs, through the page's API on a
real store (FastAPI TestClient, no rig): issue 33 items 13 and 16.

- 13: a campaign aborted in its first run says in one sentence that it has no diagnosis and
  why, in its History entry and in the 409 of its diagnosis; no answer of the API shows a
  folder of the server (the diagnosis' error, an unreadable run's);
- 16: a run is listed with the plan's label the live panel calls it by.
"""

from __future__ import annotations

import json
import re

import numpy as np
from fastapi.testclient import TestClient

from rig.runformat import read_run
from rig.store import Store
from tests.rig.web.test_web_api import client, store  # noqa: F401 (the API's fixtures)
from tests.support.paths import REPO

EXAMPLE_RUN = REPO / "rig" / "examples" / "runs" / "pair1-pos000"
UNIT = json.loads((REPO / "rig" / "examples" / "units" / "seed000-pair1.json").read_text())
ESTOP = "E-STOP pressed on the control page"
ABSOLUTE_PATH = re.compile(r"(?<![\w.:/~-])/(?:[^\s/'\"<>`]+/)+")


def record_run(store: Store, campaign_id: str | None, n: int | None = None,  # noqa: F811
               status: str = "completed", label: str = "pos000-a100-r0") -> str:
    """The example run (its first ``n`` samples) recorded through the store's API, as the
    engine records one (with the plan's label); its run id."""
    run = read_run(EXAMPLE_RUN)
    meta = {k: v for k, v in run.meta.items()
            if k not in ("format", "run_id", "started_at", "status", "reason", "result",
                         "finished_at", "n_samples", "software_version", "campaign_id")}
    meta["unit"] = {**UNIT, "serial": "U-13"}
    meta["label"] = label
    rec = store.begin_run(meta, list(run.columns), campaign_id=campaign_id)
    for i in range(run.n_samples if n is None else n):
        rec.append([None if not np.isfinite(run.data[c][i]) else float(run.data[c][i])
                    for c in run.columns])
    if status == "aborted":
        rec.finish("aborted", reason=ESTOP)
    else:
        rec.finish("completed")
    return rec.run_id


def no_server_path(text: str, store: Store) -> None:  # noqa: F811
    assert str(store.root) not in text and str(store.root.resolve()) not in text, text
    assert not ABSOLUTE_PATH.search(text), text


def test_a_campaign_aborted_in_its_first_run_says_why_it_has_no_diagnosis(
        client: TestClient, store: Store):  # noqa: F811
    cid = store.create_campaign("estopped", meta={"unit": UNIT})
    record_run(store, cid, n=300, status="aborted")
    store.finish_campaign(cid, "aborted", summary={
        "reason": ESTOP, "passed": False, "failures": [f"campaign aborted: {ESTOP}"]},
        extra={"outcome": "incomplete"})
    why = f"no diagnosis: the campaign was aborted in its first run ({ESTOP})"
    listed = {c["campaign_id"]: c for c in client.get("/api/campaigns").json()}
    assert listed[cid]["no_diagnosis"] == why
    assert client.get(f"/api/campaigns/{cid}").json()["no_diagnosis"] == why
    for suffix in ("diagnosis.json", "diagnosis.html"):
        answer = client.get(f"/api/campaigns/{cid}/{suffix}")
        assert answer.status_code == 409, answer.text
        detail = answer.json()["detail"]
        assert detail == f"campaign {cid} has {why}"
        no_server_path(answer.text, store)


def test_a_completed_campaign_offers_its_diagnosis(client: TestClient, store: Store):  # noqa: F811
    cid = store.create_campaign("done", meta={"unit": UNIT})
    record_run(store, cid)
    store.finish_campaign(cid, "completed", summary={"passed": True, "failures": []})
    assert client.get(f"/api/campaigns/{cid}").json()["no_diagnosis"] is None
    running = store.create_campaign("running", meta={"unit": UNIT})
    assert client.get(f"/api/campaigns/{running}").json()["no_diagnosis"] == (
        "no diagnosis yet: the campaign is still running")


def test_no_api_error_shows_a_folder_of_the_server(client: TestClient, store: Store):  # noqa: F811
    """An unreadable run's answers name the file by its name, not by where it lies."""
    run_id = record_run(store, None)
    folder = store.get_run(run_id).path
    for f in folder.iterdir():
        if f.name.startswith("samples"):
            f.write_bytes(b"not a samples file")
    for suffix in ("/loop", "/samples.csv", "/loop.png"):
        answer = client.get(f"/api/runs/{run_id}{suffix}")
        assert answer.status_code == 409, (suffix, answer.status_code, answer.text)
        no_server_path(answer.text, store)
    (folder / "run.json").write_text("{not json", encoding="utf-8")
    answer = client.get(f"/api/runs/{run_id}")
    assert answer.status_code == 409
    no_server_path(answer.text, store)


def test_runs_are_listed_with_the_label_the_live_panel_shows(client: TestClient,  # noqa: F811
                                                             store: Store):  # noqa: F811
    run_id = record_run(store, None, label="pos090-a100-r0")
    runs = client.get("/api/runs").json()
    assert [(r["run_id"], r["label"]) for r in runs] == [(run_id, "pos090-a100-r0")]
