"""A campaign on the simulated rig under load, started from the control page's API.

Used by ``python -m bench load`` (figures) and ``tests/rig/web/test_load.py`` (targets). What runs:

- ``rig serve --simulated`` (the page's server; the rig in its own engine process; the
  simulated devices in ``rig sim``), with ``RIG_SIM_STATS`` set so the simulated loading drive
  writes its watchdog figures (the longest silence of the master while enabled) to a file:
  the keepalive gap is measured where the drive sees it, not where we send it;
- an earlier campaign measured through the page without load (the one to diagnose);
- then the load: ``busy`` processes spinning on the CPU, a diagnosis process
  (``rig diagnose`` of the earlier campaign, over and over), ``sse_clients`` live-stream
  clients reading ``/api/live`` (one process, one thread each), and the earlier campaign's
  diagnosis requested from the page while the measured campaign runs;
- the measured campaign started through ``POST /api/control/start``.

Figures: whether the campaign completed; samples lost: encoder samples that reached the
drivers but not the store (run.json ``result.samples_dropped``: full driver queues, merge
drops; exact counts); periods of the encoder clock without a row (``load_missing_periods``,
from the row times: a SYNC the starved host sent late, or stamping slop of a few periods);
p99 of the acquisition jitter (|interval - period|, ms); the longest keepalive gap the drive
saw (s) against its watchdog (s).
"""

from __future__ import annotations

import contextlib
import json
import os
import shlex
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np

__all__ = ["run_load_scenario", "run_preview_flood", "acquisition_figures"]

TOKEN = "load-test-operator-token"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
RIG = [sys.executable, "-c", "from rig.cli import main; main()"]
ROOT = Path(__file__).resolve().parent.parent

SSE_CLIENTS_SCRIPT = """
import sys, threading, httpx
url, n = sys.argv[1], int(sys.argv[2])
def read():
    while True:
        try:
            with httpx.stream("GET", url + "api/live", timeout=None) as r:
                for _ in r.iter_bytes():
                    pass
        except Exception:
            pass
threads = [threading.Thread(target=read, daemon=True) for _ in range(n)]
for t in threads: t.start()
threading.Event().wait()
"""

BUSY_SCRIPT = "while True:\n    pass\n"

FLOOD_SCRIPT = """
import http.client, json, sys, threading, time
from urllib.parse import urlsplit
url, n, seconds, body_file, out = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), \\
    sys.argv[4], sys.argv[5]
parts = urlsplit(url)
assert parts.hostname == "127.0.0.1", parts.hostname
body = open(body_file, "rb").read()
end = time.monotonic() + seconds
codes = {}
lock = threading.Lock()
def flood():
    conn = None
    while time.monotonic() < end:
        try:
            if conn is None:
                conn = http.client.HTTPConnection(parts.hostname, parts.port, timeout=30)
            conn.request("POST", "/api/plan/preview", body=body,
                         headers={"Content-Type": "application/json"})
            r = conn.getresponse()
            r.read()
            code = r.status
        except Exception as exc:
            code = type(exc).__name__
            conn = None
        with lock:
            codes[code] = codes.get(code, 0) + 1
def report():
    while True:
        time.sleep(1.0)
        with lock:
            text = json.dumps({str(k): v for k, v in codes.items()})
        open(out, "w").write(text)
threads = [threading.Thread(target=flood, daemon=True) for _ in range(n)]
for t in threads: t.start()
threading.Thread(target=report, daemon=True).start()
for t in threads: t.join()
with lock:
    open(out, "w").write(json.dumps({str(k): v for k, v in codes.items()}))
"""
"""``n`` token-less clients (threads with keep-alive connections) posting plan previews as
fast as the page answers, ignoring 429/503 and Retry-After (a hostile flood), for at most
``seconds``; the answers' counts by status go to ``out`` every second."""


