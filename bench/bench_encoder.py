"""Encoder PDO throughput at 1 kHz SYNC: virtual bus (in-process) and SLCAN on a socket
(simulator in a separate process). Rows: sustained rate (Hz), samples lost (SYNCs sent minus
position PDOs received), p99 timestamp jitter (ms, |interval - SYNC period|).

``BENCH_SECONDS`` (default 60) sets the length of each run.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from drivers.encoder_canopen import CanBusConfig, CanopenEncoder, EncoderConfig
from simulators.encoder_node import EncoderNode, SweepPlant

SYNC_PERIOD_S = 0.001
REPO = Path(__file__).resolve().parent.parent


def _measure(bus: CanBusConfig, seconds: float) -> dict[str, float]:
    cfg = EncoderConfig(node_id=5, heartbeat_ms=100, timeout_s=3.0, missed_periods=1000, bus=bus)
    enc = CanopenEncoder(cfg)
    stamps: list[float] = []
    enc.start()
    try:
        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds:
            time.sleep(0.05)
            stamps.extend(r.t_s for r in enc.readings())
        enc.network.stop_sync()
        syncs = enc.network.syncs_sent  # every SYNC since NMT start asks for one PDO
        drain_deadline = time.monotonic() + 10.0
        while time.monotonic() < drain_deadline:  # PDOs still on their way
            time.sleep(0.2)
            batch = [r.t_s for r in enc.readings()]
            stamps.extend(batch)
            if not batch:
                break
        elapsed = time.monotonic() - t0
        received = enc.health().samples
    finally:
        enc.close()
    t = np.asarray(stamps)
    jitter_ms = np.abs(np.diff(t) - SYNC_PERIOD_S) * 1000.0 if t.size > 1 else np.array([np.nan])
    return {
        "rate_Hz": t.size / (t[-1] - t[0]) if t.size > 1 else 0.0,
        "lost": float(syncs - received),
        "syncs": float(syncs),
        "received": float(received),
        "jitter_p99_ms": float(np.percentile(jitter_ms, 99)),
        "jitter_p50_ms": float(np.percentile(jitter_ms, 50)),
        "seconds": elapsed,
    }


def _rows(kind: str, m: dict[str, float]) -> Iterator[dict]:
    extra = {"syncs_sent": int(m["syncs"]), "received": int(m["received"]),
             "seconds": round(m["seconds"], 2)}
    yield {"name": f"encoder_pdo_rate_{kind}", "value": round(m["rate_Hz"], 1), "unit": "Hz",
           "target": 1000, **extra}
    yield {"name": f"encoder_samples_lost_{kind}", "value": int(m["lost"]), "unit": "samples",
           "target": 0, **extra}
    yield {"name": f"encoder_jitter_p99_{kind}", "value": round(m["jitter_p99_ms"], 3),
           "unit": "ms", "target": "< 2", "p50_ms": round(m["jitter_p50_ms"], 3)}


def run() -> Iterator[dict]:
    seconds = float(os.environ.get("BENCH_SECONDS", "60"))

    channel = f"bench-{uuid.uuid4().hex[:8]}"
    node = EncoderNode(SweepPlant(), node_id=5, channel=channel)
    node.start()
    try:
        bus = CanBusConfig(interface="virtual", channel=channel, sync_period_s=SYNC_PERIOD_S)
        yield from _rows("virtual", _measure(bus, seconds))
    finally:
        node.stop()

    proc = subprocess.Popen(
        [sys.executable, "-m", "simulators.encoder_node", "--node-id", "5"],
        cwd=REPO, stdout=subprocess.PIPE, text=True,
    )
    try:
        address = json.loads(proc.stdout.readline())["encoder_slcan"]
        bus = CanBusConfig(interface="slcan", channel=address, sync_period_s=SYNC_PERIOD_S,
                           bus_options={"sleep_after_open": 0})
        yield from _rows("slcan_socket", _measure(bus, seconds))
    finally:
        proc.terminate()
        proc.wait(timeout=10)
