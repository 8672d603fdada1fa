"""The `rig` console script: help, one-line errors, and lean start-up per command."""

from __future__ import annotations

import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from tests.support.paths import REPO

# The console script pip installed for this interpreter (not a pyenv shim in front of it).
RIG = str(Path(sysconfig.get_path("scripts")) / "rig")
pytestmark = pytest.mark.skipif(
    not Path(RIG).is_file(), reason="the `rig` console script is not installed (pip install -e .)"
)


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=120)


def test_help_lists_every_command() -> None:
    res = run(RIG, "--help")
    assert res.returncode == 0
    for name in ("analyse", "model", "montecarlo", "runs", "version"):
        assert name in res.stdout


def test_unknown_command_exits_2() -> None:
    res = run(RIG, "no-such-command")
    assert res.returncode == 2
    assert "no-such-command" in res.stderr


def _imported(*args: str) -> set[str]:
    res = run("-X", "importtime", RIG, *args)
    assert res.returncode == 0, res.stderr[-2000:]
    return {line.rsplit("|", 1)[-1].strip() for line in res.stderr.splitlines() if "|" in line}


def test_a_command_imports_only_what_it_needs() -> None:
    """`rig version` must not pay for the scipy/matplotlib that other commands need, nor the
    seed 000 chain (its inverse involute is a bracketed Newton, not scipy.optimize: 1-2 s of
    every simulated rig's start). The control: the seed 003 Monte Carlo does load scipy
    (scipy.special's normal quantile), when it computes, not for its --help."""
    lean = _imported("version")
    assert not any(name.startswith(("scipy", "matplotlib")) for name in lean)
    model = _imported("model", str(REPO / "rig/examples/units/seed000-pair1.json"))
    assert not any(name.startswith("scipy") for name in model)
    assert not any(name.startswith("scipy") for name in _imported("montecarlo", "--help"))
    heavy = _imported("montecarlo", "-n", "200", "-q")
    assert any(name.startswith("scipy") for name in heavy)
