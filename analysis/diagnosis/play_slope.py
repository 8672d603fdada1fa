"""Torque carried inside the free play: a load path in parallel with the gear.

Inside the free play (the flat middle of seed 000 Fig. 6's loop) no gear effect carries
torque: the unit is off both flanks, and the torque channel reads only the torque zero and
the friction of what moves (one level per direction of motion, any level within the static
band while the output stands). A spring beside the gear (a seal, a cable carrier, a fixture
bearing preloaded on the output) adds ``k_p (theta - theta_0)`` to the reading there: the
flat middle of the loop tilts. No effect of the vocabulary tilts it, so a slope there is a
gap the model lacks (issue 31 item 4).

The statistic is read from the raw samples, model-free. Per run, the centre of the play is
between the two loaded branches brought to zero torque along the model's stiffness (a loop
with a spring in it has no flat part to measure a lost motion on). The moving samples in the
central part of the play are regressed on ``torque = c_(run, direction) + k_p * twist`` (a
level per run and direction of motion: the friction and the zero), robustly (Huber, scale
from the median absolute deviation), once for each half of the crossings: behind the centre
(leaving the flank just left) and past it (towards the flank ahead). A spring tilts both
halves alike; a crossing's dynamics (the drive's torque still rising while the output flies
across, a friction's rise after a start) tilt one half only. The finding rests on the weaker
half (:class:`PlayTilt`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: Half-width of the central part of the play read, as a share of the play: the flanks'
#: first contact (a bearing's soft stage, a Hertzian start) stays outside it.
CORE_HALF_WIDTH = 0.3
#: The branches that place the play's centre: |torque| in this share of the amplitude.
BRANCH_BAND = (0.2, 0.5)
#: Huber's constant (residuals in robust standard deviations).
HUBER_C = 1.5


@dataclass(frozen=True)
class PlaySlope:
    """The slope of torque on twist inside the play, pooled over the runs.

    ``slope_Nm_per_arcmin`` with its standard error; ``samples`` read inside the play's
    central part over ``runs`` runs; ``coverage`` the largest share of that part one run's
    samples span (a slope needs the samples spread across the play)."""

    slope_Nm_per_arcmin: float
    se_Nm_per_arcmin: float
    samples: int
    runs: int
    coverage: float

    @property
    def z(self) -> float:
        return abs(self.slope_Nm_per_arcmin) / self.se_Nm_per_arcmin \
            if self.se_Nm_per_arcmin > 0 else math.inf

    def to_dict(self) -> dict[str, float | int]:
        return {"slope_Nm_per_arcmin": self.slope_Nm_per_arcmin,
                "se_Nm_per_arcmin": self.se_Nm_per_arcmin, "samples": self.samples,
                "runs": self.runs, "coverage": self.coverage}


def play_core(torque_Nm: np.ndarray, twist_arcmin: np.ndarray, stiffness_Nm_per_arcmin: float
              ) -> tuple[float, float] | None:
    """(centre, half-width) of the central part of the play (arcmin), or None when a branch
    is missing. Each flank's twist at zero torque is its branch's median twist at |torque|
    within :data:`BRANCH_BAND` of the amplitude, brought to zero torque along seed 004
    eq. (8)'s stiffness; the play is the distance between the two (a runout or a
    temperature changes it from run to run)."""
    if not (math.isfinite(stiffness_Nm_per_arcmin) and stiffness_Nm_per_arcmin > 0):
        return None
    amp = float(np.percentile(np.abs(torque_Nm), 99.5))
    lo, hi = BRANCH_BAND[0] * amp, BRANCH_BAND[1] * amp
    pos = (torque_Nm >= lo) & (torque_Nm <= hi)
    neg = (torque_Nm <= -lo) & (torque_Nm >= -hi)
    if pos.sum() < 5 or neg.sum() < 5:
        return None
    k = stiffness_Nm_per_arcmin
    upper = float(np.median(twist_arcmin[pos])) - float(np.median(torque_Nm[pos])) / k
    lower = float(np.median(twist_arcmin[neg])) - float(np.median(torque_Nm[neg])) / k
    if not upper > lower:
        return None
    return 0.5 * (upper + lower), CORE_HALF_WIDTH * (upper - lower)


def _directions(twist: np.ndarray, sigma_arcmin: float) -> np.ndarray:
    """+1 / -1 moving, 0 standing: the sign of the central difference when it exceeds three
    times its noise."""
    d = np.zeros(twist.size)
    if twist.size >= 3:
        d[1:-1] = twist[2:] - twist[:-2]
    band = 3.0 * math.sqrt(2.0) * max(sigma_arcmin, 1e-9)
    return np.where(d > band, 1.0, np.where(d < -band, -1.0, 0.0))


def play_slope(runs: Sequence[tuple[np.ndarray, np.ndarray, float, float]],
               min_samples: int = 20, side: int = 1) -> PlaySlope | None:
    """The pooled slope of torque on twist inside the play (N*m/arcmin) over ``runs`` of
    (torque N*m, twist arcmin, seed 004 eq. (8) stiffness N*m/arcmin, twist noise arcmin), on
    the moving samples of one half of the crossings (``side`` +1: past the centre, -1:
    before it); None when fewer than ``min_samples`` samples are read."""
    cols_t, cols_y, groups, cover = [], [], [], []
    for i, (torque, twist, stiffness, sigma) in enumerate(runs):
        torque = np.asarray(torque, dtype=float)
        twist = np.asarray(twist, dtype=float)
        core = play_core(torque, twist, stiffness)
        if core is None:
            continue
        centre, half = core
        dirs = _directions(twist, sigma)
        x_all = twist - centre
        # moving, on one side of the centre: side +1 past it (towards the flank ahead), -1
        # before it (leaving the flank behind)
        inside = (np.abs(x_all) < half) & (side * dirs * x_all > 0)
        if inside.sum() < 3:
            continue
        x = twist[inside] - centre
        cover.append(float(np.ptp(x)) / (2.0 * half))
        cols_t.append(torque[inside])
        cols_y.append(x)
        groups.append(3 * i + 1 + dirs[inside].astype(int))
    if not cols_t or sum(c.size for c in cols_t) < min_samples:
        return None
    y = np.concatenate(cols_t)
    x = np.concatenate(cols_y)
    g = np.concatenate(groups)
    _, gi = np.unique(g, return_inverse=True)
    X = np.column_stack([x, np.eye(int(gi.max()) + 1)[gi]])
    w = np.ones(y.size)
    beta = np.zeros(X.shape[1])
    scale = 1.0
    for _ in range(6):
        sw = np.sqrt(w)
        beta, *_ = np.linalg.lstsq(X * sw[:, None], y * sw, rcond=None)
        r = y - X @ beta
        scale = max(1.4826 * float(np.median(np.abs(r - np.median(r)))), 1e-9)
        w = np.minimum(1.0, HUBER_C / np.maximum(np.abs(r) / scale, 1e-12))
    A = (X * w[:, None]).T @ X
    dof = max(y.size - X.shape[1], 1)
    try:
        cov = np.linalg.inv(A) * scale**2 * y.size / dof
        se = math.sqrt(max(float(cov[0, 0]), 0.0))
    except np.linalg.LinAlgError:
        se = math.inf
    return PlaySlope(float(beta[0]), se, int(y.size), len(cols_t), max(cover))


@dataclass(frozen=True)
class PlayTilt:
    """The slope inside the play on each half of the crossings: ``behind`` the centre
    (leaving a flank) and ``ahead`` of it (towards the other)."""

    behind: PlaySlope | None
    ahead: PlaySlope | None

    def weaker(self) -> PlaySlope | None:
        """The half with the smaller slope (None when a half has too few samples): a spring
        tilts both."""
        if self.behind is None or self.ahead is None:
            return None
        return min((self.behind, self.ahead), key=lambda h: h.slope_Nm_per_arcmin)

    def to_dict(self) -> dict[str, object]:
        weak = self.weaker()
        return {**(weak.to_dict() if weak is not None else {"slope_Nm_per_arcmin": None}),
                "behind": None if self.behind is None else self.behind.to_dict(),
                "ahead": None if self.ahead is None else self.ahead.to_dict()}


def play_slope_of(prepared: Sequence[object]) -> PlayTilt | None:
    """:class:`PlayTilt` of prepared runs (analysis.diagnosis.data.PreparedRun): their raw
    samples, their unit's nominal stiffness and their twist noise."""
    runs = []
    for p in prepared:
        raw, nominal = getattr(p, "raw", None), getattr(p, "nominal", None)
        if raw is None or nominal is None:
            continue
        runs.append((raw.torque_Nm, raw.twist_arcmin, float(nominal.stiffness_Nm_per_arcmin),
                     float(getattr(p, "raw_sigma_arcmin", 0.0))))
    if not runs:
        return None
    return PlayTilt(play_slope(runs, side=-1), play_slope(runs, side=1))
