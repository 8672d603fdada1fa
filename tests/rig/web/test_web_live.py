"""The live path: rows recorded into the store are tapped, decimated and streamed to pages
(server-sent events over a real uvicorn server on 127.0.0.1); a slow page loses its oldest
batches, never a sample on disk."""

from __future__ import annotations

import asyncio
import json
import threading
from pathlib import Path

import httpx
import pytest

from rig.store import Store
from rig.web import create_app
from rig.web.live import CLIENT_QUEUE_BATCHES, LiveHub, decimate
from rig.web.live_tap import TapStore
from rig.web.server import BackgroundServer
from rig.web.settings import resolve_settings

COLUMNS = ["t_s", "torque_Nm", "output_angle_deg"]


def test_decimate_is_bounded_even_and_keeps_the_newest():
    rows = [(float(i),) for i in range(1000)]
    out = decimate(rows, 50)
    assert len(out) == 50 and out[0] == rows[0] and out[-1] == rows[-1]
    gaps = {b[0] - a[0] for a, b in zip(out, out[1:], strict=False)}
    assert gaps <= {20.0, 21.0}  # (1000 - 1) / 49 = 20.4: even spacing
    assert decimate(rows[:10], 50) == rows[:10]
    assert decimate(rows, 1) == [rows[-1]]


def test_tap_writes_every_row_and_shows_a_decimated_few(tmp_path: Path):
    store = Store(tmp_path / "store")
    hub = LiveHub(max_points_per_tick=25)
    tap = TapStore(store, hub)

    async def scenario() -> list[dict]:
        client = hub.connect()
        with tap.begin_run({"unit": {"serial": "tap"}}, COLUMNS) as rec:
            for i in range(1000):
                rec.append([i * 0.001, 0.01 * i, 0.001 * i])
        hub.pump_once()
        out = []
        while not client.queue.empty():
            out.append(client.queue.get_nowait())
        return out

    messages = asyncio.run(scenario())
    run_id = tap.recorder.run_id
    assert store.load_run(run_id).n_samples == 1000  # full rate to disk
    assert messages[0] == {"type": "run_begin", "run_id": run_id}
    batch = messages[1]
    assert batch["type"] == "rows" and batch["n_measured"] == 1000
    assert len(batch["torque_Nm"]) == 25
    assert batch["t_s"][-1] == pytest.approx(0.999)
    assert batch["torque_Nm"][-1] == pytest.approx(9.99)
    assert batch["twist_arcmin"][-1] == pytest.approx(0.999 * 60.0)  # deg -> arcmin
    assert batch["t_wall_s"] <= batch["t_sent_s"] + 1.0


def test_a_slow_page_loses_its_oldest_batches_only():
    hub = LiveHub()

    async def scenario() -> tuple[list[dict], int, int]:
        slow = hub.connect()
        fast = hub.connect()
        got_fast = 0
        for k in range(3 * CLIENT_QUEUE_BATCHES):
            hub.add_rows([(k * 0.01, float(k), 0.0, 0.0)])
            hub.pump_once()
            while not fast.queue.empty():
                fast.queue.get_nowait()
                got_fast += 1
        kept = []
        while not slow.queue.empty():
            kept.append(slow.queue.get_nowait())
        return kept, slow.dropped, got_fast

    kept, dropped, got_fast = asyncio.run(scenario())
    assert got_fast == 3 * CLIENT_QUEUE_BATCHES
    assert len(kept) == CLIENT_QUEUE_BATCHES and dropped == 2 * CLIENT_QUEUE_BATCHES
    assert [m["torque_Nm"][0] for m in kept] == [
        float(k) for k in range(2 * CLIENT_QUEUE_BATCHES, 3 * CLIENT_QUEUE_BATCHES)]
    assert hub.rows_in == 3 * CLIENT_QUEUE_BATCHES


def test_pages_receive_rows_over_server_sent_events(tmp_path: Path):
    store = Store(tmp_path / "store")
    settings = resolve_settings(store_root=store.root, token="a-token-for-sse")
    app = create_app(settings, store=store)
    hub: LiveHub = app.state.hub
    received: list[tuple[str, dict]] = []
    connected = threading.Event()

    with BackgroundServer(app) as server:
        def read_stream() -> None:
            with httpx.stream("GET", server.url + "api/live", timeout=30.0) as r:
                assert r.headers["content-type"].startswith("text/event-stream")
                event = None
                for line in r.iter_lines():
                    if line.startswith("event: "):
                        event = line[7:]
                    elif line.startswith("data: ") and event:
                        received.append((event, json.loads(line[6:])))
                        if event == "hello":
                            connected.set()
                        if event == "rows":
                            return

        reader = threading.Thread(target=read_stream, daemon=True)
        reader.start()
        assert connected.wait(30.0)
        tap = TapStore(store, hub)
        with tap.begin_run({"unit": {"serial": "sse"}}, COLUMNS) as rec:
            for i in range(200):
                rec.append([i * 0.002, 5.0, 1.0])
        reader.join(30.0)
    kinds = [k for k, _ in received]
    assert kinds[0] == "hello" and "run_begin" in kinds and kinds[-1] == "rows"
    rows = received[-1][1]
    assert rows["run_id"] == tap.recorder.run_id
    assert rows["torque_Nm"][-1] == 5.0 and rows["twist_arcmin"][-1] == 60.0
    assert hub.n_clients == 0  # the page left: its queue is gone
