"""Serial transducer streaming: rate, lost samples and timestamp jitter over pty and TCP.

The driver streams from the simulator (``python -m simulators.transducer`` in its own
process, as a real device is its own hardware) at 1000 Hz (the most 460800 Bd carries is
1047 Hz) for ``BENCH_SECONDS`` in all (default 60 s, split between the pty and the TCP
link). Figures per link (each row also carries the 1-min load average):

- ``rate``: samples received / elapsed time (Hz), target >= 500 Hz;
- ``lost``: samples missing from the device's sequence counter;
- ``interval jitter p99``: 99th percentile of |host interval - 1/rate| (ms), target < 2 ms;
- ``latency jitter p99``: 99th percentile of |latency - median latency| (ms), the latency
  being host receive time minus the device's sample time (both monotonic clocks): what
  the link and the driver add;
- ``device interval jitter p99``: the same as the interval jitter on the device's own
  timestamps: how late the simulator's thread took its samples (a real transducer
  samples on a hardware timer);
- ``query round trip``: median and p99 of one ``TQ?`` (ms).
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from bench.processes import stop_process
from drivers.transducer.serial import SerialTorqueTransducer, TransducerConfig

REPO = Path(__file__).resolve().parent.parent

RATE_HZ = 1000.0
QUERIES = 500


def _seconds() -> float:
    return float(os.environ.get("BENCH_SECONDS", "60"))


@contextlib.contextmanager
def _simulator_process(transport: str) -> Iterator[str]:
    """Run ``python -m simulators.transducer`` and yield the address it prints."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "simulators.transducer", "--transport", transport],
        cwd=REPO,
        stdout=subprocess.PIPE,
    )
    try:
        assert proc.stdout is not None
        ready, _, _ = select.select([proc.stdout], [], [], 60.0)
        if not ready:
            raise RuntimeError("the transducer simulator printed no address within 60 s")
        yield json.loads(proc.stdout.readline())["transducer"]
    finally:
        stop_process(proc, 30)


def _measure(transport: str, seconds: float) -> Iterator[dict]:
    with (
        _simulator_process(transport) as address,
        SerialTorqueTransducer(TransducerConfig(url=address, timeout_s=2.0)) as tt,
    ):
        round_trips = []
        for _ in range(QUERIES):
            start = time.perf_counter()
            tt.read()
            round_trips.append(time.perf_counter() - start)
        host, device = [], []
        tt.start_stream(RATE_HZ)
        start = time.monotonic()
        while time.monotonic() - start < seconds:
            r = tt.next_reading()
            host.append(r.t_s)
            device.append(r.device_t_s)
        elapsed = time.monotonic() - start
        stats = tt.stop_stream()
    host_s, device_s = np.asarray(host), np.asarray(device)
    interval_jitter = np.abs(np.diff(host_s) - 1.0 / RATE_HZ)
    device_jitter = np.abs(np.diff(device_s) - 1.0 / RATE_HZ)
    # the simulator's clock started with its process: align both to the first sample
    latency = (host_s - host_s[0]) - (device_s - device_s[0])
    latency_jitter = np.abs(latency - np.median(latency))
    rt = np.asarray(round_trips)
    name = f"serial_{transport}"
    common = {
        "transport": transport,
        "seconds": round(elapsed, 2),
        "rate_set_Hz": RATE_HZ,
        "load_1min": round(os.getloadavg()[0], 2),
    }
    yield {"name": f"{name}_stream_rate", "value": stats.received / elapsed, "unit": "Hz",
           "target": ">= 500", **common}
    yield {"name": f"{name}_samples_lost", "value": stats.lost, "unit": "samples",
           "received": stats.received, "bad_lines": stats.bad_lines, **common}
    yield {"name": f"{name}_interval_jitter_p99", "unit": "ms", "target": "< 2",
           "value": float(np.percentile(interval_jitter, 99) * 1e3), **common}
    yield {"name": f"{name}_latency_jitter_p99", "unit": "ms",
           "value": float(np.percentile(latency_jitter, 99) * 1e3), **common}
    yield {"name": f"{name}_device_interval_jitter_p99", "unit": "ms",
           "value": float(np.percentile(device_jitter, 99) * 1e3), **common}
    yield {"name": f"{name}_query_round_trip_median", "unit": "ms",
           "value": float(np.median(rt) * 1e3), "queries": QUERIES}
    yield {"name": f"{name}_query_round_trip_p99", "unit": "ms",
           "value": float(np.percentile(rt, 99) * 1e3), "queries": QUERIES}


def run() -> Iterator[dict]:
    """Benchmark rows for ``python -m bench serial``."""
    seconds = _seconds() / 2.0
    for transport in ("pty", "tcp"):
        yield from _measure(transport, seconds)
