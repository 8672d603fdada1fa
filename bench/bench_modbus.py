"""Modbus TCP torque polling: sustained rate, samples lost, timestamp jitter, safe-state time.

The simulator runs in its own process (``python -m simulators.modbus.server``), as on the
rig. The torque sensor is polled on a fixed 250 Hz schedule (absolute deadlines) for
``BENCH_SECONDS`` (default 60 s). A tick is lost when its read fails or when the loop falls a
whole period behind. Jitter: deviation of each sample's timestamp from its scheduled tick,
about the median deviation (lost ticks do not count as jitter; they are counted as lost).
Targets: >= 200 Hz sustained, p99 jitter < 2 ms.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator

import numpy as np

from bench.processes import stop_process
from drivers.errors import DeviceError
from drivers.loading_drive import LoadingDrive, LoadingDriveConfig
from drivers.modbus.torque_sensor import ModbusTorqueSensor, ModbusTorqueSensorConfig

POLL_HZ = 250.0


def _paced_poll(sensor: ModbusTorqueSensor, seconds: float) -> dict[str, float]:
    period = 1.0 / POLL_HZ
    stamps: list[float] = []
    offsets: list[float] = []  # sample timestamp - its scheduled tick (s)
    lost = 0
    t0 = time.monotonic()
    tick = 0
    n_ticks = int(seconds * POLL_HZ)
    while tick < n_ticks:
        deadline = t0 + tick * period
        now = time.monotonic()
        if now < deadline:
            time.sleep(deadline - now)
        elif now - deadline > period:  # a whole period behind: those ticks are lost
            behind = int((now - deadline) / period)
            lost += behind
            tick += behind
            continue
        try:
            stamps.append(sensor.read().t_s)
            offsets.append(stamps[-1] - deadline)
        except DeviceError:
            lost += 1
        tick += 1
    elapsed = time.monotonic() - t0
    off = np.asarray(offsets)
    jitter = np.abs(off - np.median(off)) if len(off) else off
    return {
        "rate_Hz": len(stamps) / elapsed,
        "lost": float(lost),
        "jitter_p99_ms": float(np.percentile(jitter, 99) * 1e3) if len(jitter) else float("nan"),
        "jitter_max_ms": float(jitter.max() * 1e3) if len(jitter) else float("nan"),
    }


def _free_run(sensor: ModbusTorqueSensor, seconds: float) -> tuple[float, float]:
    latencies = []
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        latencies.append(sensor.read().latency_s)
    return len(latencies) / seconds, float(np.percentile(latencies, 99) * 1e3)


def run() -> Iterator[dict]:
    seconds = float(os.environ.get("BENCH_SECONDS", "60"))
    proc = subprocess.Popen([sys.executable, "-m", "simulators.modbus.server", "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        host, port = json.loads(proc.stdout.readline())["modbus_tcp"].rsplit(":", 1)
        where = {"host": host, "port": int(port), "timeout_s": 1.0}
        sensor = ModbusTorqueSensor(ModbusTorqueSensorConfig(**where))
        drive = LoadingDrive(LoadingDriveConfig(**where, torque_limit_Nm=10.0,
                                                watchdog_s=60.0), link=sensor.link)
        sensor.read()  # connect before timing
        paced = _paced_poll(sensor, seconds)
        common = {"transport": "tcp", "poll_Hz": POLL_HZ, "seconds": seconds}
        yield {"name": "modbus_torque_poll_rate", "value": round(paced["rate_Hz"], 1),
               "unit": "Hz", "target": ">= 200", **common}
        yield {"name": "modbus_torque_samples_lost", "value": int(paced["lost"]),
               "unit": "samples", "of": int(seconds * POLL_HZ), **common}
        yield {"name": "modbus_torque_jitter_p99", "value": round(paced["jitter_p99_ms"], 3),
               "unit": "ms", "target": "< 2", "max_ms": round(paced["jitter_max_ms"], 3),
               **common}
        free_rate, latency_p99 = _free_run(sensor, min(5.0, max(1.0, seconds / 10)))
        yield {"name": "modbus_torque_max_poll_rate", "value": round(free_rate, 1),
               "unit": "Hz", "transport": "tcp", "latency_p99_ms": round(latency_p99, 3)}
        times = []
        for _ in range(200):
            t = time.monotonic()
            drive.safe_state()
            times.append(time.monotonic() - t)
        yield {"name": "modbus_drive_safe_state_p99", "unit": "ms",
               "value": round(float(np.percentile(times, 99) * 1e3), 3),
               "median_ms": round(float(np.median(times) * 1e3), 3), "transport": "tcp"}
        drive.close()
        sensor.close()
    finally:
        stop_process(proc, 20)
