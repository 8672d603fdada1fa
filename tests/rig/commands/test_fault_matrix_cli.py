"""Outside fault matrix rows on the command line (issue 12): SIGTERM stops a campaign like
Ctrl-C (row 11), and an unexpected error exits 2 with one line and the traceback in a log
file, never 1, which scripts read as "a limit failed" (row 14). Each case records its row
for docs/reliability.md (``python -m bench.fault_matrix``)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from tests.support.campaigns import TINY
from tests.support.paths import REPO as ROOT

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

RIG = [sys.executable, "-c", "from rig.cli import main; main()"]


def test_sigterm_stops_a_campaign_like_ctrl_c(tmp_path: Path, record_property: Any):
    camp = tmp_path / "long.toml"
    camp.write_text(TINY.replace("LIMIT", "9.0").replace("positions_deg = [90.0]",
                                                         "positions_deg = [0.0, 90.0, 180.0]"))
    store = tmp_path / "store"
    proc = subprocess.Popen([*RIG, "campaign", "run", str(camp), "--simulated", "--store",
                             str(store)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=tmp_path)
    try:
        deadline = time.monotonic() + 120
        samples: list[Path] = []
        while time.monotonic() < deadline and not samples:
            samples = [p for p in store.glob("campaigns/*/*/samples.csv")
                       if p.stat().st_size > 20_000]
            time.sleep(0.1)
        assert samples, "no run started"
        t_signal = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
        stopped_s = time.monotonic() - t_signal
    finally:
        if proc.poll() is None:
            proc.kill()
    (campaign_json,) = store.glob("campaigns/*/campaign.json")
    cdoc = json.loads(campaign_json.read_text())
    runs = [json.loads(p.read_text()) for p in campaign_json.parent.glob("*/run.json")]
    aborted = [r for r in runs if r["status"] == "aborted"]
    record_property("fault", "SIGTERM to rig campaign run")
    record_property("phase", "during a run")
    record_property("outcome", f"exit {proc.returncode}; campaign {cdoc.get('status')}")
    record_property("safe_s", f"{stopped_s:.3f} (process gone)")
    record_property("samples_kept", str(sum(r.get("n_samples") or 0 for r in aborted)))
    record_property("message", aborted[0]["reason"] if aborted else "")
    assert proc.returncode == 2, (out[-1000:], err[-1000:])
    assert "interrupted: the rig is in its safe state" in out + err
    assert cdoc["status"] == "aborted" and cdoc["outcome"] == "incomplete"
    assert len(aborted) == 1 and aborted[0]["outcome"] == "incomplete"
    assert aborted[0]["n_samples"] > 100  # the samples measured so far are kept
    assert "SIGTERM" in aborted[0]["reason"] or "Interrupt" in aborted[0]["reason"]


def test_an_unexpected_error_exits_2_with_one_line_and_a_log(tmp_path: Path,
                                                             record_property: Any):
    run = tmp_path / "run"
    shutil.copytree(ROOT / "rig/examples/runs/pair1-pos000", run)
    meta = json.loads((run / "run.json").read_text())
    meta["test"]["rated_torque_Nm"] = {}  # a type no reader expects
    (run / "run.json").write_text(json.dumps(meta))
    logs = tmp_path / "logs"
    res = subprocess.run([*RIG, "analyse", str(run)], capture_output=True, text=True,
                         cwd=tmp_path, timeout=120, env={**os.environ, "RIG_LOG_DIR": str(logs)})
    record_property("fault", "unexpected error in a command (run.json rated_torque_Nm = {})")
    record_property("phase", "rig analyse")
    record_property("outcome", f"exit {res.returncode}")
    record_property("safe_s", "")
    record_property("samples_kept", "")
    record_property("message", res.stderr.strip())
    assert res.returncode == 2, res.stderr
    assert "Traceback" not in res.stderr
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("rig: "), res.stderr
    if "internal error" in lines[0]:  # a bug caught at the top: its traceback is kept
        (log,) = logs.glob("rig-crash-*.log")
        assert "Traceback" in log.read_text() and str(log) in lines[0]


def test_a_killed_simulator_gives_one_line_naming_the_device(tmp_path: Path,
                                                             record_property: Any):
    """Row 15: ``rig sim`` killed (-9) mid-run. The measurement stops with one line naming
    the device; python-can's and pymodbus's tracebacks go to the log file, not the terminal."""
    sim = subprocess.Popen([*RIG, "sim", "--seed", "3"], stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    logs = tmp_path / "logs"
    try:
        addresses = json.loads(sim.stdout.readline())
        store = tmp_path / "store"
        proc = subprocess.Popen(
            [*RIG, "measure", "--rig", addresses["rig_config"], "--store", str(store),
             "--rated-torque", "10", "--steps", "4"], stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True, cwd=tmp_path,
            env={**os.environ, "RIG_LOG_DIR": str(logs)})
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not list(store.glob("runs/*/samples.csv")):
            time.sleep(0.1)
        time.sleep(0.5)
        t_kill = time.monotonic()
        sim.kill()
        out, err = proc.communicate(timeout=60)
        stopped_s = time.monotonic() - t_kill
    finally:
        for p in (sim,):
            if p.poll() is None:
                p.kill()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    record_property("fault", "rig sim killed (-9)")
    record_property("phase", "during a run")
    record_property("outcome", f"exit {proc.returncode}")
    record_property("safe_s", f"{stopped_s:.3f} (devices gone; the drive's watchdog)")
    record_property("samples_kept", "")
    record_property("message", lines[-1] if lines else "")
    assert proc.returncode == 2, (out[-800:], err[-2000:])
    assert "Traceback" not in err, err[-3000:]
    logged = [ln[:30] for ln in lines if ln.startswith("rig: ")]
    assert len(logged) == len(set(logged)) <= 4, err  # each kind of warning once
    assert not any(ln.startswith(("can.", "pymodbus", "canopen")) for ln in lines), err
    assert any(word in err for word in ("encoder", "transducer", "drive", "sensor")), err
    assert list(logs.glob("rig-*.log")), "the library noise goes to a log file"
