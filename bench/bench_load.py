"""Load: a campaign on the simulated rig started from the control page while 3 busy
processes, a diagnosis and 20 live-stream clients run beside it (bench/load_scenario.py).

Figures (issue 12's names): ``load_campaign_completed`` (1 or 0), ``load_samples_lost``,
``load_max_keepalive_gap_s`` (the longest silence the simulated drive saw while enabled),
``load_watchdog_s``, ``load_acquisition_jitter_p99_ms``. ``BENCH_LOAD_REPEATS`` (default 1)
repeats the scenario; then ``load_completed_runs`` counts the completed ones.
Target: completed, 0 samples lost, keepalive gap under half the watchdog.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from typing import Any

from bench.load_scenario import run_load_scenario

UNITS = {"load_campaign_completed": "1/0", "load_samples_lost": "samples",
         "load_max_keepalive_gap_s": "s", "load_watchdog_s": "s",
         "load_acquisition_jitter_p99_ms": "ms"}


def run() -> Iterator[dict[str, Any]]:
    repeats = int(os.environ.get("BENCH_LOAD_REPEATS", "1"))
    completed = 0
    for i in range(repeats):
        figures = run_load_scenario()
        completed += figures["load_campaign_completed"]
        for name, unit in UNITS.items():
            yield {"name": name, "value": figures[name], "unit": unit, "repeat": i,
                   "state": figures["load_state"], "rows": figures["load_rows"]}
    if repeats > 1:
        yield {"name": "load_completed_runs", "value": completed, "unit": f"of {repeats}"}
