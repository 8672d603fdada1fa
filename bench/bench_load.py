"""Load: a campaign on the simulated rig started from the control page while 3 busy
processes, a diagnosis and 20 live-stream clients run beside it (bench/load_scenario.py).

Figures (issue 12's names): ``load_campaign_completed`` (1 or 0), ``load_samples_lost``,
``load_max_keepalive_gap_s`` (the longest silence the simulated drive saw while enabled),
``load_watchdog_s``, ``load_acquisition_jitter_p99_ms``; also ``load_missing_periods``.
Target: completed, 0 samples lost, keepalive gap under half the watchdog.

The simulated devices run under SCHED_FIFO 20 where the system permits it (they stand in for
hardware, which has its own CPU: the drive's watchdog figures must not include the
simulator's own starvation); the server, the engine and the CLI campaign's measuring process
stay on the normal scheduler. ``BENCH_LOAD_DEVICE_PRIORITY=0`` leaves the simulated devices
on the normal scheduler too.

Then the same with real-time priority for the engine as well (``[rig] realtime_priority`` =
20), the names prefixed ``load_rt_``: what SCHED_FIFO buys.
``BENCH_LOAD_REPEATS`` (default 1): campaigns measured one after the other under the same
load in the normal-scheduler pass; ``load_completed_runs`` counts those completed in a row.
Beside them, ``rig campaign run examples/campaigns/seed000-pair1.toml --simulated`` runs on
its own simulated rig under the same load: ``load_cli_campaign_completed`` (1 or 0).
``BENCH_LOAD_RT=0`` skips the RT pass.

Then the preview flood (issue 21 item 10, ``bench.load_scenario.run_preview_flood``): a
2-position campaign started from the page while 60 token-less clients flood the plan
preview endpoint (127.0.0.1, bounded to 300 s) beside 2 busy processes, then the E-stop
pressed 5 times under the flood: ``load_preview_flood_completed`` (target 1) and
``load_preview_flood_estop_s`` (the slowest E-stop answer, target under 0.1 s).
``BENCH_LOAD_FLOOD=0`` skips it; ``BENCH_LOAD_FLOOD=only`` runs only it.

Then the measured value under load (issue 21 item 11, ``bench.load_accuracy``): the lost
motion of both quasi-static loading modes, 2 runs each, measured while 3 busy processes spin,
against the plant's truth: ``load_lost_motion_error_pct`` (the worst run, target under
0.5 %), with the measuring process and the devices at SCHED_FIFO 20 (``BENCH_LOAD_RT=0``:
the devices at ``BENCH_LOAD_DEVICE_PRIORITY``, the measuring process on the normal
scheduler). ``BENCH_LOAD_ACCURACY=0`` skips it; ``BENCH_LOAD_ACCURACY=only`` runs only it.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from typing import Any

from bench.load_accuracy import run_lost_motion_under_load
from bench.load_scenario import ROOT, run_load_scenario, run_preview_flood

UNITS = {"load_campaign_completed": "1/0", "load_samples_lost": "samples",
         "load_missing_periods": "periods", "load_max_keepalive_gap_s": "s",
         "load_watchdog_s": "s", "load_acquisition_jitter_p99_ms": "ms"}
RT_PRIORITY = 20
EXAMPLE_CAMPAIGN = ROOT / "examples" / "campaigns" / "seed000-pair1.toml"


def run() -> Iterator[dict[str, Any]]:
    flood = os.environ.get("BENCH_LOAD_FLOOD", "1")
    accuracy = os.environ.get("BENCH_LOAD_ACCURACY", "1")
    device_priority = int(os.environ.get("BENCH_LOAD_DEVICE_PRIORITY", str(RT_PRIORITY)))
    if accuracy == "only":
        yield from _accuracy_pass(device_priority)
        return
    if flood != "only":
        yield from _load_passes(device_priority)
    if flood != "0":
        yield from _flood_pass(device_priority)
    if accuracy != "0" and flood != "only":
        yield from _accuracy_pass(device_priority)


def _accuracy_pass(device_priority: int) -> Iterator[dict[str, Any]]:
    realtime = RT_PRIORITY if os.environ.get("BENCH_LOAD_RT", "1") != "0" else None
    figures = run_lost_motion_under_load(device_priority=device_priority or None,
                                         realtime_priority=realtime)
    error = figures["load_lost_motion_error_pct"]
    yield {"name": "load_lost_motion_error_pct",
           "value": None if error is None else round(error, 3), "unit": "%",
           "target": "< 0.5", "true_arcmin": round(figures["load_lost_motion_true_arcmin"], 4),
           "completed": figures["load_lost_motion_completed"],
           "runs_without_a_value": figures["load_lost_motion_missing"],
           "device_priority": device_priority or None, "realtime_priority": realtime,
           "runs": figures["load_lost_motion_runs"],
           "aborted_by_the_load": figures["load_lost_motion_aborted"]}


def _flood_pass(device_priority: int) -> Iterator[dict[str, Any]]:
    figures = run_preview_flood(device_priority=device_priority or None)
    yield {"name": "load_preview_flood_completed",
           "value": figures["load_preview_flood_completed"], "unit": "1/0",
           "state": figures["load_preview_flood_state"],
           "message": figures["load_preview_flood_message"],
           "outcome": figures["load_preview_flood_outcome"],
           "keepalive_gap_s": figures["load_preview_flood_max_keepalive_gap_s"],
           "watchdog_trips": figures["load_preview_flood_watchdog_trips"]}
    yield {"name": "load_preview_flood_estop_s",
           "value": round(figures["load_preview_flood_estop_s"], 4), "unit": "s",
           "presses_s": figures["load_preview_flood_estop_all_s"],
           "without_flood_s": figures["load_preview_flood_estop_quiet_s"],
           "flood_answers": figures["load_preview_flood_answers"]}


def _load_passes(device_priority: int) -> Iterator[dict[str, Any]]:
    repeats = int(os.environ.get("BENCH_LOAD_REPEATS", "1"))
    figures = run_load_scenario(repeats=repeats, cli_campaign=EXAMPLE_CAMPAIGN,
                                device_priority=device_priority or None)
    for name, unit in UNITS.items():
        yield {"name": name, "value": figures[name], "unit": unit,
               "campaigns": repeats, "device_priority": device_priority or None,
               "state": figures["load_state"],
               "rows": figures["load_rows"]}
    yield {"name": "load_cli_campaign_completed",
           "value": figures.get("load_cli_campaign_completed"), "unit": "1/0",
           "exit": figures.get("load_cli_campaign_exit"),
           "reason": figures.get("load_cli_campaign_reason")}
    outcomes = figures["load_outcomes"]
    yield {"name": "load_outcomes_ok", "value": outcomes.count("ok"), "unit": f"of {repeats}",
           "outcomes": outcomes}
    if repeats > 1:
        yield {"name": "load_completed_runs", "value": figures["load_completed_in_a_row"],
               "unit": f"of {repeats} in a row"}
    if os.environ.get("BENCH_LOAD_RT", "1") != "0":
        figures = run_load_scenario(realtime_priority=RT_PRIORITY)
        for name, unit in UNITS.items():
            yield {"name": name.replace("load_", "load_rt_", 1), "value": figures[name],
                   "unit": unit, "priority": RT_PRIORITY, "state": figures["load_state"]}
