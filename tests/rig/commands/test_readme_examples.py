"""Every command the README runs, run as written (issue 21 item 23), and what the README says
of it checked: its exit code and the figure or file it promises.

The examples are read from README.md itself (``$ rig ...`` lines, ``rig ...`` code spans that
name a shipped example, the set-up block's ``rig serve --simulated``): an example added to
the README without a check here fails :func:`test_every_readme_example_is_checked`. The
campaigns run on the simulated rig in real time (about a minute each): on a loaded machine a
run may abort on a late device sample; re-run once before believing a failure.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import sysconfig
from pathlib import Path
from typing import Any

import pytest

from tests.support.paths import REPO as ROOT

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

README = (ROOT / "README.md").read_text(encoding="utf-8")
SCRIPT = Path(sysconfig.get_path("scripts")) / "rig"
RIG = [sys.executable, str(SCRIPT)] if SCRIPT.is_file() else [
    sys.executable, "-c", "from rig.cli import main; main()"]

PAIR1 = "rig campaign run examples/campaigns/seed000-pair1.toml --simulated --json pair1.json"
PAIR3 = "rig campaign run examples/campaigns/seed000-pair3.toml --simulated"  # its header's
ANALYSE_RUN = "rig analyse rig/examples/runs/pair1-pos000 --plot loop.png"
DIAGNOSE = "rig diagnose rig-store/campaigns/<campaign id> --json gap.json --html gap.html"
MODEL = "rig model rig/examples/units/seed000-pair1.json --json pair1-model.json"
ANALYSE_CAMPAIGN = ("rig analyse rig/examples/runs/campaign-pair1-positions --json campaign.json"
                    " --plot loops.png")
SERVE = "rig serve --simulated"
CHECKED = {PAIR1, ANALYSE_RUN, DIAGNOSE, MODEL, ANALYSE_CAMPAIGN, SERVE}
PAPER_PAIR3_ARCMIN = 2 + 3 / 60  # seed 000 Table 3, pair 3: 2'3"


def readme_examples() -> set[str]:
    """The ``rig`` commands the README shows being run (not the command table's synopses)."""
    found = {line.removeprefix("$ ").strip() for line in README.splitlines()
             if line.startswith("$ rig ")}
    found |= {span for span in re.findall(r"`(rig [^`]+)`", README)
              if "examples/" in span and "[" not in span}
    found |= {part.strip() for line in README.splitlines() if "&& rig " in line
              for part in line.split("&&")[1:]}
    return found


def test_every_readme_example_is_checked() -> None:
    assert readme_examples() == CHECKED
    # what the README says of the compensated pair: it exits 1 too, and why
    assert "seed000-pair3.toml" in README and "exits 1 as well" in README


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder that looks like the repository to the README's relative paths (the examples
    linked in), so that what the commands write stays out of the repository."""
    work = tmp_path_factory.mktemp("readme")
    (work / "examples").symlink_to(ROOT / "examples")
    # the package itself, not a bare folder: a folder named rig in the working directory
    # would shadow the installed package for every `python -c` the commands start
    (work / "rig").symlink_to(ROOT / "rig")
    return work


def run(command: str, cwd: Path, timeout_s: float = 900) -> subprocess.CompletedProcess[str]:
    args = command.split()
    assert args[0] == "rig"
    env = {k: v for k, v in os.environ.items() if k not in ("RIG_STORE", "RIG_WEB_TOKEN")}
    return subprocess.run([*RIG, *args[1:]], capture_output=True, text=True, cwd=cwd,
                          timeout=timeout_s, env=env)


def _png(path: Path) -> bool:
    return path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 10_000


@pytest.mark.timeout(1200)
def test_pair1_campaign_fails_its_limit_and_the_diagnosis_runs(workspace: Path) -> None:
    res = run(PAIR1, workspace)
    # "it fails the campaign's 3' limit, exit code 1"
    assert res.returncode == 1, res.stderr[-3000:]
    doc: dict[str, Any] = json.loads((workspace / "pair1.json").read_text())
    assert doc["outcome"] == "not_ok" and doc["status"] == "completed"
    assert any("above the limit 3" in cause for cause in doc["failures"]), doc["failures"]
    campaign = Path(doc["path"])
    assert campaign.parent == (workspace / "rig-store" / "campaigns").resolve()
    res = run(DIAGNOSE.replace("<campaign id>", campaign.name), workspace)
    assert res.returncode == 0, res.stderr[-3000:]
    gap = json.loads((workspace / "gap.json").read_text())
    assert gap["verdict"] and "ranking" in gap
    assert (workspace / "gap.html").read_text(encoding="utf-8").lstrip().startswith("<!")


@pytest.mark.timeout(1200)
def test_pair3_after_compensation_is_2_arcmin_on_average_and_fails_at_180(workspace: Path
                                                                          ) -> None:
    res = run(f"{PAIR3} --json pair3.json", workspace)
    # "it exits 1 as well": the mean is the paper's 2'3", the worst angle (180 deg) above 3'
    assert res.returncode == 1, res.stderr[-3000:]
    doc = json.loads((workspace / "pair3.json").read_text())
    assert doc["status"] == "completed" and doc["outcome"] == "not_ok"
    assert doc["lost_motion_arcmin"]["mean"] == pytest.approx(PAPER_PAIR3_ARCMIN, rel=0.15)
    worst = max(doc["runs"], key=lambda r: r["lost_motion_arcmin"])
    assert worst["input_angle_deg"] == pytest.approx(180.0)
    assert 3.0 < worst["lost_motion_arcmin"] < 4.5  # "about 3.8'"
    assert all("above the limit 3" in cause for cause in doc["failures"]), doc["failures"]


@pytest.mark.timeout(600)
def test_analyse_examples_write_what_they_say(workspace: Path) -> None:
    res = run(ANALYSE_RUN, workspace)
    assert res.returncode == 0, res.stderr
    assert _png(workspace / "loop.png")
    res = run(ANALYSE_CAMPAIGN, workspace)
    assert res.returncode == 0, res.stderr
    doc = json.loads((workspace / "campaign.json").read_text())
    assert len(doc["runs"]) == 4 and _png(workspace / "loops.png")
    res = run(MODEL, workspace)
    assert res.returncode == 0, res.stderr
    model = json.loads((workspace / "pair1-model.json").read_text())
    assert model["design_lost_motion_arcmin"] > 3.0  # the uncompensated pair


@pytest.mark.timeout(400)
def test_serve_simulated_prints_the_address_and_the_operator_token(workspace: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("RIG_STORE", "RIG_WEB_TOKEN")}
    # the README's command, on a free port: the default 8765 may be taken on a shared machine
    proc = subprocess.Popen([*RIG, *SERVE.split()[1:], "--port", "0"], cwd=workspace, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        lines = [proc.stdout.readline() for _ in range(3)]
    finally:
        os.killpg(proc.pid, signal.SIGINT)
        try:
            proc.wait(timeout=120)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)
        err = proc.stderr.read()
        proc.stdout.close()
        proc.stderr.close()
    assert re.match(r"control page: http://127\.0\.0\.1:\d+/$", lines[0].strip()), (lines, err)
    token = (workspace / "rig-store" / "web" / "operator-token").read_text().strip()
    assert lines[1].startswith(f"operator token: {token} (generated; kept in ")
    assert lines[2].strip().endswith(f"#token={token}")
