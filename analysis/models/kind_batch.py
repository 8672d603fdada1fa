"""A batch of units drawn within their tolerances, for the kinds other than the seed 000 pair
(analysis.models.cycloid_batch, analysis.models.beveloid_batch): per unit the lost motion at
its worst position and its smallest play (arcmin), and where the kind's batch gives it, the
lost motion at one random position."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


def _central(values: np.ndarray, coverage: float) -> tuple[float, float]:
    tail = 50.0 * (1.0 - coverage)
    low, high = np.percentile(values, [tail, 100.0 - tail])
    return float(low), float(high)


@dataclass(frozen=True)
class KindBatch:
    """Per sampled unit (arcmin): lost motion at its worst position and the smallest play over
    the positions (negative: the unit binds there); ``position_arcmin`` (None: not drawn) the
    lost motion at one random position (crank angle, mesh phase, tooth pair)."""

    worst_arcmin: np.ndarray
    least_play_arcmin: np.ndarray
    rated_torque_Nm: float
    lost_motion_pct: float
    samples: int
    position_arcmin: np.ndarray | None = None

    def band_arcmin(self, coverage: float = 0.95) -> tuple[float, float]:
        """The central ``coverage`` of the batch's worst-position lost motion (arcmin)."""
        return _central(self.worst_arcmin, coverage)

    def position_band_arcmin(self, coverage: float = 0.95) -> tuple[float, float] | None:
        """The central ``coverage`` of the lost motion at one random position (arcmin), None
        where the kind's batch does not draw it."""
        if self.position_arcmin is None:
            return None
        return _central(self.position_arcmin, coverage)

    @property
    def interference_fraction(self) -> float:
        """Share of the units that bind somewhere (smallest play below zero)."""
        return float(np.mean(self.least_play_arcmin < 0.0))

    def advice(self, what: str, **settings: float) -> dict[str, Any]:
        """The advice this batch, drawn at the advised ``settings`` (mm), stands for: the
        settings, its 95 % band, the share of units that bind, and ``what`` was advised."""
        low, high = self.band_arcmin(0.95)
        return {**settings, "band_95_arcmin": [low, high],
                "binding_fraction": self.interference_fraction, "what": what}
