"""``rig runs`` run as a real process: table, JSON, default store folder, errors.

The tests taking ``store_dir`` run on both back-ends (SQLite, PostgreSQL: conftest.py).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from rig.store import RECOVERED_REASON, Store
from tests.support.paths import REPO

COLUMNS = ["t_s", "torque_Nm", "output_angle_deg"]

KILLED_WRITER = """
import os, signal, sys
from rig.store import Store
rec = Store(sys.argv[1]).begin_run({"unit": {"serial": "KILLED"}}, ["t_s", "torque_Nm",
                                    "output_angle_deg"])
rec.append([0.0, 0.0, 0.0])
rec.samples.flush()
print(rec.run_id, flush=True)
os.kill(os.getpid(), signal.SIGKILL)
"""


def rig(*args: str, cwd: Path, env_store: str | None = None,
        extra_env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("RIG_STORE", "RIG_SAMPLES_DIR")}
    env["COLUMNS"] = "200"  # the tables whole (a CI shell may say 80: tests/rig/commands/
    #                         test_narrow_cli.py checks the narrow layout)
    if env_store is not None:
        env["RIG_STORE"] = env_store
    env.update(extra_env or {})
    return subprocess.run(
        [sys.executable, "-c", "from rig.cli import main; main()", *args],
        cwd=cwd, env=env, capture_output=True, text=True, timeout=120,
    )


@pytest.fixture
def store_dir(make_store, tmp_path: Path):
    """A store with a completed, an aborted and a killed run (and a past-due calibration):
    (--store value, run ids, environment for the child, Store.location, back-end)."""
    root = tmp_path / "rig-store"
    st = make_store(root)
    target, env = make_store.target(root), make_store.env(root)
    with st.begin_run(
        {"unit": {"serial": "RV-1"}, "operator": "Li", "plan": {"name": "gbt", "version": "2"},
         "calibration": [{"sensor": "TS-9", "due": "2001-01-01"}]},
        COLUMNS,
    ) as rec:
        rec.append([0.0, 1.0, 2.0])
        rec.append([0.1, 1.5, 2.5])
        rec.finish(result={"lost_motion_arcmin": 1.5})
    ids = {"completed": rec.run_id}
    rec = st.begin_run({"unit": {"serial": "RV-2"}}, COLUMNS)
    rec.finish("aborted", reason="E-stop pressed")
    ids["aborted"] = rec.run_id
    killed = subprocess.run(
        [sys.executable, "-c", KILLED_WRITER, target],
        cwd=REPO, capture_output=True, text=True, timeout=60, env={**os.environ, **env},
    )
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    ids["killed"] = killed.stdout.strip()
    return target, ids, env, make_store.location(root), make_store.backend


def test_table_lists_runs_with_status_and_marks_the_killed_run(store_dir, tmp_path):
    root, ids, env, _, _ = store_dir
    out = rig("runs", "--store", root, cwd=tmp_path, extra_env=env)
    assert out.returncode == 0, out.stderr
    text = out.stdout
    assert f"marked aborted {ids['killed']}" in text
    for run_id in ids.values():
        assert run_id in text
    assert "completed" in text and "E-stop pressed" in text and "RV-1" in text
    assert "gbt 2" in text
    assert "cal. past due" in text and "'TS-9' was past due" in text
    assert text.index(ids["killed"], text.index("┃ run")) < text.index(ids["completed"])


def test_json_output_and_filters(store_dir, tmp_path):
    root, ids, env, location, _ = store_dir
    target = tmp_path / "runs.json"
    out = rig("runs", "--store", root, "--json", str(target), cwd=tmp_path, extra_env=env)
    assert out.returncode == 0, out.stderr
    doc = json.loads(target.read_text())
    assert doc["store"] == location and doc["recovered"] == [ids["killed"]]
    assert len(doc["runs"]) == 3  # every run once
    by_id = {r["run_id"]: r for r in doc["runs"]}
    assert set(by_id) == set(ids.values())
    done = by_id[ids["completed"]]
    assert (done["status"], done["n_samples"], done["metrics"]) == (
        "completed", 2, {"lost_motion_arcmin": 1.5}
    )
    assert done["calibration_warnings"] and done["plan_version"] == "2"
    assert by_id[ids["aborted"]]["reason"] == "E-stop pressed"
    assert by_id[ids["killed"]]["reason"] == RECOVERED_REASON
    assert by_id[ids["killed"]]["n_samples"] == 1

    out = rig("runs", "--store", root, "--json", "-", "--status", "aborted",
              "--limit", "1", cwd=tmp_path, extra_env=env)
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    assert [r["run_id"] for r in doc["runs"]] == [ids["killed"]]  # newest aborted one


def test_store_folder_defaults_to_rig_store_env_then_cwd(store_dir, tmp_path):
    root, ids, env, location, backend = store_dir
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    out = rig("runs", "--json", "-", cwd=elsewhere, env_store=root, extra_env=env)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["store"] == location
    if backend != "sqlite":  # ./rig-store below is a folder store
        return
    out = rig("runs", "--json", "-", cwd=Path(root).parent)  # ./rig-store
    assert out.returncode == 0, out.stderr
    assert {r["run_id"] for r in json.loads(out.stdout)["runs"]} == set(ids.values())
    out = rig("runs", "--help", cwd=tmp_path)
    assert out.returncode == 0 and "RIG_STORE" in out.stdout and "rig-store" in out.stdout


@pytest.mark.parametrize("command", ["runs", "spc"])
def test_a_malformed_database_url_is_one_line_naming_it(tmp_path, command: str):
    """Issue 33 item 7: a malformed PostgreSQL URL (``[::1:bad``) was an internal error."""
    out = rig(command, "--store", "postgresql://rig2:Pw-s3cret@[::1:bad/db", "--samples",
              str(tmp_path / "samples"), cwd=tmp_path)
    assert out.returncode == 2, out.stderr
    (line,) = out.stderr.strip().splitlines()
    assert line.startswith("rig: error: ") and "internal error" not in line, line
    assert "malformed" in line and "postgresql://rig2:***@[::1:bad/db" in line, line
    assert "Pw-s3cret" not in out.stdout + out.stderr


def test_missing_store_and_bad_status_exit_2_with_a_message(tmp_path):
    out = rig("runs", "--store", str(tmp_path / "none"), cwd=tmp_path)
    assert out.returncode == 2
    assert "no store at" in out.stderr and "index.sqlite" in out.stderr
    assert not (tmp_path / "none").exists()
    Store(tmp_path / "s")
    out = rig("runs", "--store", str(tmp_path / "s"), "--status", "done", cwd=tmp_path)
    assert out.returncode == 2 and "'done' is not one of" in out.stderr
    out = rig("runs", "--store", str(tmp_path / "s"), cwd=tmp_path)
    assert out.returncode == 0 and "no runs in" in out.stdout


def test_a_run_json_edited_after_indexing_is_what_every_command_says(tmp_path: Path) -> None:
    """run.json is the record, the index a copy made at the run's end (issue 33 item 7b): a
    lost motion set to NaN by hand a minute after the run (the file's time says so) makes
    ``rig runs``, ``rig spc`` and ``rig certificate`` agree on INCOMPLETE; none says OK."""
    from rig.store.synthetic_runs import write_campaign

    root = tmp_path / "store"
    st = Store(root)
    write_campaign(st, "ED-1", positions_deg=(0.0,), n_quarter=40,
                   limits={"lost_motion_arcmin_max": 9.0})
    (run,) = st.list_runs()
    assert run.outcome == "ok"
    record = run.path / "run.json"
    meta = json.loads(record.read_text())
    meta["result"]["lost_motion_arcmin"] = float("nan")
    record.write_text(json.dumps(meta, indent=2))  # NaN, as a hand edit leaves it
    later = record.stat().st_mtime + 60.0
    os.utime(record, (later, later))

    listed = rig("runs", "--store", str(root), "--json", "-", cwd=tmp_path)
    assert listed.returncode == 0, listed.stderr
    (row,) = json.loads(listed.stdout)["runs"]
    assert row["outcome"] == "incomplete" and row["lost_motion_arcmin"] is None, row
    table = rig("runs", "--store", str(root), cwd=tmp_path)
    assert "INCOMPLETE" in table.stdout and " OK " not in table.stdout, table.stdout
    spc = rig("spc", "--store", str(root), "--json", "-", cwd=tmp_path)
    assert spc.returncode == 0, spc.stderr
    (test,) = json.loads(spc.stdout)["designs"][0]["tests"]
    assert test["verdict"] == "INCOMPLETE" and test["lost_motion_arcmin"] is None, test
    cert = rig("certificate", run.run_id, "--store", str(root), "--html",
               str(tmp_path / "c.html"), cwd=tmp_path)
    assert cert.returncode == 0, cert.stderr
    assert "INCOMPLETE" in (tmp_path / "c.html").read_text()
