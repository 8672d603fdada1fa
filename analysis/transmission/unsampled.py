"""What a stretch without samples may hide from a TE figure (issue 32: jitter and stalls).

Where the sampler stalled, the TE curve is the fitted orders (known everywhere) plus the
residual drawn straight across the stretch (:mod:`.evaluate`). The residual's content there
(pitch errors, unnamed orders) was not seen, so a peak of it may be missing, and every
extreme-value figure can only read low. How far the residual may stray at a point ``d`` deg
from the nearest sample is judged by the residual itself where it was sampled: the 95th
percentile of its range (max - min) over windows of ``d`` deg. The figures are then taken
again on the curve widened by that reach (up for the maxima, down for the minima); the
difference, ``excess``, is the most the stretch can have hidden. It is one-sided (a figure
reads low, never high), so an uncorrected figure carries ``excess / sqrt(3)`` in its budget:
the root mean square of an error spread evenly over ``[0, excess]``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import maximum_filter1d, minimum_filter1d

from analysis.transmission.evaluate import Evaluated, figures, high_pass, window_range

STALL_SPACINGS = 4.0
"""A step between neighbouring samples longer than this many median steps is a stretch
without samples."""
REACH_PERCENTILE = 95.0
REACH_LEVELS = 12
"""Distances from the nearest sample at which the reach is computed (log-spaced, then
interpolated)."""


def reach(theta: np.ndarray, r: np.ndarray, grid: np.ndarray) -> np.ndarray | None:
    """Per ``grid`` point (deg), how far (arcsec) the residual ``r`` (sampled at ``theta``
    deg) may stray from the straight line drawn across the stretch without samples the point
    lies in; 0 outside such stretches. None when the sampling has no such stretch."""
    if theta.size < 8:
        return None
    order = np.argsort(theta, kind="stable")
    t, y = theta[order], r[order]
    steps = np.diff(t)
    spacing = float(np.median(steps[steps > 0])) if np.any(steps > 0) else 0.0
    if spacing <= 0.0:
        return None
    wide = np.flatnonzero(steps > STALL_SPACINGS * spacing)
    if wide.size == 0:
        return None
    # the distance of each grid point from its nearest sample, inside the wide stretches only
    k = np.searchsorted(t, grid)
    lo = t[np.clip(k - 1, 0, t.size - 1)]
    hi = t[np.clip(k, 0, t.size - 1)]
    inside = np.isin(k - 1, wide) & (grid > lo) & (grid < hi)
    dist = np.where(inside, np.minimum(grid - lo, hi - grid), 0.0)
    if not np.any(dist > 0):
        return None
    # the residual on a uniform grid of the median step, its range over windows of d deg
    uniform = np.arange(t[0], t[-1], spacing)
    ru = np.interp(uniform, t, y)
    longest = float(dist.max())
    levels = np.geomspace(spacing, max(longest, spacing * 1.01), REACH_LEVELS)
    ranges = []
    for d in levels:
        w = max(2, min(int(round(d / spacing)) + 1, ru.size))
        spread = maximum_filter1d(ru, w, mode="nearest") - minimum_filter1d(ru, w,
                                                                          mode="nearest")
        ranges.append(float(np.percentile(spread, REACH_PERCENTILE)))
    return np.where(inside, np.interp(dist, levels, np.maximum.accumulate(ranges)), 0.0)


def excess(ev: Evaluated, output_teeth: int | None) -> dict[str, float]:
    """How much each figure of :func:`figures` of one direction's curve may read low because
    of its stretches without samples (module doc), per figure key. Empty when there is none."""
    if ev.residual_at is None:
        return {}
    values = ev.values
    grid = ev.start_deg + np.arange(values.size) * (360.0 / ev.n_eval)
    at = reach(ev.residual_at[0], ev.residual_at[1], grid)
    if at is None:
        return {}
    widened = at.reshape(values.shape)
    base = figures(values, output_teeth, ev.periodic)
    up, down = values + widened, values - widened
    out = {"pp": float(up.max() - down.min()) - float(base["pp"] or 0.0),
           "Fi": float(np.max(up.max(axis=1) - down.min(axis=1))) - float(base["Fi"] or 0.0)}
    if output_teeth:
        revs, n = values.shape
        width = int(round(n / float(output_teeth))) + 1
        out["fi"] = (window_range(up.reshape(-1), down.reshape(-1), width, ev.periodic)
                     - float(base["fi"]))
        hp = high_pass(values.reshape(-1), revs, output_teeth / 2.0)
        flat = widened.reshape(-1)
        out["fis"] = (window_range(hp + flat, hp - flat, width, ev.periodic)
                      - float(base["fis"]))
    return {key: max(0.0, v) for key, v in out.items()}


def u_of_excess(value: float) -> float:
    """The budget's term of a one-sided ``excess`` left uncorrected (module doc)."""
    return value / math.sqrt(3.0)
