"""One timed call of a benchmark: wall time, process CPU time (all threads) and the load
average before it, so that a slow machine (other jobs) is told from a slow program."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Timed:
    """What :func:`timed` measured around one call."""

    result: Any
    wall_s: float
    cpu_s: float
    load_before: float

    def fields(self) -> dict[str, Any]:
        """The benchmark row's timing keys: ``value`` (wall s), ``unit``, ``cpu_s`` and
        ``load_avg_1min_before``."""
        return {"value": round(self.wall_s, 3), "unit": "s", "cpu_s": round(self.cpu_s, 3),
                "load_avg_1min_before": round(self.load_before, 2)}


def timed(job: Callable[[], Any]) -> Timed:
    """Call ``job()`` once and time it."""
    load_before = os.getloadavg()[0]
    cpu_start, start = time.process_time(), time.perf_counter()
    result = job()
    wall = time.perf_counter() - start
    return Timed(result, wall, time.process_time() - cpu_start, load_before)
