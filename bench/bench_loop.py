"""Loop metrics on a 1,000,000-sample run: wall time and peak memory of ``analyse_loop``.

The run: 5 cycles of constant-rate ramps to ±rated (10 N·m), the run-format reference loop
(6 arcmin play, 5 N·m/arcmin), white noise on torque (0.01 N·m) and twist (0.02 arcmin),
a 23-bit output encoder, Harmonic Drive corners asked for too.
"""

from __future__ import annotations

import statistics
import time
import tracemalloc
from collections.abc import Iterator

import numpy as np

from analysis.loop import analyse_loop
from analysis.loop.synthetic import dead_zone_twist, triangle_profile

N_SAMPLES = 1_000_000
CYCLES = 5
RATED_Nm = 10.0
ENCODER_ARCMIN = 360.0 * 60.0 / 2**23


def make_run(seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Time (s), measured torque (N·m) and quantised noisy twist (arcmin), 1e6 samples."""
    rng = np.random.default_rng(seed)
    n_quarter = N_SAMPLES // (4 * CYCLES)
    torque = triangle_profile(RATED_Nm, n_quarter, cycles=CYCLES, phase=0.5)[:N_SAMPLES]
    twist = dead_zone_twist(torque, 6.0, 5.0) + rng.normal(0.0, 0.02, torque.size)
    twist = np.round(twist / ENCODER_ARCMIN) * ENCODER_ARCMIN
    torque = torque + rng.normal(0.0, 0.01, torque.size)
    t = np.arange(torque.size) * 1e-4
    return t, torque, twist


def _analyse(t: np.ndarray, torque: np.ndarray, twist: np.ndarray):
    return analyse_loop(
        t, torque, twist,
        rated_torque_Nm=RATED_Nm, twist_resolution_arcmin=ENCODER_ARCMIN,
        hd_T1_Nm=2.0, hd_T2_Nm=5.0,
    )  # fmt: skip


def run() -> Iterator[dict]:
    t, torque, twist = make_run()
    result = _analyse(t, torque, twist)  # warm-up (imports, page faults)
    times = []
    for _ in range(5):
        start = time.perf_counter()
        _analyse(t, torque, twist)
        times.append(time.perf_counter() - start)
    yield {
        "name": "loop_metrics_1M_samples",
        "value": statistics.median(times),
        "unit": "s",
        "target": 0.5,
        "min_s": min(times),
        "max_s": max(times),
        "repeats": len(times),
        "n_cycles": result.n_cycles,
        "lost_motion_arcmin": result.metrics["lost_motion_arcmin"].value,
    }
    data_bytes = t.nbytes + torque.nbytes + twist.nbytes
    tracemalloc.start()
    try:
        _analyse(t, torque, twist)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    yield {
        "name": "loop_metrics_1M_peak_memory_ratio",
        "value": peak / data_bytes,
        "unit": "x",
        "target": 10,
        "peak_MB": peak / 1e6,
        "data_MB": data_bytes / 1e6,
    }
