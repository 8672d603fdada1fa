"""A batch of units drawn within their tolerances, for the kinds other than the seed 000 pair
(analysis.models.cycloid_batch, analysis.models.beveloid_batch): per unit the lost motion at
its worst position and its smallest play (arcmin)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class KindBatch:
    """Per sampled unit (arcmin): lost motion at its worst position and the smallest play over
    the positions (negative: the unit binds there)."""

    worst_arcmin: np.ndarray
    least_play_arcmin: np.ndarray
    rated_torque_Nm: float
    lost_motion_pct: float
    samples: int

    def band_arcmin(self, coverage: float = 0.95) -> tuple[float, float]:
        """The central ``coverage`` of the batch's worst-position lost motion (arcmin)."""
        tail = 50.0 * (1.0 - coverage)
        low, high = np.percentile(self.worst_arcmin, [tail, 100.0 - tail])
        return float(low), float(high)

    @property
    def interference_fraction(self) -> float:
        """Share of the units that bind somewhere (smallest play below zero)."""
        return float(np.mean(self.least_play_arcmin < 0.0))
