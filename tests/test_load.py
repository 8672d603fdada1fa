"""The load test of issue 12: a campaign started through the control page's API on the
simulated rig completes while 3 busy processes, a diagnosis process and 20 live-stream clients
run beside it and the page is asked for an earlier campaign's diagnosis.

The keepalive gap is measured by the simulated loading drive itself (the longest silence of
the master while enabled, ``RIG_SIM_STATS``), samples lost from the recorded rows against the
encoder period (bench/load_scenario.py). ``python -m bench load`` prints the same figures for
the full 4-position campaign.
"""

from __future__ import annotations

from pathlib import Path

from bench.load_scenario import acquisition_figures, run_load_scenario


def test_acquisition_figures_count_missing_periods_not_bursts():
    period = 0.004
    t = [i * period for i in range(101)]
    lost, jitter = acquisition_figures(t, period)
    assert lost == 0 and jitter < 1e-9
    gap = t[:40] + t[45:]  # five periods without a row
    lost, _ = acquisition_figures(gap, period)
    assert lost == 5
    burst = t[:40] + [t[41] + 1e-4 * k for k in range(2)] + t[42:]  # late, not lost
    assert acquisition_figures(burst, period)[0] == 0


def test_campaign_from_the_page_completes_under_load(tmp_path: Path):
    figures = run_load_scenario(tmp_path, positions=(0.0, 180.0), steps_per_quarter=2)
    assert figures["load_campaign_completed"] == 1, figures
    assert figures["load_diagnosis_http_status"] == 200, figures
    assert figures["load_watchdog_trips"] == 0, figures
    assert figures["load_max_keepalive_gap_s"] < figures["load_watchdog_s"] / 2, figures
    assert figures["load_samples_lost"] == 0, figures  # dropped between driver and store
    assert figures["load_rows"] > 1000, figures
