"""Issue 33 item 18: the CLI at 80 columns, piped as a script or a pager reads it (COLUMNS set,
no terminal): ``rig runs`` shows every column it prints readably and names those it leaves
out (``--wide`` shows them), ``rig spc`` and ``rig diagnose`` keep every name whole (never
"lostmotio…"), the output honours COLUMNS, and ``rig --help`` cuts no description mid-phrase."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from rig.examples import RUNS_DIR
from rig.store import Store
from rig.store.synthetic_runs import write_campaign

RIG = [sys.executable, "-c", "from rig.cli import main; main()"]
RUN_HEADERS = ("run", "status", "outcome", "lost motion arcmin", "reason", "unit", "operator",
               "plan", "started (UTC)", "samples", "campaign")


def _rig(*args: str, columns: int | None, cwd: Path | None = None
         ) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items()
           if k not in ("RIG_STORE", "RIG_SAMPLES_DIR", "COLUMNS", "LINES")}
    if columns is not None:
        env["COLUMNS"] = str(columns)
    res = subprocess.run([*RIG, *args], capture_output=True, text=True, timeout=300, env=env,
                         cwd=cwd)
    assert res.returncode == 0, res.stderr
    return res


def _fits(text: str, columns: int) -> None:
    assert "…" not in text, text
    assert max(len(line) for line in text.splitlines()) <= columns, text


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> dict:
    root = tmp_path_factory.mktemp("narrow") / "store"
    st = Store(root)
    write_campaign(st, "SN-2026-LINE-B-0001", n_quarter=100,
                   limits={"lost_motion_arcmin_max": 3.0})
    rec = st.begin_run({"unit": {"serial": "RV-2"}, "operator": "Bartholomew Fitzgerald",
                        "plan": {"name": "gbt", "version": "2"}},
                       ["t_s", "torque_Nm", "output_angle_deg"])
    rec.finish("aborted", reason="E-stop pressed")
    runs = [r.run_id for r in st.list_runs()]
    st.close()
    return {"root": root, "runs": runs}


def test_rig_runs_at_80_columns_shows_its_columns_whole(store: dict) -> None:
    text = _rig("runs", "--store", str(store["root"]), columns=80).stdout
    _fits(text, 80)
    lines = text.splitlines()
    rule = next(i for i, line in enumerate(lines) if set(line.strip()) <= set("─━"))
    head = " ".join(lines[1:rule])
    for header in ("run", "status", "outcome", "lost motion arcmin", "started (UTC)"):
        assert all(word in head for word in header.split()), (header, head)
    for run_id in store["runs"]:  # its row: every cell there, whole
        row = next(line for line in lines[rule:] if line.startswith(run_id))
        cells = row[len(run_id):].split()
        aborted = run_id.startswith("RV-2")
        assert cells[:2] == (["aborted", "INCOMPLETE"] if aborted else ["completed", "OK"])
        assert aborted or cells[2] == "2.020", row
        assert re.search(r"\b20\d\d-\d\d-\d\d\b", row), row
    assert any(line.startswith(f"{store['runs'][0]}: E-stop pressed") for line in lines)
    left = " ".join(" ".join(lines[-2:]).split())
    assert "left out at 80 columns" in left and "rig runs --wide" in left, text
    for header in ("reason", "unit", "operator", "plan", "samples", "campaign"):
        assert header in left, (header, left)


def _boxed_rows(text: str) -> tuple[list[str], dict[str, list[str]]]:
    lines = text.splitlines()
    heads = [c.strip() for c in next(x for x in lines if x.startswith("┃")).split("┃")[1:-1]]
    rows = {}
    for line in lines:
        cells = [c.strip() for c in line.split("│")[1:-1]]
        if cells and cells[0]:
            rows[cells[0]] = cells
    return heads, rows


@pytest.mark.parametrize("args", [(), ("--wide",)])
def test_rig_runs_wide_shows_every_column_whole(store: dict, args: tuple[str, ...]) -> None:
    """At 200 columns every column with content fits; --wide shows all, even at 80."""
    text = _rig("runs", "--store", str(store["root"]), *args,
                columns=80 if args else 200).stdout
    assert "…" not in text
    heads, rows = _boxed_rows(text)
    if args:
        assert tuple(heads) == RUN_HEADERS, heads
        assert "left out" not in text
    else:  # those that fit whole, in their order; the others named
        assert heads[:3] == ["run", "status", "outcome"], heads
        assert set(heads) >= {"lost motion arcmin", "reason", "unit", "started (UTC)"}, heads
        left = [h for h in RUN_HEADERS if h not in heads]
        assert f"left out at 200 columns: {', '.join(left)} (rig runs --wide shows every " \
            "column)" in " ".join(text.split()), text
    for run_id in store["runs"]:
        cells = dict(zip(heads, rows[run_id], strict=True))
        empty = {"lost motion arcmin", "campaign", "plan", "samples"} \
            if run_id.startswith("RV-2") else {"reason", "plan"}
        assert all(cells[h] for h in heads if h not in empty), cells


def _spc_store(root: Path) -> None:
    st = Store(root)
    for k, play in enumerate([2.0, 2.1, 2.3]):
        write_campaign(st, f"P-{k}", play_arcmin=play, design="SYN-1", n_quarter=100,
                       positions_deg=(0.0,), limits={"lost_motion_arcmin_max": 3.0})
    st.close()


@pytest.mark.parametrize("columns", [80, 200])
def test_rig_spc_keeps_every_metric_name_whole(tmp_path: Path, columns: int) -> None:
    _spc_store(tmp_path / "store")
    text = _rig("spc", "--store", str(tmp_path / "store"), columns=columns).stdout
    _fits(text, columns)
    for header in ("metric", "n", "mean", "LCL", "UCL", "MR̄", "Cpk", "signals"):
        assert re.search(rf"(?<!\w){re.escape(header)}(?!\w)", text), (header, text)
    for name in ("lost_motion_arcmin", "backlash_arcmin", "stiffness_Nm_per_arcmin"):
        row = next(line for line in text.replace("│", " ").splitlines()
                   if re.search(rf"\b{name}\b", line))
        assert re.search(rf"\b{name}\s+3\s+\d", row), row  # name, n, the mean
    assert re.search(r"te_pp_arcsec: no chart: .*a chart needs 2", " ".join(text.split()))


def test_rig_diagnose_keeps_every_effect_name_whole(tmp_path: Path) -> None:
    out = tmp_path / "r.json"
    text = _rig("diagnose", str(RUNS_DIR / "campaign-pair1-positions"), "--json", str(out),
                columns=80).stdout
    _fits(text, 80)
    report = json.loads(out.read_text())
    assert len(report["ranking"]) >= 3
    for r in report["ranking"]:
        assert re.search(rf"^\W*{r['effect']}\s", text, re.M), (r["effect"], text)
    for word in ("effect", "shrink", "RMS after,", "arcsec", "false", "alarm", "ΔBIC",
                 "cross-validation"):
        assert word in text, word


def test_rig_help_at_80_columns_cuts_no_description() -> None:
    import typer.main

    from rig.cli import app

    group = typer.main.get_command(app)
    for path, command in [((), group), (("campaign",), group.commands["campaign"])]:
        text = _rig(*path, "--help", columns=80).stdout
        _fits(text, 80)
        listed = text[text.index("Commands:"):].splitlines()[1:]
        assert "..." not in "\n".join(listed), text
        assert len(listed) == len(command.commands)
        for line in listed:
            name, description = line.split(None, 1)
            sub = command.commands[name]
            assert description == (sub.short_help or sub.help), line  # whole, on one line
            assert description.count("(") == description.count(")"), line


def test_piped_output_takes_its_width_from_columns(monkeypatch: pytest.MonkeyPatch) -> None:
    """Not a terminal (pytest captures stdout): COLUMNS, else 120 columns."""
    from rig.commands.output import DEFAULT_WIDTH, make_console

    monkeypatch.setenv("COLUMNS", "80")
    assert make_console().width == 80 and make_console(stderr=True).width == 80
    monkeypatch.delenv("COLUMNS")
    assert DEFAULT_WIDTH == 120 and make_console().width == 120