class BackgroundLoad:
    """Processes started in their own sessions (a scenario's load); :meth:`stop` kills each
    with its whole process group."""

    def __init__(self) -> None:
        self.procs: list[subprocess.Popen] = []

    def start(self, args: list[str], **popen: Any) -> subprocess.Popen:
        """Start ``args`` in a new session (``popen``: more Popen arguments)."""
        proc = subprocess.Popen(args, start_new_session=True, **popen)
        self.procs.append(proc)
        return proc

    def busy(self, count: int) -> None:
        """Start ``count`` processes that keep a core busy."""
        for _ in range(count):
            self.start([sys.executable, "-c", BUSY_SCRIPT])

    def stop(self) -> None:
        for p in self.procs:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, 9)


def acquisition_figures(t_s: np.ndarray, period_s: float) -> tuple[int, float]:
    """Samples lost and p99 jitter (ms) of one run's row times ``t_s`` (s, host time at
    receipt).

    The output encoder is the master clock: one row per position PDO, one PDO every
    ``period_s`` (run.json ``sensors.encoder_period_s``). Lost: periods of the run's span
    without a row, ``round(span / period) + 1 - rows`` (never negative: a late PDO arrives in
    a burst with the next and is not lost). Jitter: |interval - period| of consecutive rows.
    """
    t = np.asarray(t_s, dtype=float)
    dt = np.diff(t)
    if dt.size == 0:
        return 0, 0.0
    expected = int(round((t[-1] - t[0]) / period_s)) + 1
    lost = max(0, expected - t.size)
    jitter_ms = np.abs(dt - period_s) * 1e3
    return lost, float(np.percentile(jitter_ms, 99))


def _sim_env(realtime_priority: int | None, device_priority: int | None) -> dict[str, str]:
    """The environment for programs that start simulated rigs: the priorities asked, none
    inherited."""
    env = dict(os.environ)
    for name, value in (("RIG_SIM_REALTIME_PRIORITY", realtime_priority),
                        ("RIG_SIM_DEVICE_PRIORITY", device_priority)):
        env.pop(name, None)
        if value is not None:
            env[name] = str(value)
    return env


@contextlib.contextmanager
def _serve(store: Path, stats: Path, log: Path, env: dict[str, str]) -> Iterator[str]:
    env = {**env, "RIG_SIM_STATS": str(stats)}
    env.pop("RIG_WEB_TOKEN", None)
    with open(log, "w", encoding="utf-8") as err:
        proc = subprocess.Popen([*RIG, "serve", "--simulated", "--port", "0", "--store",
                                 str(store), "--token", TOKEN], stdout=subprocess.PIPE,
                                stderr=err, text=True, env=env, cwd=store.parent)
        try:
            url = ""
            assert proc.stdout is not None
            for line in proc.stdout:
                if line.startswith("control page:"):
                    url = line.split(":", 1)[1].strip()
                    break
            if not url:
                raise RuntimeError(f"rig serve did not start: {log.read_text()[-2000:]}")
            yield url
        finally:
            proc.send_signal(2)
            try:
                proc.wait(60)
            except subprocess.TimeoutExpired:
                proc.kill()


def _served(stack: contextlib.ExitStack, workdir: Path | None, env: dict[str, str]
            ) -> tuple[Path, Path, Path, str]:
    """``rig serve`` on a store in ``workdir`` (None: a temporary folder) until ``stack``
    closes: (workdir, store, the simulator's stats file, the page's URL)."""
    if workdir is None:
        workdir = Path(stack.enter_context(tempfile.TemporaryDirectory()))
    store = workdir / "store"
    store.mkdir(parents=True, exist_ok=True)
    stats = workdir / "sim-stats.json"
    url = stack.enter_context(_serve(store, stats, workdir / "serve.log", env))
    return workdir, store, stats, url


def _wait_state(client: httpx.Client, states: tuple[str, ...], timeout_s: float
                ) -> dict[str, Any]:
    end = time.monotonic() + timeout_s
    status: dict[str, Any] = {}
    while time.monotonic() < end:
        with contextlib.suppress(httpx.HTTPError):
            status = client.get("api/status", timeout=10).json()
            if status.get("state") in states:
                return status
        time.sleep(0.3)
    raise TimeoutError(f"the page did not reach {states} in {timeout_s:.0f} s: {status}")


