"""One verdict vocabulary everywhere (issue 21, items 3, 13, 14, 20 and 22): ``rig runs`` (table
and ``--json``), ``rig spc`` with a NaN in the index, ``Store.runs(outcome=...)`` and the
page's history API. The stores are written through the ordinary store API by
:func:`rig.store.synthetic_runs.write_campaign` (closed-form dead-zone loops, recorded with limits
and outcomes as a measured campaign records them); the commands run as processes.
"""

from __future__ import annotations

import json
import os
import re
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from rig.store import Store
from rig.store.synthetic_runs import write_campaign
from tests.support.paths import REPO as ROOT

UNIT = json.loads((ROOT / "rig/examples/units/seed000-pair1.json").read_text())


def _rig(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("RIG_STORE", "RIG_SAMPLES_DIR")}
    env["COLUMNS"] = "200"  # the tables whole (test_narrow_cli.py checks 80 columns)
    return subprocess.run([sys.executable, "-c", "from rig.cli import main; main()", *args],
                          cwd=cwd, env=env, capture_output=True, text=True, timeout=120)


def _old_ok_without_limits(st: Store, serial: str) -> str:
    """A run as an older version recorded it: outcome "ok" and no limit in force."""
    meta = {"unit": {"serial": serial, "design": "SYN-1"}, "outcome": "ok",
            "limits": {"lost_motion_arcmin_max": None, "backlash_arcmin_max": None,
                       "stiffness_Nm_per_arcmin_min": None},
            "test": {"rated_torque_Nm": 10.0, "input_angle_deg": 0.0}}
    with st.begin_run(meta, ["t_s", "torque_Nm", "output_angle_deg"]) as rec:
        rec.append([0.0, 1.0, 0.01])
        rec.finish(result={"lost_motion_arcmin": 2.5, "uncertainty": {
            "lost_motion_arcmin": 0.004}})
    return rec.run_id


def _set_index_metric(root: Path, run_id: str, key: str, value: float) -> None:
    """Put a non-finite metric into the index row of ``run_id`` (as an older tool left it:
    the store itself refuses to write NaN)."""
    with sqlite3.connect(root / "index.sqlite") as conn:
        (metrics,) = conn.execute("SELECT metrics FROM runs WHERE run_id = ?",
                                  (run_id,)).fetchone()
        doc = json.loads(metrics)
        doc[key] = value
        conn.execute("UPDATE runs SET metrics = ? WHERE run_id = ?", (json.dumps(doc), run_id))


@pytest.fixture
def verdict_store(tmp_path: Path) -> dict:
    """A store with one run of each verdict: OK, NOT OK, NO LIMITS (new and as an older
    version recorded it), INCOMPLETE (a NaN lost motion against a limit)."""
    st = Store(tmp_path / "store")
    ids = {}
    for name, play, limits in (("OK-1", 2.0, {"lost_motion_arcmin_max": 3.0}),
                               ("NOK-1", 2.5, {"lost_motion_arcmin_max": 2.0}),
                               ("NOLIM-1", 2.2, None),
                               ("NAN-1", 2.1, {"lost_motion_arcmin_max": 3.0})):
        cid = write_campaign(st, name, play_arcmin=play, limits=limits, n_quarter=100,
                             positions_deg=(0.0,))
        (ids[name],) = [r.run_id for r in st.list_runs(campaign_id=cid)]
    ids["OLD-1"] = _old_ok_without_limits(st, "OLD-1")
    _set_index_metric(tmp_path / "store", ids["NAN-1"], "lost_motion_arcmin", float("nan"))
    st.close()
    return {"root": tmp_path / "store", "ids": ids, "tmp": tmp_path}


EXPECTED = {"OK-1": ("ok", "OK", 2.02), "NOK-1": ("not_ok", "NOT OK", 2.52),
            "NOLIM-1": ("no_limits", "NO LIMITS", 2.22),
            "OLD-1": ("no_limits", "NO LIMITS", 2.5), "NAN-1": ("incomplete", "INCOMPLETE", None)}


def test_rig_runs_shows_the_verdict_and_the_lost_motion(verdict_store: dict):
    root, ids, tmp = verdict_store["root"], verdict_store["ids"], verdict_store["tmp"]
    res = _rig("runs", "--store", str(root), cwd=tmp)
    assert res.returncode == 0, res.stderr
    header = next(line for line in res.stdout.splitlines() if "run" in line and "status" in line)
    assert "outcome" in header and "lost motion arcmin" in header
    # a run id as a whole word: "OK-1-<time>" stands inside "NOK-1-<time>" too
    rows = {serial: next(line for line in res.stdout.splitlines()
                         if re.search(rf"(?<![\w-]){re.escape(ids[serial])}(?![\w-])", line))
            for serial in ids}
    for serial, (_, word, lm) in EXPECTED.items():
        cells = [c.strip() for c in re.split(r"[│|]", rows[serial]) if c.strip()]
        assert word in cells, (serial, cells)
        if lm is not None:
            assert f"{lm:.3f}" in " ".join(cells), (serial, cells)
    assert "2.500 ± 0.004" in rows["OLD-1"]
    assert "nan (not a number)" in rows["NAN-1"]
    assert not re.search(r"\bOK\b", rows["OLD-1"].replace("NOT OK", ""))
    assert "FAIL" not in res.stdout

    res = _rig("runs", "--store", str(root), "--json", "-", cwd=tmp)
    assert res.returncode == 0, res.stderr
    doc = json.loads(res.stdout)  # strict JSON: a NaN is null
    by_id = {r["run_id"]: r for r in doc["runs"]}
    for serial, (code, word, lm) in EXPECTED.items():
        run = by_id[ids[serial]]
        assert (run["outcome"], run["verdict"]) == (code, word), serial
        assert run["lost_motion_arcmin"] == (pytest.approx(lm) if lm is not None else None)
    assert by_id[ids["OLD-1"]]["lost_motion_arcmin_u"] == 0.004


