"""Issue 33 item 14: ``rig analyse``, ``rig runs``, and ``rig certificate`` on a
run whose twist runs against the torque (tests/support/reversed_twist.py): never a figure
below zero ("-5.192 ± 0.004"), the words "below zero: no measurement" with the likely cause
(the output encoder's counting direction), and never the verdict OK."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest

from tests.support.reversed_twist import store_reversed_twist_run, write_reversed_twist_run

RIG = [sys.executable, "-c", "from rig.cli import main; main()"]
CAUSE = "the twist runs against the torque: check the output encoder's counting direction"


def _rig(*args: str, columns: int = 200) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("RIG_STORE", "RIG_SAMPLES_DIR")}
    env["COLUMNS"] = str(columns)
    return subprocess.run([*RIG, *args], capture_output=True, text=True, timeout=120, env=env)


def _flat(text: str) -> str:
    """The text with its line breaks and table rules as single spaces."""
    return " ".join(re.sub(r"[│┃|]", " ", text).split())


@pytest.fixture(scope="module")
def flipped(tmp_path_factory: pytest.TempPathFactory) -> dict:
    tmp = tmp_path_factory.mktemp("flipped")
    folder = write_reversed_twist_run(tmp / "flipped-run")
    run_id = store_reversed_twist_run(tmp / "store")
    return {"folder": folder, "store": tmp / "store", "run_id": run_id, "tmp": tmp}


def test_rig_analyse_says_below_zero_with_the_cause(flipped: dict) -> None:
    res = _rig("analyse", str(flipped["folder"]), columns=80)
    assert res.returncode == 0, res.stderr
    text = _flat(res.stdout)
    assert "-5.19" not in text and "-27." not in text and "-0.4" not in text, res.stdout
    assert text.count("below zero: no measurement") >= 4, res.stdout  # each cell, the note
    assert f"lost motion, backlash, stiffness, loop area below zero: no measurement ({CAUSE})" \
        in text, res.stdout


@pytest.mark.parametrize("columns", [80, 200])
def test_rig_runs_says_below_zero_with_the_cause_and_no_ok(flipped: dict, columns: int) -> None:
    res = _rig("runs", "--store", str(flipped["store"]), columns=columns)
    assert res.returncode == 0, res.stderr
    text = _flat(res.stdout)
    assert "-5.19" not in text, res.stdout
    assert "below zero: no measurement" in text and CAUSE in text, res.stdout
    assert "INCOMPLETE" in text and not re.search(r"(?<!NOT )\bOK\b", text), res.stdout


def test_the_certificate_names_the_cause(flipped: dict) -> None:
    html = flipped["tmp"] / "certificate.html"
    res = _rig("certificate", flipped["run_id"], "--store", str(flipped["store"]),
               "--html", str(html))
    assert res.returncode == 0, res.stderr
    text = _flat(re.sub(r"<[^>]+>", " ", html.read_text(encoding="utf-8")))
    assert "below zero: no measurement" in text and "INCOMPLETE" in text
    assert CAUSE.replace("'", "&#39;") in text or CAUSE in text, text[-3000:]
