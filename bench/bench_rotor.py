"""Seed 004 geared rotor: wall time of the critical speeds (synchronous eigenproblem) of the
coupled rotor (2 x 24 Timoshenko elements, 250 coordinates) and of one Campbell speed step.

``cpu_s`` and the load average before the run tell a slow machine from a slow program."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from analysis.models.seed004_modes import campbell, critical_speeds
from analysis.models.seed004_paper import coupled_rotor
from bench.timing import timed


def run() -> Iterator[dict]:
    system = coupled_rotor()
    for name, job in (
        ("seed004_coupled_critical_speeds", lambda: critical_speeds(system)),
        ("seed004_coupled_campbell_step", lambda: campbell(system, np.array([1000.0]))),
    ):
        t = timed(job)
        out = t.result
        yield {
            "name": name,
            **t.fields(),
            "coordinates": system.size,
            "results": len(out) if name.endswith("speeds") else int(out[0][0].size),
        }