def test_store_runs_filters_on_the_words_and_the_codes(verdict_store: dict):
    import rig

    ids = verdict_store["ids"]
    st = rig.Store(verdict_store["root"])
    for text in ("NOT OK", "not_ok", "Not Ok"):
        frame = st.runs(outcome=text)
        assert list(frame["run_id"]) == [ids["NOK-1"]], text
        assert list(frame["verdict"]) == ["NOT OK"]
    assert set(st.runs(outcome="no limits")["run_id"]) == {ids["NOLIM-1"], ids["OLD-1"]}
    assert list(st.runs(outcome="ok")["run_id"]) == [ids["OK-1"]]  # the old "ok": NO LIMITS
    assert list(st.runs(outcome="INCOMPLETE")["run_id"]) == [ids["NAN-1"]]
    assert len(st.runs(outcome="no_limits", limit=1)) == 1
    everything = st.runs()
    assert dict(zip(everything["run_id"], everything["verdict"], strict=True)) == {
        ids[s]: word for s, (_, word, _) in EXPECTED.items()}
    for bad in ("FAIL", "passed"):
        with pytest.raises(ValueError, match=r"outcome must be one of ok, not_ok, incomplete, "
                                             r"no_limits \(or the words OK, NOT OK, INCOMPLETE,"
                                             r" NO LIMITS, any case\), got"):
            st.runs(outcome=bad)


def test_the_page_history_api_speaks_the_same_words(verdict_store: dict, monkeypatch):
    from fastapi.testclient import TestClient

    from rig.web import create_app
    from rig.web.settings import TOKEN_ENV, resolve_settings

    ids = verdict_store["ids"]
    st = Store(verdict_store["root"])
    monkeypatch.delenv(TOKEN_ENV, raising=False)
    settings = resolve_settings(store_root=st.root, token="verdict-test-token")
    with TestClient(create_app(settings, store=st)) as client:
        words = client.get("/api/outcomes").json()
        assert {k: v["word"] for k, v in words.items()} == {
            "ok": "OK", "not_ok": "NOT OK", "incomplete": "INCOMPLETE",
            "no_limits": "NO LIMITS"}
        assert words["no_limits"]["meaning"] == "no limits set"
        runs = {r["run_id"]: r for r in client.get("/api/runs").json()}
        for serial, (code, word, _) in EXPECTED.items():
            assert (runs[ids[serial]]["outcome"], runs[ids[serial]]["verdict"]) == (code, word)
        camps = {c["meta"]["unit"]["serial"]: c for c in client.get("/api/campaigns").json()}
        assert camps["NOK-1"]["verdict"] == "NOT OK" and camps["OK-1"]["verdict"] == "OK"
        assert camps["NOLIM-1"]["verdict"] == "NO LIMITS"
        assert camps["NAN-1"]["verdict"] == "INCOMPLETE"  # its run's NaN: no verdict
        loop = client.get(f"/api/runs/{ids['NOLIM-1']}/loop").json()
        assert (loop["outcome"], loop["verdict"]) == ("no_limits", "NO LIMITS")
        js = client.get("/static/app.js").text
        assert "FAIL" not in js and "PASS" not in js and "/api/outcomes" in js


def test_rig_spc_leaves_a_nan_run_out_and_names_it(tmp_path: Path):
    """Five units at two positions (as tests/rig/reports/test_spc.py's small line); one run's
    lost motion is NaN in the index: the charts are drawn without that run, and the run is named
    in the CLI output, the JSON and the page."""
    st = Store(tmp_path / "store")
    plays = [[2.0, 1.9], [2.1, 2.2], [2.1, 1.8], [2.6, 2.5], [2.3, 2.2]]
    for k, p in enumerate(plays):
        write_campaign(st, f"P-{k}", play_arcmin=p, design="SYN-1", unit_data=UNIT,
                       limits={"lost_motion_arcmin_max": 3.0}, n_quarter=100)
    bad = next(r for r in st.list_runs(serial="P-3")
               if r.metrics["lost_motion_arcmin"] == pytest.approx(2.62))
    st.close()
    _set_index_metric(tmp_path / "store", bad.run_id, "lost_motion_arcmin", float("nan"))
    res = _rig("spc", "--store", str(tmp_path / "store"), "--json", str(tmp_path / "spc.json"),
               "--html", str(tmp_path / "spc.html"), cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert bad.run_id in res.stdout and "not a finite number" in res.stdout
    assert "left out of the charts" in res.stdout
    text = (tmp_path / "spc.json").read_text()
    doc = json.loads(text)  # strict JSON
    assert "NaN" not in text
    (e,) = doc["excluded"]
    assert (e["run_id"], e["unit_serial"]) == (bad.run_id, "P-3")
    assert "lost_motion_arcmin = nan" in e["reason"]
    (d,) = doc["designs"]
    assert d["excluded"] == [{k: v for k, v in e.items() if k != "design"}]
    assert d["n_tests"] == 5 and d["n_runs"] == 9
    lm = d["metrics"]["lost_motion_arcmin"]
    # P-3's other run (2.5 + 0.02) is its worst now
    assert [p["value"] for p in lm["points"]] == pytest.approx([2.02, 2.22, 2.12, 2.52, 2.32])
    assert lm["chart"] is not None and lm["error"] is None
    assert [t["verdict"] for t in d["tests"]] == ["OK", "OK", "OK", "INCOMPLETE", "OK"]
    page = (tmp_path / "spc.html").read_text()
    assert bad.run_id in page and "Left out of the charts" in page
