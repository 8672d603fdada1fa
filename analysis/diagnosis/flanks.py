"""Do the two flanks have the same loaded slope? A check outside the effect vocabulary.

The reference model (docs/run-format.md, seed 004 eq. 8) gives both flanks of the loop one
mesh stiffness K: ``twist = s * play / 2 + T / K``. No effect of the vocabulary makes the
slope depend on the flank: an offset shifts the loop, friction separates the branches, a
take-up or a stiffening is odd in the torque. A slope that differs with the flank (a torque
channel whose gain depends on the sign, flanks of different contact) is a real gap that no
candidate can close, so the verdict is ``unexplained``, never ``none``.

Calibrated against the repeats: each run gives its own pair of flank compliances, fitted on
its loaded points (clear of the play crossing); the relative difference is tested across the
runs with Student's t (the runs are independent measurements, so the within-run correlation
of the noise does not enter). It counts when it is beyond chance at the diagnosis level and
material: above the stiffness tolerance of seed 004 eq. (8) and, as twist at the campaign's
amplitude, above the noise floor the verdict ``none`` is judged against.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from analysis.diagnosis.fit import LinearFit, Stack, run_columns

LOADED_SHARE = 0.25
"""Points with a chain torque below this share of the run's amplitude are left out (the play
crossing, its impacts and the floating points)."""


@dataclass
class FlankAsymmetry:
    """Flank compliances across the runs: ``relative`` = (c_negative - c_positive) / mean c
    per run (mean and its t test), ``size_arcmin`` the twist the difference makes at the
    amplitude (half the difference of the two slopes times the amplitude)."""

    relative: float
    relative_se: float
    p_value: float
    runs: int
    size_arcmin: float
    stiffness_positive_Nm_per_arcmin: float
    stiffness_negative_Nm_per_arcmin: float

    def finding(self, alpha: float, tolerance: float, floor_arcmin: float,
                min_runs: int = 3) -> bool:
        """Beyond chance at ``alpha`` over at least ``min_runs`` runs, above ``tolerance``
        (relative) and ``floor_arcmin``."""
        return (self.runs >= min_runs and self.p_value <= alpha and abs(self.relative) > tolerance
                and self.size_arcmin > floor_arcmin)

    def to_dict(self) -> dict[str, Any]:
        return {"relative_compliance_difference": self.relative,
                "relative_se": self.relative_se, "p_value": self.p_value, "runs": self.runs,
                "size_arcsec": self.size_arcmin * 60.0,
                "stiffness_positive_Nm_per_arcmin": self.stiffness_positive_Nm_per_arcmin,
                "stiffness_negative_Nm_per_arcmin": self.stiffness_negative_Nm_per_arcmin}


def _run_flank_compliances(stack: Stack, i: int, nl: dict[str, float]
                           ) -> tuple[float, float] | None:
    """(c_positive, c_negative) arcmin/(N*m) of run ``i`` by least squares on its loaded
    points: ``twist = a * s / 2 + c_pos * tau [s > 0] - c_neg * tau [s < 0] + offset``."""
    run = stack.runs[i]
    X = run_columns(stack, run, ["backlash"], nl, [])
    s, st = np.sign(X[:, 0]), X[:, 1]
    tau = np.abs(st)
    loaded = tau >= LOADED_SHARE * max(run.amplitude_Nm, 1e-12)
    pos, neg = loaded & (s > 0), loaded & (s < 0)
    if pos.sum() < 4 or neg.sum() < 4:
        return None
    A = np.column_stack([s / 2.0, np.where(s > 0, st, 0.0), np.where(s < 0, st, 0.0),
                         np.ones(s.size)])[loaded]
    beta, *_ = np.linalg.lstsq(A, run.twist_arcmin[loaded], rcond=None)
    c_pos, c_neg = float(beta[1]), float(beta[2])
    if not (c_pos > 0 and c_neg > 0):
        return None
    return c_pos, c_neg


def flank_asymmetry(stack: Stack, base: LinearFit) -> FlankAsymmetry | None:
    """The flanks' slopes run by run (module docstring); None with fewer than 3 usable runs."""
    pairs = [p for i in range(stack.n_runs)
             if (p := _run_flank_compliances(stack, i, base.nl)) is not None]
    if len(pairs) < 3:
        return None
    c = np.array(pairs)
    mean_c = c.mean(axis=1)
    rel = (c[:, 1] - c[:, 0]) / mean_c
    n = rel.size
    m = float(rel.mean())
    se = float(rel.std(ddof=1) / math.sqrt(n))
    p = float(2.0 * stats.t.sf(abs(m) / se, n - 1)) if se > 0 else (0.0 if m else 1.0)
    amplitude = float(np.median([r.amplitude_Nm for r in stack.runs]))
    size = 0.5 * abs(float(np.mean(c[:, 1] - c[:, 0]))) * amplitude
    cp, cn = float(c[:, 0].mean()), float(c[:, 1].mean())
    return FlankAsymmetry(m, se, p, n, size, 1.0 / cp, 1.0 / cn)
