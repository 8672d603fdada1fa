"""``rig serve`` stopping on Ctrl-C with pages open (issue 21 item 19; target: under 2 s).

The console script on the simulated rig (127.0.0.1, a free port); ``BENCH_STREAMS`` (default
3) live streams (``/api/live``, server-sent events) are read as open pages would; then SIGINT
goes to the process group, as a terminal's Ctrl-C does. Figures: ``serve_stop_s`` (SIGINT to
the server's exit: the streams end, the rig is brought to its safe state and closed, the
simulated rig's processes stop) and ``serve_stop_streams_s`` (SIGINT to the last live stream
ended by the server). ``tracebacks`` counts "Traceback" in the server's stderr (must be 0).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from tempfile import TemporaryDirectory
from typing import Any

import httpx


def _stream(url: str, opened: threading.Event, ended: list[float]) -> None:
    try:
        with httpx.stream("GET", url + "api/live",
                          timeout=httpx.Timeout(30.0, read=None)) as response:
            for text in response.iter_text():
                if "event: hello" in text:
                    opened.set()
    except httpx.HTTPError:
        pass
    ended.append(time.monotonic())


def _measure(n_streams: int) -> dict[str, Any]:
    with TemporaryDirectory(prefix="bench-serve-stop-") as tmp:
        env = {k: v for k, v in os.environ.items() if k != "RIG_WEB_TOKEN"}
        proc = subprocess.Popen(
            [sys.executable, "-c", "from rig.cli import main; main()", "serve", "--simulated",
             "--port", "0", "--store", str(Path(tmp) / "store")],
            cwd=tmp, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            start_new_session=True)
        err: list[str] = []
        threading.Thread(target=lambda: err.extend(proc.stderr), daemon=True).start()
        try:
            url = re.search(r"http://\S+/", proc.stdout.readline()).group(0)
            threading.Thread(target=proc.stdout.read, daemon=True).start()
            deadline = time.monotonic() + 120
            while httpx.get(url + "api/status", timeout=30).json().get("state") != "idle":
                if time.monotonic() > deadline:
                    raise RuntimeError("the simulated rig did not open in 120 s")
                time.sleep(0.3)
            ended: list[float] = []
            opened = [threading.Event() for _ in range(n_streams)]
            for event in opened:
                threading.Thread(target=_stream, args=(url, event, ended), daemon=True).start()
            for event in opened:
                event.wait(30)
            sent = time.monotonic()
            os.killpg(proc.pid, signal.SIGINT)
            proc.wait(timeout=120)
            stop_s = time.monotonic() - sent
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=10)
        time.sleep(0.5)
    return {"stop_s": stop_s, "streams_s": max(ended) - sent if ended else None,
            "tracebacks": "".join(err).count("Traceback")}


def run() -> Iterator[dict[str, Any]]:
    n = int(os.environ.get("BENCH_STREAMS", "3"))
    out = _measure(n)
    load = round(os.getloadavg()[0], 1)
    yield {"name": "serve_stop_s", "value": round(out["stop_s"], 2), "unit": "s",
           "target": 2.0, "streams": n, "tracebacks": out["tracebacks"], "load_avg_1min": load}
    yield {"name": "serve_stop_streams_s", "value": None if out["streams_s"] is None
           else round(out["streams_s"], 2), "unit": "s", "streams": n}