def _campaign_body(name: str, positions: list[float], steps_per_quarter: int,
                   plan: dict[str, Any] | None = None) -> dict[str, Any]:
    unit = json.loads((ROOT / "rig" / "examples" / "units" / "seed000-pair1.json")
                      .read_text(encoding="utf-8"))
    return {"kind": "campaign", "name": name, "operator": "load bench",
            "unit": {**unit, "serial": f"load-{name}"},
            "plan": {"rated_torque_Nm": 10.0, "steps_per_quarter": steps_per_quarter,
                     "pre_cycles": 1, **(plan or {})},
            "axes": {"positions_deg": positions}}


def _measure(client: httpx.Client, body: dict[str, Any], timeout_s: float
             ) -> dict[str, Any]:
    _wait_state(client, ("idle", "completed", "aborted"), 120.0)
    r = client.post("api/devices/input-lock", json={"confirm": True}, headers=AUTH)
    r.raise_for_status()
    r = client.post("api/control/start", json=body, headers=AUTH)
    if r.status_code != 200:
        raise RuntimeError(f"start refused: {r.status_code} {r.text}")
    return _wait_state(client, ("completed", "aborted"), timeout_s)


def _measure_under_load(client: httpx.Client, store: Any, body: dict[str, Any],
                        diagnose_id: str, timeout_s: float) -> dict[str, Any]:
    """One campaign started through the page's API while the load runs, with the diagnosis
    of campaign ``diagnose_id`` requested from the page while it measures; its figures."""
    _wait_state(client, ("idle", "completed", "aborted"), 120.0)
    client.post("api/devices/input-lock", json={"confirm": True}, headers=AUTH)
    r = client.post("api/control/start", json=body, headers=AUTH)
    started = r.status_code == 200
    diagnosis_status = None
    if started:
        time.sleep(1.0)
        d = client.get(f"api/campaigns/{diagnose_id}/diagnosis.json", timeout=300)
        diagnosis_status = d.status_code
    done = (_wait_state(client, ("completed", "aborted"), timeout_s) if started
            else {"state": "refused", "message": r.text})
    result = done.get("last_result") or {}
    campaign_id = result.get("campaign_id")
    lost, missing, jitters, n_rows = 0, 0, [], 0
    period_s = 0.002
    outcome = None
    if campaign_id:
        doc = client.get(f"api/campaigns/{campaign_id}").json()
        outcome = doc.get("outcome") or (doc.get("summary") or {}).get("outcome")
        for run in doc.get("runs", []):
            loaded = store.load_run(run["run_id"])
            t = np.asarray(loaded.data["t_s"], dtype=float)
            period_s = float(loaded.meta.get("sensors", {}).get("encoder_period_s")
                             or period_s)
            run_missing, run_jitter = acquisition_figures(t, period_s)
            missing += run_missing
            lost += int((loaded.meta.get("result") or {}).get("samples_dropped", 0))
            jitters.append(run_jitter)
            n_rows += t.size
    return {"completed": done.get("state") == "completed", "state": done.get("state"),
            "message": done.get("fault") or done.get("message"), "samples_lost": lost,
            "missing_periods": missing, "jitter_p99_ms": max(jitters) if jitters else None,
            "rows": n_rows, "period_s": period_s, "diagnosis_http_status": diagnosis_status,
            "outcome": outcome}


