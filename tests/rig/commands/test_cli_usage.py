"""The CLI as an operator meets it (issue 21 items 21 and 22): every error one line, help and
tables whole at 80 columns, ``--json -`` on stdout, no folder made for a mistyped path."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest
from typer.testing import CliRunner

from rig.cli import app
from rig.examples import RUNS_DIR
from tests.support.paths import REPO as ROOT

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

UNIT = ROOT / "rig/examples/units/seed000-pair1.json"
CAMPAIGN = RUNS_DIR / "campaign-pair1-positions"
# The console script (it imports only the command named); else the same entry point.
SCRIPT = Path(sysconfig.get_path("scripts")) / "rig"
RIG = [sys.executable, str(SCRIPT)] if SCRIPT.is_file() else [
    sys.executable, "-c", "from rig.cli import main; main()"]


def rig(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*RIG, *args], capture_output=True, text=True, timeout=180,
                          cwd=cwd, env={**__import__("os").environ, "COLUMNS": "80"})


# -- item 21: one line per error -------------------------------------------------------------
@pytest.mark.parametrize(("args", "words"), [
    (["runs", "--json"], ["--json", "requires an argument"]),
    (["runs", "--status", "done"], ["--status", "'done'", "running, completed, aborted"]),
    (["runs", "--limit", "0"], ["--limit", "greater than or equal to 1"]),
    (["analyse", str(CAMPAIGN), "--percent", "abc"], ["--percent", "valid number"]),
    (["serve", "--simulated", "--port", "99999"], ["--port", "65535"]),
    (["anlyse"], ["No such command 'anlyse'", "Did you mean 'analyse'"]),
])
def test_usage_errors_are_one_line_exit_2(tmp_path: Path, args: list[str], words: list[str]):
    res = rig(*args, cwd=tmp_path)
    assert res.returncode == 2, res.stderr
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith("rig: error: "), lines[0]
    for word in words:
        assert word in lines[0], lines[0]
    assert not any(ch in lines[0] for ch in "╭╰│"), lines[0]  # no box
    assert res.stdout == ""


def _commands() -> list[list[str]]:
    import typer.main

    group = typer.main.get_command(app)
    names = []
    for name, command in group.commands.items():
        subs = getattr(command, "commands", None)
        names += [[name, sub] for sub in subs] if subs else [[name]]
    return sorted(names)


@pytest.mark.timeout(600)
def test_help_at_80_columns_keeps_every_option_name_whole():
    import typer.main

    group = typer.main.get_command(app)
    commands = _commands()
    assert ["sim"] in commands and ["campaign", "run"] in commands
    for path in commands:
        res = CliRunner().invoke(app, [*path, "--help"], env={"COLUMNS": "80"})
        assert res.exit_code == 0, (path, res.output)
        assert "…" not in res.output, (path, res.output)
        command = group
        for name in path:
            command = command.commands[name]
        for param in command.params:
            for opt in [*param.opts, *param.secondary_opts]:
                if opt.startswith("-"):
                    assert opt in res.output, (path, opt, res.output)
        assert max(len(line) for line in res.output.splitlines()) <= 80, path


@pytest.mark.timeout(600)
def test_analyse_table_keeps_its_headers_and_shows_the_loop_area_in_mJ(tmp_path: Path):
    out = tmp_path / "c.json"
    res = CliRunner().invoke(app, ["analyse", str(CAMPAIGN), "--json", str(out)],
                             env={"COLUMNS": "80"})
    assert res.exit_code == 0, res.output
    text = res.stdout
    assert "…" not in text
    assert max(len(line) for line in text.splitlines()) <= 80
    for header in ("run", "metric", "measured ± u", "model", "unit"):
        assert header in text
    doc = json.loads(out.read_text())
    for run in doc["runs"]:
        rows = text[text.index(run["run_id"]):].splitlines()[:5]
        area = next(row for row in rows if "loop area" in row)
        cells = [c.strip() for c in area.split("│") if c.strip()]
        assert cells[-1] == "mJ", cells
        value, u = (float(x) for x in cells[-2].split(" ± "))
        mJ, u_mJ = run["loop_area_J"] * 1e3, run["uncertainty"]["loop_area_J"] * 1e3
        # three significant digits of the figure, and an uncertainty that is not "0.0000"
        assert value == pytest.approx(mJ, rel=5e-3)
        assert u == pytest.approx(u_mJ, rel=0.05) and u > 0
        assert len(cells[-2].split(" ± ")[0].lstrip("-0.")) >= 3
        for label in ("lost motion", "backlash", "stiffness", "torque offset"):
            assert any(label in row for row in rows), (label, rows)
    assert "0.0000 J" not in text and not math.isnan(value)


# -- item 22: --json - is stdout; no folder made for a mistyped path ----------------------------
JSON_DASH_COMMANDS = [
    ["analyse", str(RUNS_DIR / "pair1-pos000")],
    ["analyse", str(CAMPAIGN)],
    ["model", str(UNIT)],
    ["batch", str(UNIT), "--samples", "40"],
    ["rotor", "--elements", "4"],
    ["montecarlo", "--samples", "200", "--quiet"],
    ["diagnose", str(CAMPAIGN)],
]


@pytest.mark.timeout(600)
@pytest.mark.parametrize("args", JSON_DASH_COMMANDS,
                         ids=lambda a: "-".join(x for x in a if not x.startswith("/"))[:40])
def test_json_dash_is_stdout(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, args: list[str]):
    monkeypatch.chdir(tmp_path)
    res = CliRunner().invoke(app, [*args, "--json", "-"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)  # the JSON alone on stdout: tables and notes on stderr
    assert isinstance(doc, dict) and doc
    assert not (tmp_path / "-").exists()
    assert list(tmp_path.iterdir()) == []


@pytest.fixture(scope="module")
def empty_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from rig.store import Store

    root = tmp_path_factory.mktemp("store")
    Store(root).close()
    return root


STORE_JSON_COMMANDS = ["runs", "spc", "reanalyse"]


@pytest.mark.timeout(600)
@pytest.mark.parametrize("command", STORE_JSON_COMMANDS)
def test_json_dash_is_stdout_of_the_store_commands(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, empty_store: Path, command: str):
    monkeypatch.chdir(tmp_path)
    res = CliRunner().invoke(app, [command, "--store", str(empty_store), "--json", "-"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)  # the JSON alone on stdout
    assert isinstance(doc, dict) and doc
    assert list(tmp_path.iterdir()) == []


JSON_DASH_ELSEWHERE = {
    "te-calibrate": "two TE runs: tests/test_te_app.py",
    "validate-diagnosis": "a minute of diagnoses: tests/test_validate_like.py",
    "measure": "a rig", "campaign run": "a rig", "devices": "a rig",
}
"""Commands with ``--json`` whose ``--json -`` is not run here, and why."""


def test_every_command_with_json_is_checked_for_json_dash():
    import typer.main

    group = typer.main.get_command(app)
    with_json = set()
    for path in _commands():
        command = group
        for name in path:
            command = command.commands[name]
        if any("--json" in param.opts for param in command.params):
            with_json.add(" ".join(path))
    checked = {args[0] for args in JSON_DASH_COMMANDS} | set(STORE_JSON_COMMANDS)
    assert with_json == checked | set(JSON_DASH_ELSEWHERE), with_json ^ (
        checked | set(JSON_DASH_ELSEWHERE))


def test_certificate_refuses_a_missing_folder_and_makes_nothing(tmp_path: Path):
    run = RUNS_DIR / "pair1-pos000"
    for option in ("--pdf", "--html"):
        res = rig("certificate", str(run), option, "missing-dir/x.out", cwd=tmp_path)
        assert res.returncode == 2, res.stderr
        lines = [line for line in res.stderr.splitlines() if line.strip()]
        assert len(lines) == 1 and lines[0].startswith("rig: error: "), res.stderr
        assert "missing-dir" in lines[0] and "no folder" in lines[0], lines[0]
        assert not (tmp_path / "missing-dir").exists()
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("start", [["-c", "import sys, rig.cli; print(sorted(m for m in "
                                    "sys.modules if m.startswith('rig.commands.')))"],
                                   ["-m", "rig"]])
def test_a_command_started_by_the_rig_itself_imports_only_that_command(start) -> None:
    """``rig sim`` as the rig starts its simulated devices (``python -c "... main()" sim``) and
    ``python -m rig``: only the named command's module is imported (the others pull in scipy
    and matplotlib: 1.8 s and 135 MB more for every simulated rig started)."""
    if start[0] == "-m":
        code = ("import runpy, sys; sys.argv = ['rig/__main__.py', 'version']; "
                "import rig.cli; print(sorted(m for m in sys.modules "
                "if m.startswith('rig.commands.')))")
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              timeout=60)
        assert proc.returncode == 0, proc.stderr
        assert proc.stdout.strip() == "['rig.commands.version']"
        return
    proc = subprocess.run([sys.executable, *start, "version"], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "['rig.commands.version']"
    # imported as a module with no command named (tests, scripts): every command is there
    listed = CliRunner().invoke(app, ["--help"]).output
    assert all(name in listed for name in ("sim", "measure", "diagnose", "version"))
