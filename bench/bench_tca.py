"""Seed 001 TCA speed: wall time per mesh cycle of the beveloid pair's transmission error
(eq. 11 by the contact equations 7 and 10), for the parallel-axis line contact and for the
paper's combined installation errors, at 12 points per cycle (37 tooth-pair solves).

``cpu_s`` and the load average before the run tell a slow machine from a slow program."""

from __future__ import annotations

from collections.abc import Iterator

from analysis.models.seed001_beveloid import PAPER_CASES, paper_pair, transmission_error
from bench.timing import timed

POINTS_PER_CYCLE = 12


def run() -> Iterator[dict]:
    pair = paper_pair()
    for name in ("standard", "combined"):
        t = timed(lambda name=name: transmission_error(pair, PAPER_CASES[name], POINTS_PER_CYCLE))
        te = t.result
        yield {
            "name": f"seed001_tca_{name}_per_mesh_cycle",
            **t.fields(),
            "points_per_cycle": POINTS_PER_CYCLE,
            "te_peak_to_peak_arcsec": round(te.peak_to_peak_arcsec, 3),
        }
