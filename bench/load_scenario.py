"""A campaign on the simulated rig under load, started from the control page's API.

Used by ``python -m bench load`` (figures) and ``tests/test_load.py`` (targets). What runs:

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

__all__ = ["run_load_scenario", "acquisition_figures"]

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


@contextlib.contextmanager
def _serve(store: Path, stats: Path, log: Path, realtime_priority: int | None
           ) -> Iterator[str]:
    env = {**os.environ, "RIG_SIM_STATS": str(stats)}
    env.pop("RIG_SIM_REALTIME_PRIORITY", None)
    if realtime_priority is not None:
        env["RIG_SIM_REALTIME_PRIORITY"] = str(realtime_priority)
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


def _campaign_body(name: str, positions: list[float], steps_per_quarter: int
                   ) -> dict[str, Any]:
    unit = json.loads((ROOT / "rig" / "examples" / "units" / "seed000-pair1.json")
                      .read_text(encoding="utf-8"))
    return {"kind": "campaign", "name": name, "unit": {**unit, "serial": f"load-{name}"},
            "plan": {"rated_torque_Nm": 10.0, "steps_per_quarter": steps_per_quarter,
                     "pre_cycles": 1},
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


def run_load_scenario(workdir: Path | None = None, *, positions: tuple[float, ...] = (
        0.0, 90.0, 180.0, 270.0), steps_per_quarter: int = 4, busy: int = 3,
        sse_clients: int = 20, timeout_s: float = 600.0, realtime_priority: int | None = None
        ) -> dict[str, Any]:
    """Run the scenario of the module docstring; return its figures (see module doc).

    ``realtime_priority``: SCHED_FIFO for the simulated devices and, through the rig
    configuration they write (``[rig] realtime_priority``), for the engine process.
    """
    with contextlib.ExitStack() as stack:
        if workdir is None:
            workdir = Path(stack.enter_context(tempfile.TemporaryDirectory()))
        store = workdir / "store"
        store.mkdir(parents=True, exist_ok=True)
        stats = workdir / "sim-stats.json"
        url = stack.enter_context(_serve(store, stats, workdir / "serve.log",
                                        realtime_priority))
        client = stack.enter_context(httpx.Client(base_url=url, timeout=30))
        # the earlier campaign (no load): the one the page is asked to diagnose
        earlier = _measure(client, _campaign_body("earlier", list(positions),
                                                  steps_per_quarter), timeout_s)
        if earlier["state"] != "completed":
            raise RuntimeError(f"the earlier campaign did not complete: {earlier}")
        earlier_id = earlier["last_result"]["campaign_id"]
        from rig.store import Store

        earlier_path = Store(store).get_campaign(earlier_id).path

        procs: list[subprocess.Popen] = []

        def stop_load() -> None:
            for p in procs:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(p.pid, 9)

        stack.callback(stop_load)
        for _ in range(busy):
            procs.append(subprocess.Popen([sys.executable, "-c", BUSY_SCRIPT],
                                          start_new_session=True))
        if earlier_path:
            loop = (f"while true; do {shlex.join([*RIG, 'diagnose', str(earlier_path)])} "
                    f">/dev/null 2>&1; done")
            procs.append(subprocess.Popen(["bash", "-c", loop], start_new_session=True))
        procs.append(subprocess.Popen([sys.executable, "-c", SSE_CLIENTS_SCRIPT, url,
                                       str(sse_clients)], start_new_session=True))
        time.sleep(2.0)  # the load is on before the campaign starts

        body = _campaign_body("under-load", list(positions), steps_per_quarter)
        _wait_state(client, ("idle", "completed", "aborted"), 120.0)
        client.post("api/devices/input-lock", json={"confirm": True}, headers=AUTH)
        r = client.post("api/control/start", json=body, headers=AUTH)
        started = r.status_code == 200
        diagnosis_status = None
        if started:
            time.sleep(1.0)
            d = client.get(f"api/campaigns/{earlier_id}/diagnosis.json", timeout=300)
            diagnosis_status = d.status_code
        done = (_wait_state(client, ("completed", "aborted"), timeout_s) if started
                else {"state": "refused", "message": r.text})
        stop_load()
        result = done.get("last_result") or {}
        campaign_id = result.get("campaign_id")
        lost, missing, jitters, n_rows = 0, 0, [], 0
        period_s = 0.002
        if campaign_id:
            the_store = Store(store)
            for run in client.get(f"api/campaigns/{campaign_id}").json().get("runs", []):
                loaded = the_store.load_run(run["run_id"])
                t = np.asarray(loaded.data["t_s"], dtype=float)
                period_s = float(loaded.meta.get("sensors", {}).get("encoder_period_s")
                                 or period_s)
                run_missing, run_jitter = acquisition_figures(t, period_s)
                missing += run_missing
                lost += int((loaded.meta.get("result") or {}).get("samples_dropped", 0))
                jitters.append(run_jitter)
                n_rows += t.size
        drive = json.loads(stats.read_text(encoding="utf-8")) if stats.is_file() else {}
        return {
            "load_campaign_completed": int(done.get("state") == "completed"),
            "load_samples_lost": lost,
            "load_missing_periods": missing,
            "load_max_keepalive_gap_s": drive.get("drive_max_write_gap_s"),
            "load_watchdog_s": drive.get("drive_watchdog_s"),
            "load_acquisition_jitter_p99_ms": max(jitters) if jitters else None,
            "load_watchdog_trips": drive.get("drive_watchdog_trips"),
            "load_rows": n_rows,
            "load_period_s": period_s,
            "load_diagnosis_http_status": diagnosis_status,
            "load_state": done.get("state"),
            "load_message": done.get("fault") or done.get("message"),
        }
