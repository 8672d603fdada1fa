"""One direction's TE curve without the smoothing of output-angle bins (issue 32 item 1), its
gaps, and the figures of docs/transmission-error.md on it.

The curve is **the fitted orders plus the binned residual**: every named order (output, input,
mesh, the unit's own; :mod:`.orders`) is fitted jointly on the samples of the revolutions used
and evaluated exactly, at the input angle of each evaluation point; only what no order names
(pitch errors, unnamed content, noise) is averaged, in residual bins of ``360 / n_residual``
deg holding a few samples each, and interpolated linearly onto the evaluation grid. The grid
has ``n_eval`` points per output revolution, at least :data:`POINTS_PER_PERIOD` per period of
the highest kept order (the tooth mesh's first harmonic, twice the input order) and a whole
number per output tooth pitch, so that f'_i's window is exactly one pitch.

What the method still does to a figure is estimated by Richardson's rule: the figure is taken
again on a grid of half the points with residual bins twice as wide; both errors go as the
square of the step, so the finer figure's remaining bias is about ``|fine - coarse| / 3``, which
the uncertainty budget carries (``method``).

Gaps: rows of one direction whose output or input angle (or TE) is NaN are dropped and
counted. A run of such rows that leaves a hole in the output angle longer than the shortest
kept period is never bridged: the revolutions used are the most whole revolutions that fit
between the holes (the others are left out, with a note); with none, the run is refused naming
the rows (``AnalysisError``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import maximum_filter1d, minimum_filter1d

from analysis.errors import AnalysisError
from analysis.transmission.orders import OrderModel, is_whole

POINTS_PER_PERIOD = 32
"""Evaluation points per period of the highest kept order (the issue asks for 8 at least):
a sinusoid's peak is then missed by at most ``1 - cos(pi / 32)`` = 0.5 % of its amplitude."""
SAMPLES_PER_RESIDUAL_BIN = 10.0
"""Mean samples per residual bin, unless that would make a bin wider than
:data:`RESIDUAL_BINS_PER_PITCH`'s share of an output tooth pitch."""
RESIDUAL_BINS_PER_PITCH = 12
NOISE_DRAWS = 16
"""Draws of the parametric bootstrap of the noise's bias on the extreme-value figures."""
MIN_EVAL_POINTS = 3600
MAX_EVAL_POINTS = 2**17
RICHARDSON = 1.0
"""``fine - coarse = (2^2 - 1) x bias(fine)`` for an error that goes as the step squared."""
DIRECTIONS = {1: "forward", -1: "reverse"}
MAD_PER_SIGMA = 0.6744897501960817
"""The median of ``|x|`` for ``x`` normal with unit standard deviation (``Phi^-1(3/4)``)."""


@dataclass(frozen=True)
class Hole:
    """A run of rows without a finite angle that leaves a hole in the output angle."""

    first_row: int
    last_row: int
    lo_deg: float
    hi_deg: float

    @property
    def rows(self) -> int:
        return self.last_row - self.first_row + 1

    def text(self) -> str:
        return (f"rows {self.first_row + 2}-{self.last_row + 2} of samples.csv "
                f"({self.rows} rows without a finite angle) leave a hole of "
                f"{self.hi_deg - self.lo_deg:.2f} deg of output angle, "
                f"{self.lo_deg:.2f} .. {self.hi_deg:.2f} deg")


@dataclass
class GapReport:
    """What one direction's rows without a finite angle did: ``dropped`` rows in all, the
    ``holes`` longer than the shortest kept period, and notes."""

    dropped: int = 0
    holes: list[Hole] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def find_holes(rows: np.ndarray, output_deg: np.ndarray, valid: np.ndarray,
               longest_deg: float) -> tuple[int, list[Hole]]:
    """Runs of invalid rows (``valid`` False) among one direction's ``rows`` (row numbers of
    samples.csv, 0 = first data row) that span more than ``longest_deg`` of output angle
    between their valid neighbours. Invalid rows at either end only shorten the record."""
    dropped = int(np.count_nonzero(~valid))
    holes: list[Hole] = []
    if dropped == 0:
        return 0, holes
    v = valid.astype(np.int8)
    edges = np.diff(np.concatenate([[1], v, [1]]))
    starts = np.flatnonzero(edges == -1)
    ends = np.flatnonzero(edges == 1) - 1
    for a, b in zip(starts, ends, strict=True):
        if a == 0 or b == valid.size - 1:
            continue
        lo, hi = sorted((float(output_deg[a - 1]), float(output_deg[b + 1])))
        if hi - lo > longest_deg:
            holes.append(Hole(int(rows[a]), int(rows[b]), lo, hi))
    return dropped, holes


