"""A store on a read-only file system, or one this user may not write (issue 33 item 4): the
commands that read (``rig runs``, ``rig spc``, ``rig certificate``) work, and the ones that
would write (``rig measure``, ``rig campaign run``, ``rig reanalyse``)
say in one line that the store is read-only, before any rig starts, and change nothing."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from rig.store import Store
from rig.store.synthetic_runs import write_campaign
from tests.support.campaigns import TINY
from tests.support.readonly import drop_dac_capabilities, set_writable

RIG = [sys.executable, "-c", "from rig.cli import main; main()"]


@pytest.fixture
def read_only_store(tmp_path: Path) -> Iterator[tuple[Path, str]]:
    """A store of one completed run, made read-only; the store and the run id."""
    root = tmp_path / "store"
    st = Store(root)
    write_campaign(st, "RO-1", positions_deg=(0.0,), n_quarter=40,
                   limits={"lost_motion_arcmin_max": 9.0})
    (run,) = st.list_runs()
    st.close()
    set_writable(root, False)
    try:
        yield root, run.run_id
    finally:
        set_writable(root, True)


def _rig(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([*RIG, *args], capture_output=True, text=True, cwd=cwd, timeout=120,
                          preexec_fn=drop_dac_capabilities,
                          env={**os.environ, "RIG_LOG_DIR": str(cwd)})


def _snapshot(root: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns)
            for p in sorted(root.rglob("*"))}


def test_reading_commands_work_and_writing_ones_say_read_only(
        read_only_store: tuple[Path, str], tmp_path: Path) -> None:
    root, run_id = read_only_store
    before = _snapshot(root)
    listed = _rig("runs", "--store", str(root), "--json", "-", cwd=tmp_path)
    assert listed.returncode == 0, listed.stderr
    (row,) = json.loads(listed.stdout)["runs"]
    assert row["run_id"] == run_id and row["status"] == "completed"
    spc = _rig("spc", "--store", str(root), "--json", "-", cwd=tmp_path)
    assert spc.returncode == 0, spc.stderr
    assert json.loads(spc.stdout)["designs"]
    cert = _rig("certificate", run_id, "--store", str(root), "--html",
                str(tmp_path / "c.html"), cwd=tmp_path)
    assert cert.returncode == 0, cert.stderr
    assert run_id in (tmp_path / "c.html").read_text()

    camp = tmp_path / "tiny.toml"
    camp.write_text(TINY.replace("LIMIT", "9.0"))
    for args in (["measure"], ["campaign", "run", str(camp), "--simulated"],
                 ["reanalyse"]):
        res = _rig(*args, "--store", str(root), cwd=tmp_path)
        lines = res.stderr.strip().splitlines()
        assert res.returncode == 2, res.stdout + res.stderr
        assert lines == [f"rig: error: the store {root} is read-only (no permission to write "
                         f"there): {lines[0].split('): ', 1)[-1]}"], res.stderr
        assert "cannot be stored there" in lines[0] and "internal error" not in res.stderr
    assert _snapshot(root) == before