def run_load_scenario(workdir: Path | None = None, *, positions: tuple[float, ...] = (
        0.0, 90.0, 180.0, 270.0), steps_per_quarter: int = 4, busy: int = 3,
        sse_clients: int = 20, timeout_s: float = 600.0, realtime_priority: int | None = None,
        device_priority: int | None = None, repeats: int = 1, cli_campaign: Path | None = None,
        plan: dict[str, Any] | None = None) -> dict[str, Any]:
    """Run the scenario of the module docstring; return its figures (see module doc).

    ``repeats``: measured campaigns one after the other under the same load (each with the
    diagnosis requested while it runs); ``load_campaign_completed`` is 1 only if all
    completed, ``load_completed_in_a_row`` counts them from the first. ``cli_campaign``: a
    campaign file run with ``rig campaign run FILE --simulated`` (its own simulated rig)
    beside them, under the same load (``load_cli_campaign_completed``). ``plan``: keys of
    the page's plan set over the default for the earlier and the measured campaigns (the
    test's shorter plan).

    ``realtime_priority``: SCHED_FIFO for the simulated devices and, through the rig
    configuration they write (``[rig] realtime_priority``), for the engine process.
    ``device_priority``: SCHED_FIFO for the simulated devices only (they stand in for
    hardware, which has its own CPU; the engine, the server and the CLI campaign's measuring
    process stay on the normal scheduler).
    """
    env = _sim_env(realtime_priority, device_priority)
    with contextlib.ExitStack() as stack:
        workdir, store, stats, url = _served(stack, workdir, env)
        client = stack.enter_context(httpx.Client(base_url=url, timeout=30))
        # the earlier campaign (no load): the one the page is asked to diagnose
        earlier = _measure(client, _campaign_body("earlier", list(positions),
                                                  steps_per_quarter, plan), timeout_s)
        if earlier["state"] != "completed":
            raise RuntimeError(f"the earlier campaign did not complete: {earlier}")
        earlier_id = earlier["last_result"]["campaign_id"]
        from rig.store import Store

        earlier_path = Store(store).get_campaign(earlier_id).path

        load = BackgroundLoad()
        stack.callback(load.stop)
        load.busy(busy)
        if earlier_path:
            loop = (f"while true; do {shlex.join([*RIG, 'diagnose', str(earlier_path)])} "
                    f">/dev/null 2>&1; done")
            load.start(["bash", "-c", loop])
        load.start([sys.executable, "-c", SSE_CLIENTS_SCRIPT, url, str(sse_clients)])
        time.sleep(2.0)  # the load is on before the campaign starts

        cli = None
        if cli_campaign is not None:  # the engineer's CLI campaign on its own simulated rig
            cli_json = workdir / "cli-campaign.json"
            cli_log = stack.enter_context(open(workdir / "cli-campaign.log", "w",
                                               encoding="utf-8"))
            cli = load.start([*RIG, "campaign", "run", str(cli_campaign), "--simulated",
                              "--store", str(workdir / "cli-store"), "--json", str(cli_json)],
                             stdout=cli_log, stderr=cli_log, cwd=workdir, env=env)
        the_store = Store(store)
        campaigns: list[dict[str, Any]] = []
        for i in range(repeats):
            campaigns.append(_measure_under_load(client, the_store, _campaign_body(
                f"under-load-{i}", list(positions), steps_per_quarter, plan), earlier_id,
                timeout_s))
        cli_figures: dict[str, Any] = {}
        if cli is not None:
            try:
                cli.wait(timeout_s)
            except subprocess.TimeoutExpired:
                cli.kill()
            doc = (json.loads(cli_json.read_text(encoding="utf-8")) if cli_json.is_file()
                   else {})
            cli_figures = {"load_cli_campaign_completed": int(
                cli.returncode in (0, 1) and doc.get("status") == "completed"),
                "load_cli_campaign_exit": cli.returncode,
                "load_cli_campaign_reason": doc.get("reason")}
        load.stop()
        completed = [c["completed"] for c in campaigns]
        in_a_row = next((i for i, ok in enumerate(completed) if not ok), len(completed))
        jitters = [c["jitter_p99_ms"] for c in campaigns if c["jitter_p99_ms"] is not None]
        last = campaigns[-1]
        drive = json.loads(stats.read_text(encoding="utf-8")) if stats.is_file() else {}
        return {
            "load_campaign_completed": int(all(completed)),
            "load_samples_lost": sum(c["samples_lost"] for c in campaigns),
            "load_missing_periods": sum(c["missing_periods"] for c in campaigns),
            "load_max_keepalive_gap_s": drive.get("drive_max_write_gap_s"),
            "load_watchdog_s": drive.get("drive_watchdog_s"),
            "load_acquisition_jitter_p99_ms": max(jitters) if jitters else None,
            "load_watchdog_trips": drive.get("drive_watchdog_trips"),
            "load_campaigns": repeats,
            "load_completed_in_a_row": in_a_row,
            "load_outcomes": [c["outcome"] for c in campaigns],
            "load_rows": sum(c["rows"] for c in campaigns),
            "load_period_s": last["period_s"],
            "load_diagnosis_http_status": next(
                (c["diagnosis_http_status"] for c in campaigns
                 if c["diagnosis_http_status"] != 200), 200),
            "load_state": last["state"],
            "load_message": next((c["message"] for c in campaigns if not c["completed"]),
                                 last["message"]),
            **cli_figures,
        }


