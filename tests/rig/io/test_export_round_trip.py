"""Issue 33 item 12: ``rig import`` reads back the rig's own parquet, xlsx and mat exports.

The engineer's round trip: ``rig export RUN --format F``, then ``rig import`` of that file
through examples/maps/rig-export.toml (the CLI's commands, in this process), and the
imported run has the original's samples and figures (the example campaign's first run).
Before the fix each import said the file was "not utf-8 text" (and then that it was
binary). The one-line errors go through the console script, as a process.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from rig.cli import app
from rig.results.analyse import analyse_run
from rig.runformat import read_run
from tests.support.paths import REPO

RIG = [sys.executable, "-c", "from rig.cli import main; main()"]
RUN = REPO / "rig/examples/runs/campaign-pair1-positions/pair1-pos000"
MAP = REPO / "examples/maps/rig-export.toml"


def _rig(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run([*RIG, *args], capture_output=True, text=True, cwd=cwd, timeout=180,
                          env=env)


def _cli(*args: str | Path) -> None:
    res = CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)
    assert res.exit_code == 0, res.output


@pytest.mark.parametrize("fmt", ["parquet", "xlsx", "mat"])
def test_an_export_imports_back_with_the_same_figures(tmp_path: Path, fmt: str) -> None:
    (tmp_path / "unit.json").write_text(json.dumps(read_run(RUN).unit))
    exported = tmp_path / f"run.{fmt}"
    _cli("export", RUN, "--format", fmt, "--out", exported)
    _cli("import", exported, "--map", MAP, "--unit", tmp_path / "unit.json", "--out",
         tmp_path / "back")
    back, original = read_run(tmp_path / "back"), read_run(RUN)
    assert back.n_samples == original.n_samples == 2850
    np.testing.assert_allclose(back.torque_Nm, original.torque_Nm, rtol=1e-14)
    np.testing.assert_allclose(back.output_angle_deg, original.output_angle_deg, rtol=1e-14)
    got, want = analyse_run(back).to_dict(), analyse_run(original).to_dict()
    for key in ("lost_motion_arcmin", "backlash_arcmin", "stiffness_Nm_per_arcmin"):
        assert got[key] == pytest.approx(want[key], rel=1e-9), key


def test_a_matlab_v73_file_and_a_broken_export_are_one_line(tmp_path: Path) -> None:
    """A v7.3 .mat (HDF5; rig export writes v5) and a cut parquet file: one line naming the
    file and what to do or what failed, nothing written."""
    (tmp_path / "unit.json").write_text(json.dumps(read_run(RUN).unit))
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Sat Nov 28 2026 HDF5 schema"
    (tmp_path / "v73.mat").write_bytes(header.ljust(512, b" ") + b"\x89HDF\r\n\x1a\n")
    (tmp_path / "cut.parquet").write_bytes(b"PAR1" + b"\0" * 40)
    for name, words in (("v73.mat", "MATLAB v7.3 (HDF5)"), ("cut.parquet", "not a readable "
                                                                           "parquet file")):
        res = _rig("import", name, "--map", str(MAP), "--unit", "unit.json", "--out", "back",
                   cwd=tmp_path)
        lines = res.stderr.strip().splitlines()
        assert res.returncode == 2 and len(lines) == 1, res.stderr
        assert name in lines[0] and words in lines[0], lines[0]
        assert not (tmp_path / "back").exists()
