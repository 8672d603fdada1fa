"""Split a torque record into loading and unloading branches, and group them into cycles.

A branch is a stretch of samples between two torque reversals. A reversal counts only when
the torque has come back from its last extremum by more than a threshold (a Schmitt trigger
on the torque, the "zig-zag" rule), so noise, dwell plateaus (dT/dt ~ 0 for a while) and
slow ramps never split a branch: a plateau belongs to the branch it continues. The sample at
a turning point ends one branch and starts the next (it is on both).

The scan is vectorised per block with running maxima/minima (``np.maximum.accumulate``); its
Python loop runs once per block and once per reversal, never once per sample.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from analysis.errors import AnalysisError

#: Default reversal threshold, in multiples of the torque noise (standard deviation).
NOISE_MULTIPLE = 8.0
#: Default floor of the reversal threshold, as a fraction of the torque amplitude
#: (half the peak-to-peak torque): reversals smaller than this are not hysteresis cycles.
AMPLITUDE_FRACTION = 0.05

#: A peak held for at least this many samples is a dwell (it joins the branch that reached it).
MIN_DWELL_SAMPLES = 5

_FIRST_BLOCK = 1024
_MAX_BLOCK = 1 << 16


@dataclass(frozen=True, eq=False)
class Branches:
    """Branches of a run: contiguous segments ``[starts[k], stops[k])`` of the samples.

    ``direction[k]`` is +1 for a loading segment (torque increasing) and -1 for an unloading
    one. ``cycle[k]`` is the cycle the segment belongs to (-1: left out, e.g. an unpaired
    partial branch). A cycle is one loading pass plus one unloading pass; a pass is one
    segment, or, for a run that ends where it began (the GB/T 0 -> +T -> -T -> 0 sequence),
    the last segment followed by the first (the loop closes through the start of the run).
    ``passes[c]`` lists the segment numbers of cycle ``c`` as ``(loading, unloading)``,
    each a tuple of segment numbers in path order.
    """

    starts: np.ndarray
    stops: np.ndarray
    direction: np.ndarray
    cycle: np.ndarray
    turning_points: np.ndarray
    threshold_Nm: float
    n_samples: int
    passes: tuple[tuple[tuple[int, ...], tuple[int, ...]], ...] = field(default=())

    @property
    def n_cycles(self) -> int:
        """Number of complete cycles (paired loading and unloading passes)."""
        return len(self.passes)

    def slices(self, segments: tuple[int, ...]) -> list[slice]:
        """The sample slices of the given segment numbers, in the order given."""
        return [slice(int(self.starts[k]), int(self.stops[k])) for k in segments]

    def sample_direction(self) -> np.ndarray:
        """Per sample: +1 loading, -1 unloading (a turning sample takes the later branch)."""
        out = np.empty(self.n_samples, dtype=np.int8)
        for k in range(len(self.starts)):
            out[self.starts[k] : self.stops[k]] = self.direction[k]
        return out

    def loading_mask(self) -> np.ndarray:
        """Boolean mask of the samples on loading branches."""
        return self.sample_direction() > 0

    def unloading_mask(self) -> np.ndarray:
        """Boolean mask of the samples on unloading branches."""
        return self.sample_direction() < 0


#: The noise estimate reads at most this many second differences (evenly strided).
_NOISE_SAMPLES = 200_000


def white_noise_std(signal: np.ndarray) -> float:
    """Robust standard deviation of the white noise on a signal (same unit as the signal).

    From the median absolute second difference: for white noise of standard deviation s,
    ``x[i+1] - 2 x[i] + x[i-1]`` has standard deviation ``sqrt(6) s``; ramps give zero and the
    few kinks and steps are outliers the median ignores. Long records are read at an even
    stride (at most 200,000 second differences).
    """
    x = np.asarray(signal, dtype=float)
    if x.size < 3:
        return 0.0
    k = max(1, (x.size - 2) // _NOISE_SAMPLES)
    mid = x[1:-1:k]
    d2 = x[2::k][: mid.size] - 2.0 * mid
    d2 += x[:-2:k][: mid.size]
    np.abs(d2, out=d2)
    return float(1.4826 * np.median(d2) / np.sqrt(6.0))


def default_threshold_Nm(
    torque_Nm: np.ndarray, torque_resolution_Nm: float = 0.0, noise_Nm: float | None = None
) -> float:
    """Reversal threshold, N·m: the largest of 8 noise standard deviations, two resolution
    steps and 5 % of the torque amplitude. ``noise_Nm`` (if known) saves estimating it."""
    x = np.asarray(torque_Nm, dtype=float)
    amplitude = 0.5 * float(np.max(x) - np.min(x)) if x.size else 0.0
    noise = white_noise_std(x) if noise_Nm is None else noise_Nm
    return max(
        NOISE_MULTIPLE * noise,
        2.0 * float(torque_resolution_Nm),
        AMPLITUDE_FRACTION * amplitude,
    )


def _first_direction(x: np.ndarray, h: float) -> tuple[int, int]:
    """Index where the torque first leaves a band of width ``h`` and the direction it takes.

    Returns ``(index, +1 | -1)``, or ``(len(x), 0)`` when it never does.
    """
    n = x.size
    lo = hi = float(x[0])
    i, block = 0, _FIRST_BLOCK
    while i < n:
        seg = x[i : i + block]
        cmax = np.maximum.accumulate(seg)
        np.maximum(cmax, hi, out=cmax)
        cmin = np.minimum.accumulate(seg)
        np.minimum(cmin, lo, out=cmin)
        hit = np.flatnonzero(cmax - cmin > h)
        if hit.size:
            j = int(hit[0])
            return i + j, (1 if seg[j] >= cmax[j] else -1)
        hi, lo = float(cmax[-1]), float(cmin[-1])
        i += seg.size
        block = min(2 * block, _MAX_BLOCK)
    return n, 0


def _next_turn(
    x: np.ndarray, start: int, direction: int, h: float, plateau_tol: float = 0.0
) -> int | None:
    """Index of the extremum that ends the branch running from ``start`` in ``direction``.

    The branch ends when the torque comes back by more than ``h`` from its running extremum.
    The turning point is the (first) sample at that extremum, except after a dwell at the
    peak (at least ``MIN_DWELL_SAMPLES`` contiguous samples within ``plateau_tol`` of it): then
    it is the dwell's last sample, because the dwell belongs to the branch that reached it
    (the unit is still in its loading state there: friction, creep) and the next branch
    starts when the torque really turns. None if the run ends first.
    """
    n = x.size
    best, ibest = -np.inf, start
    i, block = start, _FIRST_BLOCK
    while i < n:
        seg = x[i : i + block] if direction > 0 else -x[i : i + block]
        cmax = np.maximum.accumulate(seg)
        np.maximum(cmax, best, out=cmax)
        hit = np.flatnonzero(cmax - seg > h)
        stop = int(hit[0]) + 1 if hit.size else seg.size
        j = int(np.argmax(seg[:stop]))
        if seg[j] > best:
            best, ibest = float(seg[j]), i + j
        if hit.size:
            departure = i + int(hit[0])
            tail = x[ibest:departure] if direction > 0 else -x[ibest:departure]
            off = np.flatnonzero(tail < best - plateau_tol)
            length = int(off[0]) if off.size else tail.size  # contiguous samples at the peak
            return ibest + length - 1 if length >= MIN_DWELL_SAMPLES else ibest
        i += seg.size
        block = min(2 * block, _MAX_BLOCK)
    return None


def _turning_points(x: np.ndarray, h: float, plateau_tol: float = 0.0) -> tuple[np.ndarray, int]:
    """Turning-point indices and the direction of the first branch (0: no branch found)."""
    i, first = _first_direction(x, h)
    if first == 0:
        return np.empty(0, dtype=np.int64), 0
    # The first branch starts at the extremum of the samples before the band was left.
    head = x[: i + 1]
    origin = int(np.argmin(head) if first > 0 else np.argmax(head))
    turns: list[int] = []
    direction, start = first, origin
    while True:
        t = _next_turn(x, start, direction, h, plateau_tol)
        if t is None:
            break
        turns.append(t)
        direction, start = -direction, t
    return _drop_transients(x, np.asarray(turns, dtype=np.int64), origin, h), first


#: A reversal pair nested inside a longer movement is a transient (not a cycle) when the
#: reversed stretch between its two turns lasts at most this fraction of the enclosing
#: movement's samples ...
TRANSIENT_DURATION_FRACTION = 0.05
#: ... and its torque range is at most this fraction of the enclosing movement's range.
TRANSIENT_RANGE_FRACTION = 0.25


def _drop_transients(x: np.ndarray, turns: np.ndarray, origin: int, h: float) -> np.ndarray:
    """The turning points without the transient pairs: two turns ``a, b`` whose movement
    ``prev -> a`` continues past ``a`` after ``b`` (``b -> next`` beyond ``a`` and ``b`` short
    of ``prev``, each by more than ``h``), with the reversed stretch ``a -> b`` short and small
    against the enclosing ``prev -> next`` (:data:`TRANSIENT_DURATION_FRACTION`,
    :data:`TRANSIENT_RANGE_FRACTION`). The flank impact at the play crossing spikes the
    measured torque by up to several % of the amplitude for a few samples; without a
    recorded torque command that spike split a branch and cost the cycle its lost motion.
    A deliberate minor loop lasts longer than a spike and stays a cycle."""
    kept = [int(t) for t in turns]
    n = x.size
    i = 0
    while i + 1 < len(kept):
        a, b = kept[i], kept[i + 1]
        prev = kept[i - 1] if i > 0 else origin
        nxt = kept[i + 2] if i + 2 < len(kept) else n - 1
        d = 1.0 if x[a] > x[b] else -1.0  # a is a maximum: the movement prev -> a rises
        past = d * (x[nxt] - x[a]) > h and d * (x[prev] - x[b]) < -h
        short = (b - a) <= TRANSIENT_DURATION_FRACTION * (nxt - prev)
        small = d * (x[a] - x[b]) <= TRANSIENT_RANGE_FRACTION * d * (x[nxt] - x[prev])
        if past and short and small:
            del kept[i : i + 2]
            i = max(i - 1, 0)
        else:
            i += 1
    return np.asarray(kept, dtype=np.int64)


def _passes(
    x: np.ndarray, starts: np.ndarray, stops: np.ndarray, direction: np.ndarray, h: float
) -> tuple[tuple[tuple[int, ...], tuple[int, ...]], ...]:
    """Group segments into cycles: k-th loading pass with k-th unloading pass, in time order."""
    n_seg = len(starts)
    segs = list(range(n_seg))
    merged: tuple[int, int] | None = None
    if n_seg >= 3 and direction[0] == direction[-1]:
        t0, t_end = float(x[0]), float(x[-1])
        interior = (t0 - float(np.min(x)) > h) and (float(np.max(x)) - t0 > h)
        if interior and abs(t_end - t0) <= 2.0 * h:
            merged = (n_seg - 1, 0)  # the run's end, then its start: one closed pass
    loading: list[tuple[int, ...]] = []
    unloading: list[tuple[int, ...]] = []
    for k in segs:
        if merged is not None and k == n_seg - 1:
            continue
        group = merged if (merged is not None and k == 0) else (k,)
        (loading if direction[k] > 0 else unloading).append(group)
    return tuple(zip(loading, unloading, strict=False))


def split_branches(
    torque_Nm: np.ndarray,
    *,
    threshold_Nm: float | None = None,
    torque_resolution_Nm: float = 0.0,
) -> Branches:
    """Split a torque record (N·m, time order) into loading/unloading branches and cycles.

    ``threshold_Nm`` is the reversal threshold (default :func:`default_threshold_Nm`).
    Samples before the first branch (a dwell before the torque starts to move) join it.
    """
    x = np.asarray(torque_Nm, dtype=float)
    if x.ndim != 1 or x.size < 3:
        raise AnalysisError(f"torque must be a 1-D array of at least 3 samples, got {x.shape}")
    if not np.all(np.isfinite(x)):
        bad = int(np.flatnonzero(~np.isfinite(x))[0])
        raise AnalysisError(f"torque sample {bad} is not a finite number ({x[bad]})")
    h = default_threshold_Nm(x, torque_resolution_Nm) if threshold_Nm is None else threshold_Nm
    if not h > 0:
        raise AnalysisError(f"reversal threshold must be > 0 N·m, got {h}")
    # a dwell at a peak: samples within 4 noise standard deviations (or one resolution step)
    # of the extremum belong to the branch that reached it
    plateau_tol = min(max(4.0 * white_noise_std(x), float(torque_resolution_Nm)), 0.5 * h)
    turns, first = _turning_points(x, h, plateau_tol)
    n = x.size
    if first == 0:
        starts = np.array([0], dtype=np.int64)
        stops = np.array([n], dtype=np.int64)
        direction = np.array([1 if x[-1] >= x[0] else -1], dtype=np.int8)
    else:
        bounds = np.concatenate(([0], turns, [n - 1])).astype(np.int64)
        starts = bounds[:-1]
        stops = bounds[1:] + 1
        keep = stops - starts > 1  # a turn on the last sample leaves a 1-sample tail
        starts, stops = starts[keep], stops[keep]
        direction = np.where(np.arange(starts.size) % 2 == 0, first, -first).astype(np.int8)
    passes = _passes(x, starts, stops, direction, h)
    cycle = np.full(starts.size, -1, dtype=np.int64)
    for c, (load, unload) in enumerate(passes):
        cycle[list(load) + list(unload)] = c
    return Branches(
        starts=starts,
        stops=stops,
        direction=direction,
        cycle=cycle,
        turning_points=turns,
        threshold_Nm=float(h),
        n_samples=n,
        passes=passes,
    )


TIP_SEARCH_SAMPLES = 25
"""How far (samples) from a command's turn the measured torque's own extremum is looked for."""


def at_measured_tips(branches: Branches, torque_Nm: np.ndarray,
                     search: int = TIP_SEARCH_SAMPLES) -> Branches:
    """The branches split at the command's turns, each turn moved to the measured torque's
    extremum next to it (within ``search`` samples, inside the two segments that meet there).

    The command locates a reversal without noise, but the loop's tip is where the measured
    torque turns: the two branches meet there (both end on the tip sample). Rows stamped late
    under load, or a drive that lags its command, put the measured turn a few samples off the
    command's: split at the command alone, the unloading branch began at 9.66 N·m after a
    dwell at 10 N·m, and the stiffness at the peak could not be read."""
    x = np.asarray(torque_Nm, dtype=float)
    starts, stops = branches.starts.copy(), branches.stops.copy()
    turns = branches.turning_points.copy()
    for k in range(len(starts) - 1):
        t = int(starts[k + 1])
        if int(stops[k]) != t + 1:  # not a shared turn sample
            continue
        lo = max(int(starts[k]) + 1, t - search)
        hi = min(int(stops[k + 1]) - 2, t + search)
        if hi <= lo:
            continue
        window = x[lo : hi + 1]
        j = lo + int(np.argmax(window) if branches.direction[k] > 0 else np.argmin(window))
        starts[k + 1], stops[k] = j, j + 1
        turns[turns == t] = j
    return Branches(starts=starts, stops=stops, direction=branches.direction,
                    cycle=branches.cycle, turning_points=turns,
                    threshold_Nm=branches.threshold_Nm, n_samples=branches.n_samples,
                    passes=branches.passes)