def _estop_times(client: httpx.Client, presses: int) -> list[float]:
    """The E-stop's HTTP answer time (s) for ``presses`` presses, token-less like the
    page's button (its own keep-alive connection), 0.3 s apart; the latched fault is reset
    after each (with the token)."""
    times = []
    viewer = httpx.Client(base_url=client.base_url, timeout=30)
    viewer.get("static/app.js")  # the connection is open, as the page's is
    for _ in range(presses):
        t0 = time.monotonic()
        r = viewer.post("api/control/estop")
        times.append(time.monotonic() - t0)
        r.raise_for_status()
        time.sleep(0.3)
        client.post("api/devices/reset-faults", json={}, headers=AUTH)
    viewer.close()
    return times


def run_preview_flood(workdir: Path | None = None, *, clients: int = 60, busy: int = 2,
                      positions: tuple[float, ...] = (0.0, 180.0), steps_per_quarter: int = 4,
                      max_seconds: float = 300.0, estop_presses: int = 5,
                      device_priority: int | None = None) -> dict[str, Any]:
    """Issue 21 item 10: a campaign started from the page while ``clients`` token-less
    clients flood the plan preview endpoint (``FLOOD_SCRIPT``, 127.0.0.1 only, stopped
    after the campaign and the E-stop presses or after ``max_seconds``) beside ``busy``
    busy processes; then the E-stop pressed ``estop_presses`` times under the same flood
    (and as often before the flood and the busy processes began, for comparison).

    Figures: ``load_preview_flood_completed`` (1 or 0), ``load_preview_flood_estop_s`` (the
    slowest E-stop answer, s), the flood's answers by status, and the drive's keepalive
    figures. The bench's own client sends the operator token (it is the operator)."""
    env = _sim_env(None, device_priority)
    with contextlib.ExitStack() as stack:
        workdir, store, stats, url = _served(stack, workdir, env)
        client = stack.enter_context(httpx.Client(base_url=url, timeout=30, headers=AUTH))
        _wait_state(client, ("idle",), 120.0)
        body = _campaign_body("flood", list(positions), steps_per_quarter)
        body_file = workdir / "preview-body.json"
        body_file.write_text(json.dumps(body), encoding="utf-8")
        counts_file = workdir / "flood-counts.json"
        quiet = _estop_times(client, estop_presses)  # the same presses without the flood
        load = BackgroundLoad()
        stack.callback(load.stop)
        load.busy(busy)
        load.start([sys.executable, "-c", FLOOD_SCRIPT, url, str(clients), str(max_seconds),
                    str(body_file), str(counts_file)])
        time.sleep(3.0)  # the flood is on before the campaign starts
        done = _measure(client, body, max_seconds)
        estop = _estop_times(client, estop_presses)
        flood = (json.loads(counts_file.read_text(encoding="utf-8"))
                 if counts_file.is_file() else {})
        load.stop()
        drive = json.loads(stats.read_text(encoding="utf-8")) if stats.is_file() else {}
        result = done.get("last_result") or {}
        return {
            "load_preview_flood_completed": int(done.get("state") == "completed"),
            "load_preview_flood_estop_s": max(estop),
            "load_preview_flood_estop_all_s": [round(t, 4) for t in estop],
            "load_preview_flood_estop_quiet_s": [round(t, 4) for t in quiet],
            "load_preview_flood_state": done.get("state"),
            "load_preview_flood_message": done.get("fault") or done.get("message"),
            "load_preview_flood_outcome": result.get("outcome"),
            "load_preview_flood_answers": flood,
            "load_preview_flood_max_keepalive_gap_s": drive.get("drive_max_write_gap_s"),
            "load_preview_flood_watchdog_trips": drive.get("drive_watchdog_trips"),
        }
