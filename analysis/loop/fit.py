"""Values read off one branch of a hysteresis loop, with their standard uncertainties.

Only interpolation, never extrapolation: a branch value at a torque is the intercept of a
straight line fitted by least squares to the branch samples inside a torque window around
(or on one side of) that torque, and the window must hold samples on both sides of it (to
within ``tol_Nm``). Its standard uncertainty combines

* the scatter of the twist about the local line (residual standard deviation, propagated
  to the intercept: ``s * sqrt(1/n + (T - mean T)^2 / Sxx)``, times ``sqrt(ν/(ν-2))`` for
  the ``ν = n - 2`` degrees of freedom of ``s``: the standard deviation of Student's t),
* the encoder resolution ``q / sqrt(12)`` (a quantisation error does not average out when
  the noise is smaller than a count, so it is added once, not divided by n),
* the torque resolution ``q_T / sqrt(12)`` times the local slope.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis.errors import MetricUnavailable
from analysis.loop.numeric import dot

#: Fewer degrees of freedom than this: the residual scatter is not trusted below the
#: run's global twist noise.
_MIN_DOF_TRUSTED = 10


@dataclass(frozen=True)
class PointEstimate:
    """A branch value: twist in arcmin at a torque, its standard uncertainty and sample count.

    ``slope`` is the local slope d(twist)/d(torque), arcmin/(N·m).
    """

    value: float
    uncertainty: float
    n: int
    slope: float


@dataclass(frozen=True)
class Resolution:
    """Measurement resolutions and the run's global twist noise, for the uncertainties."""

    twist_arcmin: float = 0.0
    torque_Nm: float = 0.0
    twist_noise_arcmin: float = 0.0


class BranchPass:
    """One pass of a branch (its sample slices) with running envelopes for fast windows.

    Along a loading slice the running maximum of the torque and the running minimum from
    the end are both non-decreasing, so the samples with torque in ``[lo, hi]`` lie in one
    index range found by binary search (the mirror image for an unloading slice): a window
    costs its own size, not the pass's.
    """

    def __init__(
        self,
        torque: np.ndarray,
        twist: np.ndarray,
        slices: list[slice],
        sign: int,
        shared_first: list[bool] | None = None,
    ):
        """``shared_first[k]``: slice k starts on a turning sample that the previous branch
        also holds; it counts for reaching a torque but is left out of the fits, so that
        the two branches of a cycle never share a sample (their errors stay independent)."""
        self.parts = []
        shared = shared_first or [False] * len(slices)
        for s, skip in zip(slices, shared, strict=True):
            x, y = torque[s], twist[s]
            z = x if sign > 0 else -x
            head_max = np.maximum.accumulate(z)
            tail_min = np.ascontiguousarray(np.minimum.accumulate(z[::-1])[::-1])
            self.parts.append((x, y, head_max, tail_min, bool(skip)))
        self.sign = sign

    def window(self, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray, float, float]:
        """Torque and twist of the samples to fit with torque in ``[lo, hi]`` N·m, and the
        lowest and highest torque the pass has in ``[lo, hi]`` (shared samples included)."""
        zlo, zhi = (lo, hi) if self.sign > 0 else (-hi, -lo)
        xs, ys = [], []
        low, high = np.inf, -np.inf
        for x, y, head_max, tail_min, skip in self.parts:
            i0 = int(np.searchsorted(head_max, zlo, side="left"))
            i1 = int(np.searchsorted(tail_min, zhi, side="right"))
            if i1 <= i0:
                continue
            xw = x[i0:i1]
            m = xw >= lo
            m &= xw <= hi
            if skip and i0 == 0 and m[0]:
                low, high = min(low, float(xw[0])), max(high, float(xw[0]))
                m[0] = False
            if m.any():
                xm = xw[m]
                low, high = min(low, float(xm.min())), max(high, float(xm.max()))
                xs.append(xm)
                ys.append(y[i0:i1][m])
        if not xs:
            return np.empty(0), np.empty(0), low, high
        return np.concatenate(xs), np.concatenate(ys), low, high


EXTRAPOLATE_SHARE = 0.1
"""A branch may be evaluated this share of its samples' torque span beyond them (the
linear fit's uncertainty at that distance is part of the value's)."""