def revolutions_between_holes(theta: np.ndarray, holes: list[Hole], step_deg: float,
                              n_eval: int) -> tuple[float, int, list[str]]:
    """The start (deg, a multiple of ``step_deg``) and number of the whole output revolutions
    to use: the most that fit in one stretch of the record without a hole (centred in it)."""
    lo_all, hi_all = float(np.min(theta)), float(np.max(theta))
    cuts = sorted((h.lo_deg, h.hi_deg) for h in holes)
    stretches, at = [], lo_all
    for lo, hi in cuts:
        stretches.append((at, lo))
        at = max(at, hi)
    stretches.append((at, hi_all))
    best: tuple[int, float, float] | None = None
    for lo, hi in stretches:
        # grid cells touched by the stretch (a record of 360 deg less one sample spacing is
        # one revolution, as the bins of before counted it)
        first = math.floor(lo / step_deg)
        steps = math.floor(hi / step_deg) - first + 1
        revs = steps // n_eval
        if revs >= 1 and (best is None or (revs, hi - lo) > (best[0], best[2] - best[1])):
            best = (revs, lo, hi)
    notes: list[str] = []
    if best is None:
        return 0.0, 0, notes
    revs, lo, hi = best
    first = math.floor(lo / step_deg)
    steps = math.floor(hi / step_deg) - first + 1
    start = (first + (steps - revs * n_eval) // 2) * step_deg
    if holes:
        notes.append(f"revolutions used: output {start:.2f} .. {start + revs * 360.0:.2f} deg "
                     f"({revs}); the record's {lo_all:.2f} .. {hi_all:.2f} deg outside them is "
                     "left out")
    return start, revs, notes


def eval_points_per_rev(highest_order: float, output_teeth: int | None) -> int:
    """``n_eval``: at least :data:`POINTS_PER_PERIOD` per period of ``highest_order`` (per
    output revolution) and :data:`MIN_EVAL_POINTS`, a multiple of ``2 z`` (the half grid of
    Richardson's estimate keeps a whole number of points per pitch) and of 360."""
    want = max(MIN_EVAL_POINTS, POINTS_PER_PERIOD * abs(highest_order))
    unit = math.lcm(360, 2 * int(output_teeth)) if output_teeth else 720
    n = int(math.ceil(want / unit) * unit)
    while n > MAX_EVAL_POINTS and n - unit >= MIN_EVAL_POINTS:
        n -= unit
    return n


@dataclass(frozen=True)
class Evaluated:
    """One direction evaluated on the grid: the values of every whole revolution used
    (``values``: revolutions x ``n_eval``, uncentred, in the order of the output angle from
    ``start_deg``; ``coarse`` the same on the half grid), the residual's spread and bins."""

    values: np.ndarray
    coarse: np.ndarray
    start_deg: float
    revolutions: int
    n_eval: int
    n_residual: int
    residual_std_arcsec: float
    samples_per_bin: float
    n_samples: int
    empty_bins: int
    longest_empty_deg: float
    noise_at: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    """The residual bins' angles, their means' standard deviations, and the grid."""
    noise_at_coarse: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    residual_at: tuple[np.ndarray, np.ndarray] | None = None
    """The samples' output angles (deg) and their residual from the fitted orders (arcsec)."""
    periodic: bool = False
    """Every named order is whole per output revolution: the TE repeats every output
    revolution and the tooth windows wrap round the record (:func:`figures`)."""

    def folded(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The grid of one revolution (deg, ``0 .. 360 - step``) and ``values`` (revolutions x
        points) averaged over the revolutions, column ``j`` at ``j * 360 / n`` deg."""
        n = values.shape[1]
        shift = int(round(self.start_deg / (360.0 / n))) % n
        return np.arange(n) * (360.0 / n), np.roll(values.mean(axis=0), shift)


def _residual_bins(theta: np.ndarray, r: np.ndarray, start: float, width_deg: float, n: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    idx = np.floor((theta - start) / width_deg).astype(np.int64)
    keep = (idx >= 0) & (idx < n)
    idx, th, rr = idx[keep], theta[keep], r[keep]
    counts = np.bincount(idx, minlength=n).astype(float)
    sum_r = np.bincount(idx, weights=rr, minlength=n)
    sum_t = np.bincount(idx, weights=th, minlength=n)
    filled = counts > 0
    mean_r = np.zeros(n)
    mean_r[filled] = sum_r[filled] / counts[filled]
    mean_t = start + (np.arange(n) + 0.5) * width_deg
    mean_t[filled] = sum_t[filled] / counts[filled]
    # The noise of one sample, two ways that white noise makes equal but the signal inflates
    # differently: from the samples (inflated by a pattern that alternates from sample to
    # sample and averages out within a bin, such as a quantisation at a count and a half per
    # sample), and from the bins' means as the noise of a mean of the bin's count (inflated by
    # content between the bins that the samples resolve). The smaller is kept.
    per_bin = float(counts[filled].mean()) if filled.any() else 1.0
    of_means = noise_std(mean_t[filled], mean_r[filled]) * math.sqrt(per_bin)
    return mean_t, mean_r, counts, min(noise_std(th, rr), of_means)


def noise_std(theta: np.ndarray, r: np.ndarray) -> float:
    """The white noise's standard deviation (arcsec) in ``r`` sampled at ``theta`` (deg), by
    the pseudo-residuals of Gasser, Sroka and Jennen-Steinmetz (Biometrika 73, 1986): each
    sample against the straight line through its two neighbours in angle, scaled so that noise
    of ``sigma`` gives ``sigma``. A smooth curve (an order the fit does not name, a pitch
    error's hand-over across a tooth) cancels to second order in the sample spacing, where
    the scatter about a bin's mean counted its slope across the bin as noise too."""
    if r.size < 3:
        return 0.0
    order = np.argsort(theta, kind="stable")
    t, y = theta[order], r[order]
    span = t[2:] - t[:-2]
    ok = span > 0
    a = np.where(ok, (t[2:] - t[1:-1]) / np.where(ok, span, 1.0), 0.5)
    b = 1.0 - a
    e = a * y[:-2] + b * y[2:] - y[1:-1]
    c = 1.0 / np.sqrt(a**2 + b**2 + 1.0)
    return float(np.median(np.abs(c * e)) / MAD_PER_SIGMA)


def evaluate(theta: np.ndarray, inp: np.ndarray, te: np.ndarray, model: OrderModel,
             start_deg: float, revolutions: int, n_eval: int,
             output_teeth: int | None = None) -> Evaluated:
    """The curve of one direction (module doc) on ``revolutions`` whole output revolutions
    from ``start_deg``: fitted orders at the grid plus the binned residual, and the same on
    the half grid (for Richardson's estimate of the method's bias)."""
    hi = start_deg + revolutions * 360.0
    m = (theta >= start_deg) & (theta < hi)
    th, ip, y = theta[m], inp[m], te[m]
    if th.size < 4:
        raise AnalysisError("too few samples in the revolutions used")
    r = y - model.evaluate(th, ip)
    per_rev = th.size / revolutions
    least = RESIDUAL_BINS_PER_PITCH * output_teeth if output_teeth else 360
    n_res = int(min(n_eval, max(360, least, per_rev / SAMPLES_PER_RESIDUAL_BIN)))
    step = 360.0 / n_eval
    grid = start_deg + np.arange(revolutions * n_eval) * step
    order = np.argsort(th, kind="stable")
    inp_grid = np.interp(grid, th[order], ip[order])
    fitted = model.evaluate(grid, inp_grid)
    out = []
    info = None
    noise = []
    for n_r, sub in ((n_res, slice(None)), (max(n_res // 2, 180), slice(None, None, 2))):
        mean_t, mean_r, counts, std = _residual_bins(th, r, start_deg, 360.0 / n_r,
                                                     revolutions * n_r)
        filled = counts > 0
        if filled.sum() < 2:
            raise AnalysisError("too few samples for the residual bins")
        resid_grid = np.interp(grid[sub], mean_t[filled], mean_r[filled])
        out.append(fitted[sub] + resid_grid)
        noise.append((mean_t[filled], std / np.sqrt(counts[filled]), grid[sub]))
        if info is None:
            empty = ~filled
            longest = 0
            if empty.any():
                e = np.diff(np.concatenate([[0], empty.astype(np.int8), [0]]))
                longest = int(np.max(np.flatnonzero(e == -1) - np.flatnonzero(e == 1)))
            info = (n_r, std, float(counts[filled].mean()), int(empty.sum()),
                    longest * 360.0 / n_r)
    assert info is not None
    n_r, std, spb, n_empty, longest_deg = info
    fine = out[0].reshape(revolutions, n_eval)
    coarse = out[1].reshape(revolutions, n_eval // 2)
    return Evaluated(values=fine, coarse=coarse, start_deg=start_deg, revolutions=revolutions,
                     n_eval=n_eval, n_residual=n_r, residual_std_arcsec=std,
                     samples_per_bin=spb, n_samples=int(th.size), empty_bins=n_empty,
                     longest_empty_deg=longest_deg, noise_at=noise[0],
                     noise_at_coarse=noise[1], residual_at=(th, r),
                     periodic=all(is_whole(o.frequency) for o in model.orders))


def sliding_range(seq: np.ndarray, width: int, periodic: bool = False) -> float:
    """Largest ``max - min`` over any ``width`` consecutive points of ``seq``. ``periodic``
    (whole output revolutions of a TE that repeats every output revolution): the windows
    wrap from the record's end to its start, which is the same angle of the unit; else only
    the windows inside the record. On a record of one revolution the unwrapped windows never
    read the teeth across the revolution's cut: f'_i read 7-12 % low on the simulated rig
    (258-279 arcsec against 299) when the worst tooth lay there."""
    return window_range(seq, seq, width, periodic)


def window_range(upper: np.ndarray, lower: np.ndarray, width: int,
                 periodic: bool = False) -> float:
    """Largest ``max(upper) - min(lower)`` over any ``width`` consecutive points, the windows
    wrapping or not as in :func:`sliding_range` (which is ``upper = lower``)."""
    width = max(2, min(int(width), upper.size))
    mode = "wrap" if periodic else "nearest"
    hi = maximum_filter1d(upper, size=width, mode=mode)
    lo = minimum_filter1d(lower, size=width, mode=mode)
    return float(np.max(hi - lo))


def high_pass(seq: np.ndarray, revolutions: int, below_order: float) -> np.ndarray:
    """``seq`` (whole output revolutions, uniform in the output angle) without the orders
    below ``below_order`` per output revolution (the long-term component of ISO 1328-1 f_is):
    the straight line through its two ends is taken away (so the record's ends meet and a
    non-whole order does not leak), then every Fourier order ``k / revolutions < below_order``
    is set to zero."""
    n = seq.size
    line = seq[0] + (seq[-1] - seq[0]) * np.arange(n) / max(n - 1, 1)
    spec = np.fft.rfft(seq - line)
    k = np.arange(spec.size) / float(revolutions)
    spec[k < below_order] = 0.0
    return np.fft.irfft(spec, n)


def figures(values: np.ndarray, output_teeth: int | None, periodic: bool = False
            ) -> dict[str, float | None]:
    """The figures of one direction's whole revolutions (``values``: revolutions x points,
    centred or not), docs/transmission-error.md:

    - ``pp``: GB/T 35089 transmission accuracy, max - min over every revolution;
    - ``Fi``: ISO 1328-1:2013 F_is of this flank, max - min within one revolution, the worst;
    - ``fi``: the project's f'_i, the largest max - min within any window of exactly one output
      tooth pitch (``n / z`` steps, ``n / z + 1`` points) along the record;
    - ``fis``: ISO 1328-1:2013 f_is, the same after the long-term component (orders below
      ``z / 2`` per output revolution) is removed.

    ``periodic``: the TE repeats every output revolution (every named order whole per output
    revolution), so f'_i's and f_is's windows wrap round the record (:func:`sliding_range`).
    """
    revs, n = values.shape
    seq = values.reshape(-1)
    out: dict[str, float | None] = {"pp": float(np.ptp(seq)),
                                    "Fi": float(np.max(np.ptp(values, axis=1)))}
    if output_teeth:
        width = int(round(n / float(output_teeth))) + 1
        out["fi"] = sliding_range(seq, width, periodic)
        out["fis"] = sliding_range(high_pass(seq, revs, output_teeth / 2.0), width, periodic)
    else:
        out["fi"] = out["fis"] = None
    return out


NOISE_BIAS_SCALE = 1.0 / (math.sqrt(2.0) - 1.0)
"""A draw adds noise of the bins' own size to a curve that already has it: an extreme's bias
grows as the noise, ``sigma sqrt(2)`` against ``sigma``, so the curve's own bias is
``delta / (sqrt(2) - 1)`` of the draws' mean change ``delta``."""


def noise_bias(values: np.ndarray, noise_at: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
               output_teeth: int | None, draws: int = NOISE_DRAWS, seed: int = 0,
               periodic: bool = False) -> tuple[dict[str, float], dict[str, float]]:
    """The bias of each extreme-value figure of ``values`` (max - min picks the noise's
    extremes too) and its spread, by a parametric bootstrap: the residual bins' noise (their
    means' standard deviation, ``noise_at``) drawn ``draws`` times onto the curve. Returns
    ``(bias, u)`` per figure key (:func:`figures`)."""
    if noise_at is None:
        return {}, {}
    at, sd, grid = noise_at
    if not np.any(sd > 0):
        return {}, {}
    base = figures(values, output_teeth, periodic)
    rng = np.random.default_rng(seed)
    got: dict[str, list[float]] = {k: [] for k, v in base.items() if v is not None}
    for _ in range(draws):
        eps = np.interp(grid, at, rng.normal(0.0, 1.0, sd.size) * sd)
        f = figures(values + eps.reshape(values.shape), output_teeth, periodic)
        for k in got:
            got[k].append(float(f[k] or 0.0))
    bias = {k: NOISE_BIAS_SCALE * (float(np.mean(v)) - float(base[k] or 0.0))
            for k, v in got.items()}
    spread = {k: float(np.std(v, ddof=1)) / math.sqrt(2.0) for k, v in got.items()}
    return bias, spread
