"""``rig reanalyse``: results written back with their version, old ones kept, unreadable runs
named, resumable, on a local Dask cluster or a scheduler address.

The runs are the reference dead-zone loop (rig.store.synthetic_runs), so the re-computed metrics
are known in closed form: backlash = play, stiffness = 30 N·m/arcmin, lost motion = play +
2 * 3 % * 10 N·m / 30 N·m/arcmin = play + 0.02 arcmin.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from rig import __version__
from rig.store.reanalyse import reanalyse
from rig.store.synthetic_runs import write_campaign
from tests.support.paths import REPO

UNIT = json.loads((REPO / "rig/examples/units/seed000-pair1.json").read_text())
PLAYS = [[4.3, 4.4], [4.1, 4.5], [4.2, 4.25]]


def line(st) -> None:
    for k, plays in enumerate(PLAYS):
        write_campaign(st, f"L-{k}", play_arcmin=plays, unit_data=UNIT, design="RV-X")


def rig(*args: str, cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess:
    clean = {k: v for k, v in os.environ.items() if k not in ("RIG_STORE", "RIG_SAMPLES_DIR")}
    return subprocess.run([sys.executable, "-c", "from rig.cli import main; main()", *args],
                          cwd=cwd, env={**clean, **env}, capture_output=True, text=True,
                          timeout=180)


def test_reanalyse_writes_versioned_results_keeps_old_ones_and_names_unreadable_runs(
        make_store, tmp_path):
    root = tmp_path / "store"
    st = make_store(root)
    line(st)
    runs = st.list_runs()
    assert len(runs) == 6
    old = runs[-1].run_id
    assert st.add_result(run_id=old, software_version="0.0.1", metrics={"lost_motion_arcmin": 9})
    gone = runs[0]  # its sample file disappears from the shared storage
    for f in gone.path.iterdir():
        if f.name.startswith("samples"):
            f.unlink()
    out = rig("reanalyse", "--store", make_store.target(root), "--workers", "1", "--json",
              cwd=tmp_path, env=make_store.env(root))
    assert out.returncode == 1, out.stderr  # an unreadable run
    summary = json.loads(out.stdout)
    assert (summary["n_runs"], summary["n_campaigns"]) == (6, 3)
    # 5 runs + the 2 campaigns without the lost file; that run and its campaign are named
    assert summary["written"] == 7 and summary["skipped"] == 0
    assert len(summary["unreadable"]) == 2
    assert f"unreadable run {gone.run_id}" in out.stderr
    assert f"unreadable campaign {gone.campaign_id}" in out.stderr
    assert "re-analysing" in out.stderr  # the progress bar

    for info in runs[1:]:
        (res,) = st.results(run_id=info.run_id, software_version=__version__)
        m = res["metrics"]
        play = info.metrics["backlash_arcmin"]
        assert m["backlash_arcmin"] == pytest.approx(play, abs=1e-9)
        assert m["lost_motion_arcmin"] == pytest.approx(play + 0.02, abs=1e-9)
        assert m["stiffness_Nm_per_arcmin"] == pytest.approx(30.0, rel=1e-9)
        assert res["error"] is None and res["computed_at"]
    assert [r["software_version"] for r in st.results(run_id=old)] == ["0.0.1", __version__]
    assert st.results(run_id=old)[0]["metrics"] == {"lost_motion_arcmin": 9}  # kept
    for camp in st.list_campaigns():
        if camp.campaign_id == gone.campaign_id:
            assert st.results(campaign_id=camp.campaign_id) == []  # retried next time
            continue
        (res,) = st.results(campaign_id=camp.campaign_id)
        assert res["diagnosis"]["format"] == "rig-diagnosis/1" and res["diagnosis"]["verdict"]

    again = rig("reanalyse", "--store", make_store.target(root), "--json", cwd=tmp_path,
                env=make_store.env(root))
    doc = json.loads(again.stdout)
    assert doc["written"] == 0 and doc["skipped"] == 7 and len(doc["unreadable"]) == 2


def test_an_interrupted_reanalysis_resumes_where_it_stopped(tmp_path):
    from rig.store import Store

    st = Store(tmp_path)
    line(st)
    seen = []

    def stop_after_three(done: int, total: int) -> None:
        seen.append((done, total))
        if done == 3:
            raise KeyboardInterrupt  # what Ctrl-C does in the client loop

    with pytest.raises(KeyboardInterrupt):
        reanalyse(st, workers=1, on_progress=stop_after_three, batch=1)
    assert seen[0] == (0, 9)
    assert len(st.results()) == 3
    summary = reanalyse(st, workers=1)
    assert (summary.skipped, summary.written) == (3, 6)
    keys = [(r["run_id"], r["campaign_id"]) for r in st.results()]
    assert len(keys) == len(set(keys)) == 9
    assert reanalyse(st, since="2999-01-01").n_runs == 0


def test_a_dask_scheduler_address_and_option_errors(tmp_path):
    from dask.distributed import LocalCluster

    from rig.store import Store

    st = Store(tmp_path / "store")
    write_campaign(st, "D-1", play_arcmin=[4.0], positions_deg=(0.0,), unit_data=UNIT)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp://",
                      host="127.0.0.1", scheduler_port=0, dashboard_address=None) as cluster:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        out = rig("reanalyse", "--store", str(tmp_path / "store"), "--dask",
                  cluster.scheduler_address, "--json", cwd=tmp_path, env={})
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["written"] == 2
    out = rig("reanalyse", "--store", str(tmp_path / "store"), "--dask", "tcp://127.0.0.1:1",
              "--workers", "2", cwd=tmp_path, env={})
    assert out.returncode == 2 and "not both" in out.stderr
