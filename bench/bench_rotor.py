"""Seed 004 geared rotor: wall time of the critical speeds (synchronous eigenproblem) of the
coupled rotor (2 x 24 Timoshenko elements, 250 coordinates) and of one Campbell speed step.

``cpu_s`` and the load average before the run tell a slow machine from a slow program."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator

import numpy as np

from analysis.models.seed004_modes import campbell, critical_speeds
from analysis.models.seed004_paper import coupled_rotor


def run() -> Iterator[dict]:
    system = coupled_rotor()
    for name, job in (
        ("seed004_coupled_critical_speeds", lambda: critical_speeds(system)),
        ("seed004_coupled_campbell_step", lambda: campbell(system, np.array([1000.0]))),
    ):
        load_before = os.getloadavg()[0]
        cpu_start = time.process_time()
        start = time.perf_counter()
        out = job()
        elapsed = time.perf_counter() - start
        yield {
            "name": name,
            "value": round(elapsed, 3),
            "unit": "s",
            "coordinates": system.size,
            "cpu_s": round(time.process_time() - cpu_start, 3),
            "load_avg_1min_before": round(load_before, 2),
            "results": len(out) if name.endswith("speeds") else int(out[0][0].size),
        }
