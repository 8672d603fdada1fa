"""``rig serve`` refuses what it must, with a clear message and exit code 2 (the console
script run as a process); starting it for real is the e2e test's job."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

RIG = [sys.executable, "-c", "from rig.cli import main; main()"]


def rig(*args: str, tmp_path: Path, env: dict[str, str] | None = None
        ) -> subprocess.CompletedProcess:
    clean = {k: v for k, v in os.environ.items() if k != "RIG_WEB_TOKEN"}
    return subprocess.run([*RIG, *args], capture_output=True, text=True, timeout=120,
                          cwd=tmp_path, env={**clean, **(env or {})})


def test_serve_refuses_another_address_without_a_token(tmp_path: Path):
    r = rig("serve", "--simulated", "--host", "0.0.0.0", "--store", "s", tmp_path=tmp_path)
    assert r.returncode == 2
    assert "rig: error: refusing to bind to 0.0.0.0" in r.stderr
    assert "--token" in r.stderr and r.stdout == ""
    assert not (tmp_path / "s" / "web" / "operator-token").exists()


def test_serve_needs_one_rig(tmp_path: Path):
    r = rig("serve", "--store", "s", tmp_path=tmp_path)
    assert r.returncode == 2 and "--simulated" in r.stderr and "--rig FILE" in r.stderr


def test_serve_names_a_port_in_use(tmp_path: Path):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        r = rig("serve", "--simulated", "--port", str(port), "--store", "s",
                tmp_path=tmp_path)
    assert r.returncode == 2
    assert f"cannot listen on 127.0.0.1:{port}" in r.stderr


def test_serve_names_an_unknown_example_unit(tmp_path: Path):
    r = rig("serve", "--simulated", "--unit", "no-such-unit", "--store", "s",
            tmp_path=tmp_path)
    assert r.returncode == 2
    assert "no such example unit" in r.stderr and "seed000-pair1" in r.stderr


def test_serve_names_a_bad_plant_file(tmp_path: Path):
    r = rig("serve", "--simulated", "--plant", "no-such-plant.toml", "--store", "s",
            tmp_path=tmp_path)
    assert r.returncode == 2
    assert "--plant:" in r.stderr and "no-such-plant.toml" in r.stderr
    assert "cannot read plant config" in r.stderr
    r = rig("serve", "--rig", "rig.toml", "--plant", "p.toml", "--store", "s", tmp_path=tmp_path)
    assert r.returncode == 2 and "give it with --simulated" in r.stderr
