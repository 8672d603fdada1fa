"""Issue 21 item 10: a token-less flood is rate-limited (429 with Retry-After, per client
address) while the operator's requests and the E-stop are still served, and plan previews
are computed in a worker process of lower priority with a bounded queue (503 when full),
not in the server's process (its event loop) nor in the engine's.

The page runs on a real uvicorn server on 127.0.0.1 (a free port), with a real store and no
rig; figures for the flood beside a measuring rig come from ``python -m bench load``.
"""

from __future__ import annotations

import json
import math
import os
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from rig.store import Store
from rig.web import create_app
from rig.web.ratelimit import GENERAL_RATE, PREVIEW_RATE
from rig.web.server import BackgroundServer
from rig.web.settings import TOKEN_ENV, resolve_settings
from rig.web.workers import QUEUE_LIMIT, worker_pids
from tests.support.paths import REPO

UNIT = json.loads((REPO / "rig" / "examples" / "units" / "seed000-pair1.json").read_text())
TOKEN = "operator-token-for-the-flood"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
SMALL = {"unit": UNIT, "plan": {"rated_torque_Nm": 10.0}}
BIG = {"unit": UNIT, "kind": "campaign",
       "plan": {"rated_torque_Nm": 10.0, "steps_per_quarter": 50, "cycles": 20},
       "axes": {"positions_deg": [0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0]}}


@pytest.fixture
def page(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[httpx.Client]:
    monkeypatch.delenv(TOKEN_ENV, raising=False)
    store = Store(tmp_path / "store")
    app = create_app(resolve_settings(store_root=store.root, token=TOKEN), store=store)
    with BackgroundServer(app) as server, httpx.Client(base_url=server.url,
                                                       timeout=120) as client:
        yield client


def test_a_tokenless_flood_gets_429_while_the_operator_and_the_estop_are_served(
        page: httpx.Client) -> None:
    answers: list[httpx.Response] = []
    lock = threading.Lock()

    def flood(headers: dict[str, str]) -> None:  # far faster than GENERAL_RATE
        for _ in range(int(GENERAL_RATE[1]) // 4):
            r = page.get("/api/status", headers=headers)
            with lock:
                answers.append(r)

    wrong = {"Authorization": "Bearer not-the-token"}  # counts as none
    threads = [threading.Thread(target=flood, args=({} if i % 2 else wrong,))
               for i in range(12)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    refused = [r for r in answers if r.status_code == 429]
    assert refused and {r.status_code for r in answers} == {200, 429}
    assert any("authorization" in r.request.headers for r in refused)
    assert any("authorization" not in r.request.headers for r in refused)
    assert all(int(r.headers["Retry-After"]) >= 1 for r in refused)
    assert "operator token" in refused[0].json()["detail"]
    # the same address with the token is served at once, reads and previews alike
    assert page.get("/api/status", headers=AUTH).status_code == 200
    assert page.post("/api/plan/preview", json=SMALL, headers=AUTH).status_code == 200
    # the E-stop is never limited
    assert page.post("/api/control/estop").status_code == 200


def test_tokenless_previews_have_their_own_tighter_limit(page: httpx.Client) -> None:
    rate, burst = PREVIEW_RATE
    answers: list[httpx.Response] = []
    lock = threading.Lock()

    def ask() -> None:
        r = page.post("/api/plan/preview", json=SMALL)
        with lock:
            answers.append(r)

    t0 = time.monotonic()
    threads = [threading.Thread(target=ask) for _ in range(3 * int(burst))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    elapsed = time.monotonic() - t0
    codes = [r.status_code for r in answers]
    assert 429 in codes and 200 in codes and set(codes) <= {200, 429, 503}, codes
    admitted = len(codes) - codes.count(429)  # 503: admitted, the worker's queue was full
    assert admitted <= burst + math.ceil(rate * elapsed), (codes, elapsed)
    limited = next(r for r in answers if r.status_code == 429)
    assert "plan previews" in limited.json()["detail"]
    assert int(limited.headers["Retry-After"]) >= 1
    assert page.get("/api/status").status_code == 200  # other requests are not held up
    for _ in range(3):  # the operator previews as often as needed
        assert page.post("/api/plan/preview", json=SMALL, headers=AUTH).status_code == 200


def _cpu_ticks(pid: int) -> int:
    """utime + stime of a process (clock ticks, /proc/PID/stat fields 14 and 15)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return int(fields[11]) + int(fields[12])


def test_previews_run_in_a_lower_priority_worker_with_a_bounded_queue(
        page: httpx.Client) -> None:
    assert page.post("/api/plan/preview", json=SMALL, headers=AUTH).status_code == 200
    pids = worker_pids("preview")
    assert pids and os.getpid() not in pids  # not this (the server's) process
    own = os.getpriority(os.PRIO_PROCESS, 0)
    for pid in pids:
        assert os.getpriority(os.PRIO_PROCESS, pid) >= own + 10, pid
    worker_before = sum(_cpu_ticks(pid) for pid in pids)
    big = page.post("/api/plan/preview", json=BIG, headers=AUTH)
    assert big.status_code == 200 and big.json()["n_steps"] > 50_000
    # the plan of 100,000+ steps was built and estimated in the worker (5 ticks: 50 ms of
    # its CPU time at least)
    assert sum(_cpu_ticks(pid) for pid in pids) - worker_before >= 5

    # more previews at once than the queue takes: the rest are told to retry (503)
    answers: list[httpx.Response] = []
    lock = threading.Lock()

    def ask() -> None:
        r = page.post("/api/plan/preview", json=BIG, headers=AUTH)
        with lock:
            answers.append(r)

    threads = [threading.Thread(target=ask) for _ in range(3 * QUEUE_LIMIT["preview"])]
    for t in threads:
        t.start()
    for t in threads:
        t.join(300)
    codes = sorted(r.status_code for r in answers)
    assert set(codes) == {200, 503}, codes
    assert codes.count(200) >= 1
    busy = next(r for r in answers if r.status_code == 503)
    assert busy.headers["Retry-After"] == "1" and "busy" in busy.json()["detail"]
