"""Database stores: choosing the back-end, schema migrations, history queries, errors.

Tests taking ``make_store`` run on both back-ends; the others are about PostgreSQL (a
throw-away cluster, tests/support/pg_server.py) or about an index made by an older version.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import psycopg
import pytest

from rig.store import Store, StoreError
from rig.store.index import SCHEMA_VERSION
from tests.support.paths import REPO

V1_STORE = REPO / "tests" / "data" / "store-v1"  # made by the code of edd5ecb (schema 1)
COLUMNS = ["t_s", "torque_Nm", "output_angle_deg"]


def rig(*args: str, cwd: Path, env: dict[str, str] | None = None
        ) -> subprocess.CompletedProcess:
    clean = {k: v for k, v in os.environ.items() if k not in ("RIG_STORE", "RIG_SAMPLES_DIR")}
    return subprocess.run([sys.executable, "-c", "from rig.cli import main; main()", *args],
                          cwd=cwd, env={**clean, **(env or {})}, capture_output=True,
                          text=True, timeout=120)


def add_run(st: Store, serial: str, outcome: str | None = None, design: str | None = None,
            lm: float = 1.0) -> str:
    meta: dict = {"unit": {"serial": serial}}
    if design is not None:
        meta["unit"]["design"] = design
    if outcome is not None:
        meta["outcome"] = outcome
    with st.begin_run(meta, COLUMNS) as rec:
        rec.append([0.0, 1.0, 2.0])
        rec.finish(result={"lost_motion_arcmin": lm})
    return rec.run_id


def test_a_store_made_by_version_1_opens_and_is_migrated(tmp_path):
    root = tmp_path / "old"
    shutil.copytree(V1_STORE, root)
    st = Store(root, create=False)
    assert st._index.schema_version() == SCHEMA_VERSION
    runs = st.list_runs()
    assert len(runs) == 4 and {r.unit_serial for r in runs} == {"OLD-1", "OLD-2", "OLD-3"}
    aborted = st.list_runs(status="aborted")
    assert [r.reason for r in aborted] == ["E-stop"]
    camp = st.list_campaigns()[0]
    assert camp.status == "completed" and camp.summary == {"verdict": "ok"}
    done = st.list_runs(campaign_id=camp.campaign_id)
    assert sorted(r.metrics["lost_motion_arcmin"] for r in done) == [1.5, 2.5]
    assert all(r.outcome is None for r in runs)  # version 1 had no outcome column
    assert st.load_run(done[0].run_id).n_samples == 5
    assert len(st.list_runs(serial="OLD-2")) == 2
    new = add_run(st, "NEW-1", outcome="pass")  # and it takes new runs
    assert st.get_run(new).outcome == "pass"
    assert Store(root)._index.schema_version() == SCHEMA_VERSION  # a second open: no-op


def test_a_version_1_postgresql_schema_is_migrated(pg_server, tmp_path):
    from rig.store.index_pg import _PG_MIGRATIONS

    url = pg_server.create_schema()
    with psycopg.connect(url, autocommit=True) as conn:
        for statement in _PG_MIGRATIONS[1]:
            conn.execute(statement)
        conn.execute("CREATE TABLE rig_schema (version INTEGER NOT NULL)")
        conn.execute("INSERT INTO rig_schema VALUES (1)")
        conn.execute(
            "INSERT INTO runs (run_id, calibration, software_version, status, started_at, "
            "path, metrics) VALUES ('OLD-1-20260101T000000Z-1', '[]', '0.0.9', 'completed', "
            "'2026-01-01T00:00:00Z', 'runs/OLD-1-20260101T000000Z-1', "
            "'{\"lost_motion_arcmin\": 2.0}')")
    st = Store(url, samples=tmp_path, create=False)
    assert st._index.schema_version() == SCHEMA_VERSION
    (old,) = st.list_runs()
    assert (old.run_id, old.metrics, old.outcome) == (
        "OLD-1-20260101T000000Z-1", {"lost_motion_arcmin": 2.0}, None)
    add_run(st, "NEW-1", outcome="fail")
    assert [r.unit_serial for r in st.list_runs(outcome="fail")] == ["NEW-1"]


def test_a_newer_postgresql_schema_is_a_clear_error(pg_url, tmp_path):
    Store(pg_url, samples=tmp_path)
    with psycopg.connect(pg_url, autocommit=True) as conn:
        conn.execute("INSERT INTO rig_schema VALUES (99)")
    with pytest.raises(StoreError, match="schema version 99 is newer"):
        Store(pg_url, samples=tmp_path)


def test_history_queries_by_serial_date_outcome_and_design(make_store, tmp_path):
    st = make_store(tmp_path)
    ids = {
        "a": add_run(st, "S-1", outcome="pass", design="RV-40E"),
        "b": add_run(st, "S-2", outcome="fail", design="RV-40E"),
        "c": add_run(st, "S-1", outcome={"passed": False}, design="RV-80E"),
        "d": add_run(st, "S-3"),
    }
    assert {r.run_id for r in st.list_runs(serial="S-1")} == {ids["a"], ids["c"]}
    assert {r.run_id for r in st.list_runs(outcome="fail")} == {ids["b"], ids["c"]}
    assert [r.run_id for r in st.list_runs(outcome="pass")] == [ids["a"]]
    assert {r.run_id for r in st.list_runs(design="RV-40E")} == {ids["a"], ids["b"]}
    first = st.get_run(ids["a"]).started_at
    assert len(st.list_runs(since=first[:10])) == 4
    assert st.list_runs(until=first[:10]) == []
    assert len(st.list_runs(since=first, until="2999-01-01")) == 4
    assert [r.run_id for r in st.list_runs()] == [ids["d"], ids["c"], ids["b"], ids["a"]]
    with pytest.raises(ValueError, match="since: '31.12.2026' is not an ISO 8601"):
        st.list_runs(since="31.12.2026")
    audit = st.audit(ids["b"])
    assert [a["action"] for a in audit] == ["run started", "run completed"]
    assert audit[0]["pid"] == os.getpid()


def test_a_missing_or_unreadable_sample_file_is_reported_by_run_id(make_store, tmp_path):
    st = make_store(tmp_path)
    gone = add_run(st, "GONE")
    broken = add_run(st, "BROKEN")
    shutil.rmtree(st.run_path(gone))
    samples = next(p for p in st.run_path(broken).iterdir() if p.name.startswith("samples"))
    samples.write_bytes(b"\x00\xff garbage \x00")
    with pytest.raises(StoreError, match=f"run {gone}: its files cannot be read"):
        st.load_run(gone)
    with pytest.raises(StoreError, match=f"run {broken}: its files cannot be read"):
        st.load_run(broken)


def test_results_are_kept_per_software_version(make_store, tmp_path):
    st = make_store(tmp_path)
    run_id = add_run(st, "R-1")
    assert st.add_result(run_id=run_id, software_version="0.1.0", metrics={"x": 1.0})
    assert not st.add_result(run_id=run_id, software_version="0.1.0", metrics={"x": 9.0})
    assert st.add_result(run_id=run_id, software_version="0.2.0", metrics={"x": 2.0})
    got = st.results(run_id=run_id)
    assert [(r["software_version"], r["metrics"]) for r in got] == [
        ("0.1.0", {"x": 1.0}), ("0.2.0", {"x": 2.0})]
    with pytest.raises(ValueError, match="exactly one"):
        st.add_result(software_version="0.1.0")


def test_a_database_store_needs_a_samples_folder_and_a_reachable_server(
        pg_server, tmp_path):
    url = pg_server.create_schema()
    with pytest.raises(StoreError, match="--samples DIR or RIG_SAMPLES_DIR"):
        Store(url)
    out = rig("runs", "--store", url, cwd=tmp_path)
    assert out.returncode == 2 and "--samples DIR or RIG_SAMPLES_DIR" in out.stderr
    out = rig("runs", "--store", url, "--samples", str(tmp_path), cwd=tmp_path)
    assert out.returncode == 2, out.stdout
    assert "no store at postgresql://" in out.stderr and "no rig tables" in out.stderr
    dead = f"postgresql://postgres:secret@127.0.0.1:{pg_server.port + 1}/postgres"
    out = rig("runs", "--store", dead, cwd=tmp_path, env={"RIG_SAMPLES_DIR": str(tmp_path)})
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1
    assert "cannot open the store database" in out.stderr and "secret" not in out.stderr


def test_rig_runs_json_on_postgresql_lists_every_run_once(pg_url, tmp_path):
    st = Store(pg_url, samples=tmp_path / "samples")
    ids = {add_run(st, f"U-{k}") for k in range(5)}
    out = rig("runs", "--json", "-", cwd=tmp_path,
              env={"RIG_STORE": pg_url, "RIG_SAMPLES_DIR": str(tmp_path / "samples")})
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    listed = [r["run_id"] for r in doc["runs"]]
    assert sorted(listed) == sorted(ids) and len(listed) == 5
    assert doc["store"] == pg_url
    assert all(Path(r["path"]).parent == tmp_path / "samples" / "runs" for r in doc["runs"])


def test_the_pages_history_reads_either_back_end(make_store, tmp_path, monkeypatch):
    from fastapi.testclient import TestClient

    from rig.store.synthetic_runs import write_campaign
    from rig.web import create_app
    from rig.web.settings import TOKEN_ENV, resolve_settings

    st = make_store(tmp_path / "store")
    cid = write_campaign(st, "H-1", play_arcmin=[2.0, 2.1])
    monkeypatch.delenv(TOKEN_ENV, raising=False)
    settings = resolve_settings(store_root=st.root, token="history-test-token")
    with TestClient(create_app(settings, store=st)) as client:
        runs = client.get("/api/runs").json()
        assert [r["run_id"] for r in runs] == [r.run_id for r in st.list_runs()]
        assert len(runs) == 2 and {r["campaign_id"] for r in runs} == {cid}
        loop = client.get(f"/api/runs/{runs[0]['run_id']}/loop").json()
        assert loop["n_samples"] == 4001 and loop["metrics"]["backlash_arcmin"] == \
            pytest.approx(2.1, abs=1e-9)
        camps = client.get("/api/campaigns").json()
        assert [c["campaign_id"] for c in camps] == [cid]
