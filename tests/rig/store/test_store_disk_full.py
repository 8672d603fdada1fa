"""A full disk during a run (issue 33 item 3), for real: ``rig campaign run`` under a file
size limit (``RLIMIT_FSIZE``: the kernel refuses the write that would pass it with EFBIG, what
a full disk does with ENOSPC) says so in one line, keeps the samples written so far as whole
CSV lines, records the run and the campaign as aborted with that reason, and leaves no
temporary file and no run "running"."""

from __future__ import annotations

import json
import os
import re
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from rig.store import Store
from tests.support.campaigns import campaign_toml

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time

RIG = [sys.executable, "-c", "from rig.cli import main; main()"]
LIMIT_BYTES = 128 * 1024
"""Above the fresh store's index (80 KiB), below one run's samples.csv of three cycles."""
LONG = campaign_toml("full", "positions_deg = [90.0]").replace(
    "pre_cycles = 0", "pre_cycles = 0\ncycles = 3")


def _size_limit() -> None:
    resource.setrlimit(resource.RLIMIT_FSIZE, (LIMIT_BYTES, LIMIT_BYTES))


def test_a_full_disk_aborts_the_run_in_one_line_with_whole_samples(tmp_path: Path) -> None:
    store = tmp_path / "store"
    camp = tmp_path / "full.toml"
    camp.write_text(LONG)
    res = subprocess.run([*RIG, "campaign", "run", str(camp), "--simulated", "--store",
                          str(store)], capture_output=True, text=True, cwd=tmp_path,
                         timeout=180, preexec_fn=_size_limit,
                         env={**os.environ, "RIG_LOG_DIR": str(tmp_path)})
    out = res.stdout + res.stderr
    assert res.returncode == 2, out[-3000:]
    assert "internal error" not in out and "a bug" not in out and "Traceback" not in out, out
    said = re.search(r"the store's disk is full \([^)]*\): (\d+) samples kept, run aborted",
                     out)
    assert said is not None, out[-3000:]
    kept = int(said.group(1))
    assert kept > 100

    (run_dir,) = [p.parent for p in store.rglob("run.json")]
    meta = json.loads((run_dir / "run.json").read_text())
    assert meta["status"] == "aborted" and meta["reason"] == said.group(0)
    assert meta["n_samples"] == kept and meta["outcome"] == "incomplete"
    raw = (run_dir / "samples.csv").read_bytes()  # whole lines only, as many as said
    assert raw.endswith(b"\n")
    lines = raw.decode().splitlines()
    assert len(lines) == kept + 1
    assert {line.count(",") for line in lines} == {lines[0].count(",")}
    (camp_json,) = store.rglob("campaign.json")
    cmeta = json.loads(camp_json.read_text())
    assert cmeta["status"] == "aborted" and cmeta["summary"]["reason"] == said.group(0)
    leftovers = [p.name for p in store.rglob("*") if p.name.endswith((".tmp", ".lock"))]
    assert leftovers == []
    index = Store(store, create=False, recover=False)  # the index itself, not a recovery
    (row,) = index.list_runs()
    assert (row.status, row.reason, row.n_samples) == ("aborted", said.group(0), kept)