def branch_value(
    branch: BranchPass,
    at_Nm: float,
    lo_Nm: float,
    hi_Nm: float,
    *,
    tol_Nm: float,
    resolution: Resolution,
    label: str,
    exclude_Nm: float = 0.0,
) -> PointEstimate:
    """Twist (arcmin) of one branch at torque ``at_Nm`` from the samples in ``[lo, hi]`` N·m.

    Raises :class:`~analysis.errors.MetricUnavailable` (naming ``label``) when the window
    does not bracket ``at_Nm`` or holds fewer than 3 samples. Samples closer than
    ``exclude_Nm`` to ``at_Nm`` bracket it but are left out of the fit: at a discontinuity
    (the flank change of a free play at zero torque) a reading within the torque noise of
    it may belong to the other side. They are kept when the rest spans less than half the
    window (a dwell at ``at_Nm`` measured the value there).
    """
    x, y, low, high = branch.window(lo_Nm, hi_Nm)
    where = f"{lo_Nm:+.4g}..{hi_Nm:+.4g} N·m"
    if not low <= high:
        raise MetricUnavailable(f"the {label} branch has no samples in {where}")
    # short of ``at_Nm`` by more than the tolerance: refused, unless the fit reaches it by a
    # short extrapolation (EXTRAPOLATE_SHARE of the torque span of its samples; the fitted
    # value's uncertainty grows with that distance): an unloading branch split where the
    # command turns starts on the sample after the dwell at the peak, whose torque has
    # already begun to fall (9.981 after a dwell at 10.000 N·m, seen under CPU load)
    short = max(low - at_Nm, at_Nm - high, 0.0)
    if short > tol_Nm and short > EXTRAPOLATE_SHARE * (high - low):
        raise MetricUnavailable(
            f"the {label} branch does not reach {at_Nm:+.4g} N·m "
            f"(its samples in {where} span {low:+.4g}..{high:+.4g} N·m)"
        )
    if exclude_Nm > 0:
        keep = np.abs(x - at_Nm) >= exclude_Nm
        # On a dwell at the torque itself the excluded samples are the measurement: keep
        # them when what remains has no torque spread to fit a line to.
        if np.count_nonzero(keep) >= 3 and np.ptp(x[keep]) >= 0.5 * (hi_Nm - lo_Nm - exclude_Nm):
            x, y = x[keep], y[keep]
    n = x.size
    if n < 3:
        raise MetricUnavailable(f"the {label} branch has only {n} usable samples in {where}")
    dx = x - at_Nm
    xm = float(dx.mean())
    ym = float(y.mean())
    dx -= xm
    dy = y - ym
    sxx = dot(dx, dx)
    span = hi_Nm - lo_Nm
    if sxx > n * (1e-9 * span) ** 2:
        slope = dot(dx, dy) / sxx
        dof = n - 2
        lever = 1.0 / n + xm * xm / sxx
    else:  # all samples at one torque (a noise-free dwell): the mean, no slope
        slope, dof, lever = 0.0, n - 1, 1.0 / n
    value = ym - slope * xm
    dy -= slope * dx
    s2 = dot(dy, dy) / dof if dof > 0 else 0.0
    if dof < _MIN_DOF_TRUSTED:
        s2 = max(s2, resolution.twist_noise_arcmin**2)
    elif dof > 2:
        s2 *= dof / (dof - 2.0)  # variance of Student's t: s is itself estimated
    u2 = s2 * lever
    u2 += resolution.twist_arcmin**2 / 12.0
    u2 += (slope * resolution.torque_Nm) ** 2 / 12.0
    return PointEstimate(value=value, uncertainty=float(np.sqrt(u2)), n=n, slope=slope)


def torque_at_twist(
    torque_Nm: np.ndarray, twist_arcmin: np.ndarray, slices: list[slice], at_arcmin: float
) -> tuple[float, float, int, float]:
    """Torque (N·m) where a branch path crosses the twist ``at_arcmin``.

    Linear interpolation between the two samples on either side of every crossing within
    each slice (a junction between slices is not a measured step and is not used). Returns the
    mean crossing torque, the standard deviation of the crossing torques (0 for a single
    crossing), the number of crossings and the mean torque step between the two samples
    of a crossing; raises MetricUnavailable if there is none.
    """
    found: list[np.ndarray] = []
    steps: list[np.ndarray] = []
    for s in slices:
        th = twist_arcmin[s] - at_arcmin
        tq = torque_Nm[s]
        a, b = th[:-1], th[1:]
        idx = np.flatnonzero((a <= 0) != (b <= 0))
        if idx.size:
            ta, tb = a[idx], b[idx]
            frac = ta / (ta - tb)
            step = tq[idx + 1] - tq[idx]
            found.append(tq[idx] + frac * step)
            steps.append(np.abs(step))
    if not found:
        raise MetricUnavailable(f"the branch never crosses the twist {at_arcmin:+.4g} arcmin")
    t = np.concatenate(found)
    spread = float(t.std(ddof=1)) if t.size > 1 else 0.0
    return float(t.mean()), spread, int(t.size), float(np.concatenate(steps).mean())
