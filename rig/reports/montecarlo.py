"""The ``rig montecarlo`` report (rig-montecarlo/1): seed 003's three methods on the paper's
3-stage planetary train, the sensitivity ranking and the dominant spectral line (arcsec)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from analysis.models.seed003_montecarlo import (
    PAPER_FIGURES_ARCSEC,
    max_deviation,
    max_deviation_random_phase,
    monte_carlo,
    sensitivity_ranking,
    spectrum,
)
from analysis.models.seed003_planetary import PaperReading, paper_train

FORMAT = "rig-montecarlo/1"

Tracker = Callable[[str, int], Callable[[int], None] | None]
"""``tracker(label, total)``: a callback of the work done so far (of ``total``) for the step
``label``, or None (no progress shown)."""


def montecarlo_report(
    samples: int,
    seed: int,
    reading: PaperReading,
    tracker: Tracker | None = None,
    window_revs: float = 1.0,
) -> dict[str, Any]:
    """Compute the report (the JSON document) for the paper's example; ``window_revs``:
    output revolutions searched for the maximum."""
    train = paper_train(reading)

    def track(label: str, total: int) -> Callable[[int], None] | None:
        return None if tracker is None else tracker(label, total)

    mc = monte_carlo(train, samples, seed, track("Monte Carlo", samples), window_revs)
    random_phase = max_deviation_random_phase(
        train, samples, seed + 1, track("max deviation, random phases", samples), window_revs
    )
    step = track("max deviation, common phase", 1)
    common = max_deviation(train, window_revs=window_revs)
    if step:
        step(1)
    step = track("sensitivity ranking", 1)
    ranking = sensitivity_ranking(train, seed=seed + 2)
    if step:
        step(1)
    step = track("spectrum", 1)
    lines = spectrum(train, seed=seed + 3)
    if step:
        step(1)
    top = sorted(
        range(lines.amplitude_arcsec.size), key=lambda k: -lines.amplitude_arcsec[k]
    )[:10]
    return {
        "format": FORMAT,
        "model": "seed 003: three 2K-H stages in series (Table 2), max |dtheta| in arcsec",
        "window_output_revs": window_revs,
        "reading": {
            "table1_signs": reading.table1_signs,
            "planet_speed": reading.planet_speed,
            "stage3_planet_row": reading.stage3_planet_row,
        },
        "samples": samples,
        "seed": seed,
        "monte_carlo": mc.as_dict(),
        "max_deviation": common.as_dict(),
        "max_deviation_random_phase": random_phase.as_dict(),
        "paper": PAPER_FIGURES_ARCSEC,
        "sensitivity_ranking": [item.as_dict() for item in ranking],
        "spectrum": {
            "dominant_frequency_per_rev": lines.dominant_frequency_per_rev,
            "dominant_amplitude_arcsec": lines.dominant_amplitude_arcsec,
            "dominant_sources": list(lines.dominant_sources),
            "lines": [
                {
                    "frequency_per_rev": float(lines.frequency_per_rev[k]),
                    "amplitude_arcsec": float(lines.amplitude_arcsec[k]),
                }
                for k in top
            ],
        },
    }


