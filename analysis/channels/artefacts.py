"""What the measuring system adds to a run, estimated from the run itself (issue 20, point 1).

Pure numerics. None of these is an effect of the unit; each is estimated per run, taken out
of the data (or carried as a nuisance parameter of every candidate, the null included) and
reported under the diagnosis report's ``measurement`` key:

* **Time base** (:func:`time_base`): the sample interval, its jitter and the gaps (dropped
  rows). Block means never span a gap (:func:`gap_breaks`).
* **Torque-channel lag** (:func:`torque_lag_s`): a transport delay or a first-order filter of
  the torque sensor. At the loop's frequencies (far below ``1 / (2 pi tau)``) a first-order
  filter of time constant ``tau`` is the delay ``tau`` (its phase ``-omega tau``), so both are
  one parameter: the shift of the torque channel's time, to a quarter sample, that best
  explains the loaded flanks.
* **Transients after impacts** (:func:`settling_mask`): after the output crosses the free
  play it strikes the other flank and rings at the locked resonance. The samples are left out
  from the jump until the twist's second difference has stayed within its own noise band for
  SETTLED_SAMPLES samples: a rule read from the data, not a fixed count.
* **Torque zero at the play crossings** (:func:`crossing_zero`): the output changes flank
  where the chain torque passes zero, i.e. where the *measured* torque equals the sensor's
  zero plus the friction torque in the direction of loading. The mean of the rising and the
  falling crossing torques is the run's torque zero (its re-tare residual), their half
  difference the Coulomb friction, and their trend over the run the zero's drift.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Samples the twist's second difference must stay inside its noise band before a transient
#: after an impact counts as settled.
SETTLED_SAMPLES = 3
#: Band of the second difference (robust standard deviations) that counts as noise.
SETTLE_BAND = 4.0
#: A step in time larger than this many median intervals (plus four jitter sigmas) is a gap:
#: rows were dropped there.
GAP_INTERVALS = 1.5
#: Largest torque-channel lag searched (s; at least one sample): a torque transducer's
#: filter or a fieldbus delay is a few milliseconds, and a longer shift would stand in for
#: slow changes of the unit (a drift, creep) instead.
MAX_LAG_S = 0.03
#: Lag grid step (samples): a quarter sample (linear interpolation between samples).
LAG_STEP_SAMPLES = 0.25


@dataclass(frozen=True)
class TimeBase:
    """Sample times of a run: median interval (s), jitter (robust sd of the intervals, s),
    gaps (count and the longest, s) and the share of samples missing in them."""

    interval_s: float
    jitter_s: float
    gaps: int
    longest_gap_s: float
    missing_share: float

    def to_dict(self) -> dict[str, float | int]:
        return {"interval_s": self.interval_s, "jitter_s": self.jitter_s, "gaps": self.gaps,
                "longest_gap_s": self.longest_gap_s, "missing_share": self.missing_share}


def time_base(t_s: np.ndarray) -> TimeBase:
    """Sample interval, jitter and gaps of a time column (s)."""
    dt = np.diff(np.asarray(t_s, dtype=float))
    if dt.size == 0:
        return TimeBase(math.nan, math.nan, 0, 0.0, 0.0)
    med = float(np.median(dt))
    jitter = 1.4826 * float(np.median(np.abs(dt - med)))
    gap = gap_breaks(t_s)
    missing = float(np.sum(np.maximum(np.round(dt[gap] / med) - 1.0, 0.0))) if med > 0 else 0.0
    return TimeBase(med, jitter, int(gap.sum()), float(dt[gap].max()) if gap.any() else 0.0,
                    missing / (missing + t_s.size))


#: An interval below this share of the median is not a sample interval: the row was stamped
#: when it arrived, in a burst after the acquisition stalled, not when it was sampled.
RESTAMP_SHARE = 0.25


def restamped_rows(t_s: np.ndarray) -> np.ndarray:
    """Rows whose time stamp is later than their sampling time by more than half a sample
    interval (True): a burst of rows stamped on arrival after a stall (intervals below
    RESTAMP_SHARE of the median). Their samples were taken one interval apart after the last
    row stamped on time, so row j of a burst starting at row a was sampled near
    ``t[a-1] + (j - a + 1) * dt`` and stamped at ``t[j]``; a channel read at the stamp
    (the torque, interpolated at the master's time) belongs to another moment than the twist.
    A dropped row (a gap with no burst) keeps its neighbours' times and is not flagged."""
    t = np.asarray(t_s, dtype=float)
    out = np.zeros(t.size, dtype=bool)
    dt = np.diff(t)
    if dt.size < 2:
        return out
    med = float(np.median(dt))
    if not med > 0:
        return out
    squeezed = dt < RESTAMP_SHARE * med  # the step k -> k+1 is inside a burst
    k = 0
    while k < squeezed.size:
        if not squeezed[k]:
            k += 1
            continue
        m = k
        while m + 1 < squeezed.size and squeezed[m + 1]:
            m += 1
        a, b = k, m + 1  # rows a..b arrived together; row a - 1 was the last on time
        start = t[a - 1] if a > 0 else t[a] - med
        sampled = start + med * np.arange(1, b - a + 2)
        out[a:b + 1] = (t[a:b + 1] - sampled) > 0.5 * med
        k = m + 1
    return out


def after_restamped(t_s: np.ndarray, restamped: np.ndarray) -> np.ndarray:
    """Rows (True) within one stall's length after a burst of restamped rows: a play crossing
    inside the burst was not observed at its torque, so where the unit switched flank is
    unknown there to the torque the ramp covers in that time."""
    t = np.asarray(t_s, dtype=float)
    out = np.zeros(t.size, dtype=bool)
    idx = np.flatnonzero(restamped)
    if idx.size == 0:
        return out
    bursts = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
    for burst in bursts:
        a, b = int(burst[0]), int(burst[-1])
        start = t[a - 1] if a > 0 else t[a]
        span = max(t[b] - start, 0.0)
        out |= (t > t[b]) & (t <= t[b] + span)
    return out


def gap_breaks(t_s: np.ndarray) -> np.ndarray:
    """``gap[k]``: the step k -> k+1 is a gap in the time base (rows dropped there)."""
    dt = np.diff(np.asarray(t_s, dtype=float))
    if dt.size == 0:
        return np.zeros(0, dtype=bool)
    med = float(np.median(dt))
    jitter = 1.4826 * float(np.median(np.abs(dt - med)))
    return dt > GAP_INTERVALS * med + 4.0 * jitter


def settling_mask(twist: np.ndarray, jump: np.ndarray) -> np.ndarray:
    """Samples still ringing after a flank impact (True): from each jump (``jump[k]``: the
    step k -> k+1 crosses the play or bounces) up to the last sample whose second difference
    leaves SETTLE_BAND robust sigmas before it has stayed inside for SETTLED_SAMPLES samples
    in a row (none when the landing is quiet)."""
    n = twist.size
    ringing = np.zeros(n, dtype=bool)
    if n < 5 or not jump.any():
        return ringing
    d2 = np.zeros(n)
    d2[1:-1] = twist[2:] - 2.0 * twist[1:-1] + twist[:-2]
    quiet_d2 = d2[1:-1][~(jump[1:] | jump[:-1])]
    scale = 1.4826 * float(np.median(np.abs(quiet_d2))) if quiet_d2.size else 0.0
    if scale <= 0.0:  # a quantised, noise-free reading: any change of slope is a transient
        nz = np.abs(quiet_d2[quiet_d2 != 0])
        scale = float(np.min(nz)) / SETTLE_BAND if nz.size else 0.0
    band = SETTLE_BAND * scale
    for j in np.flatnonzero(jump):
        k, calm, last = j + 2, 0, j + 1
        while k < n - 1 and calm < SETTLED_SAMPLES:
            if jump[k]:
                # the next jump (a bounce) came before the twist settled: everything up to
                # it is still in flight, however still it looked (friction can hold the
                # output mid-play for a few samples between two bounces)
                last = k
                break
            if abs(d2[k]) > band:
                calm, last = 0, k
            else:
                calm += 1
            k += 1
        ringing[j + 2:last + 1] = True
    return ringing


#: Samples whose torque has moved less than this share of the amplitude since the last
#: reversal are left out of the lag estimate: there a friction holds the twist (the branch
#: changes only once the torque has moved twice the friction torque, up to 30 % of rated
#: for the largest plausible friction), which a time shift would otherwise imitate.
HOLD_SHARE = 0.3


def travel_since_reversal(torque: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """|torque - torque at the last reversal| (N*m) per sample, the reversal's torque being
    the extreme reached before the direction changed."""
    change = np.flatnonzero(np.diff(direction) != 0) + 1
    starts = np.concatenate([[0], change])
    out = np.zeros_like(torque)
    prev_extreme = float(torque[0])
    for a, b in zip(starts, [*change, torque.size], strict=True):
        out[a:b] = np.abs(torque[a:b] - prev_extreme)
        seg = torque[a:b]
        if seg.size:
            prev_extreme = float(seg.max() if direction[a] > 0 else seg.min())
    return out


#: Rows of the loaded flanks folded into the running triangular factor at a time
#: (:func:`_flank_rss`): the design matrix of a long run is never held whole.
RSS_CHUNK_ROWS = 1 << 16


def _fold_rows(r: np.ndarray | None, rows: np.ndarray) -> np.ndarray | None:
    """The triangular factor R (``R.T @ R == A.T @ A``) of the rows folded so far (``r``)
    and ``rows``: Householder QR of ``[r; rows]`` (a tall-skinny QR, one chunk at a time)."""
    if rows.shape[0] == 0:
        return r
    stacked = rows if r is None else np.vstack([r, rows])
    return np.linalg.qr(stacked, mode="r")


def _flank_rss(torque: np.ndarray, twist: np.ndarray, direction: np.ndarray, amplitude: float,
               sigma: float, away: np.ndarray | None = None,
               friction_order: bool = True) -> float:
    """Residual sum of squares (noise units) of the loaded flanks (|T| > 20 % of the amplitude)
    under a smooth law per flank (1, T, T^2) with a constant loading/unloading separation
    (Coulomb friction's 2F/K): what a lag between the channels adds is a separation
    proportional to the torque rate, which this law cannot hold. ``away``: samples far
    enough from a reversal (HOLD_SHARE) to count; ``friction_order``: the separation only in
    friction's order (see below).

    The two flanks' laws share no coefficient, so each flank is its own least-squares fit of
    ``[1, T/A, (T/A)^2, direction]`` (A the amplitude; the scaling changes no residual) to the
    twist less its mean over the flanks (the constant columns absorb it). The rows are folded
    chunk by chunk into the triangular factor R of ``[X | y]`` (``R.T R = [X|y].T [X|y]``), and
    the fit is solved on R: the same minimum-norm solution and residual as a least-squares
    fit of all rows at once, in memory of a chunk."""
    on = np.abs(torque) > 0.2 * amplitude
    if away is not None:
        on &= away
    n_on = int(np.count_nonzero(on))
    if n_on < 30:
        return math.nan
    scale = amplitude if amplitude > 0 else 1.0
    offset = float(twist[on.argmax()])  # any twist of the flanks: only the rounding cares
    factors: dict[float, np.ndarray | None] = {1.0: None, -1.0: None}
    n = torque.size
    for a in range(0, n, RSS_CHUNK_ROWS):
        sel = on[a:a + RSS_CHUNK_ROWS]
        if not sel.any():
            continue
        tq = torque[a:a + RSS_CHUNK_ROWS][sel] / scale
        rows = np.column_stack([np.ones_like(tq), tq, tq * tq,
                                direction[a:a + RSS_CHUNK_ROWS][sel],
                                twist[a:a + RSS_CHUNK_ROWS][sel] - offset])
        positive = tq > 0
        factors[1.0] = _fold_rows(factors[1.0], rows[positive])
        factors[-1.0] = _fold_rows(factors[-1.0], rows[~positive])
    rss = 0.0
    for r in factors.values():
        if r is None:
            continue
        x, y = r[:, :4], r[:, 4]
        # friction puts the loading branch below the unloading one (the direction's
        # coefficient -F/K <= 0 on both flanks); a lag of the torque channel puts it above,
        # which friction must not absorb
        free = [0, 1, 2, 3]
        for _ in range(2):
            beta = np.zeros(4)
            beta[free], *_ = np.linalg.lstsq(x[:, free], y, rcond=None)
            if not (friction_order and 3 in free and beta[3] > 0):
                break
            free = [0, 1, 2]
        res = y - x @ beta
        rss += float(res @ res)
    return rss / max(sigma, 1e-12) ** 2


def best_torque_shift(t: np.ndarray, torque: np.ndarray, twist: np.ndarray,
                      direction: np.ndarray, sigma: float, shifts_s: np.ndarray,
                      evidence: float, friction_aware: bool = True) -> float:
    """The shift ``tau`` (s) of the torque channel's time (torque read at ``t - tau`` beside the
    twist at ``t``) among ``shifts_s`` that best explains the loaded flanks, kept only when it
    improves them by ``evidence`` noise units over no shift. The gain is counted once per
    count change of a quantised twist (a reading that holds one count holds one error).
    ``friction_aware``: leave a friction's hold after each reversal out and allow the branch
    separation only in friction's order (the diagnosis); without, any constant separation
    (``rig analyse``'s check of the channels' alignment, as it was calibrated)."""
    n = torque.size
    amplitude = float(np.percentile(np.abs(torque), 99.5))
    if n < 200 or amplitude <= 0 or shifts_s.size == 0:
        return 0.0
    edge = float(np.max(np.abs(shifts_s)))
    if bool(np.all(t[1:] > t[:-1])):  # ascending time: the core is a slice (views, no copy)
        core: np.ndarray | slice = slice(int(np.searchsorted(t, t[0] + edge, "left")),
                                         int(np.searchsorted(t, t[-1] - edge, "right")))
        n_core = max(0, core.stop - core.start)
    else:
        core = (t >= t[0] + edge) & (t <= t[-1] - edge)
        n_core = int(core.sum())
    if n_core < 100:
        return 0.0
    tc, yc, dc = t[core], twist[core], direction[core]
    away = (travel_since_reversal(torque, direction)[core] > HOLD_SHARE * amplitude
            if friction_aware else np.ones(tc.size, dtype=bool))
    base = _flank_rss(torque[core], yc, dc, amplitude, sigma, away, friction_aware)
    if not math.isfinite(base):
        return 0.0
    on = (np.abs(torque[core]) > 0.2 * amplitude) & away
    changes = int(np.count_nonzero(np.diff(yc[on])))
    per_count = max(1.0, on.sum() / max(changes, 1))
    best, best_rss = 0.0, base
    for tau in shifts_s:
        if tau == 0.0:
            continue
        rss = _flank_rss(np.interp(tc - tau, t, torque), yc, dc, amplitude, sigma, away,
                         friction_aware)
        if rss < best_rss:
            best, best_rss = float(tau), rss
    return best if (base - best_rss) / per_count > evidence else 0.0


def torque_lag_s(t: np.ndarray, torque: np.ndarray, twist: np.ndarray, direction: np.ndarray,
                 sigma: float, evidence: float) -> float:
    """Lag (s) of the torque channel behind the twist (negative: ahead), to a quarter sample:
    a sensor's first-order filter or transport delay (see the module docstring)."""
    n = torque.size
    dt = float(np.median(np.diff(t))) if n > 1 else 0.0
    if n < 200 or not dt > 0:
        return 0.0
    lmax = max(1, min(math.ceil(MAX_LAG_S / dt), n // 100))
    # whole samples first, then quarter samples around the best (the flanks' residual is
    # smooth in the shift); torque read at t - tau: a channel that lags by L has tau = -L
    coarse = best_torque_shift(t, torque, twist, direction, sigma,
                               np.arange(-lmax, lmax + 1) * dt, -math.inf)
    k = round(coarse / dt)
    fine = np.arange(max(-lmax, k - 1), min(lmax, k + 1) + LAG_STEP_SAMPLES / 2,
                     LAG_STEP_SAMPLES)
    return -best_torque_shift(t, torque, twist, direction, sigma, fine * dt, evidence)


@dataclass(frozen=True)
class CrossingZero:
    """Torque zero of a run read at its play crossings (N*m): ``zero_Nm`` (mean of the rising
    and falling crossing torques), ``friction_Nm`` (half their difference), ``drift_Nm`` (the
    zero's change over the run, when two or more crossings each way date it) and the
    crossings used."""

    zero_Nm: float
    friction_Nm: float
    drift_Nm_per_s: float
    t_mid_s: float
    crossings: int

    def zero_at(self, t_s: np.ndarray) -> np.ndarray:
        return self.zero_Nm + self.drift_Nm_per_s * (np.asarray(t_s) - self.t_mid_s)


def crossing_events(t: np.ndarray, torque: np.ndarray, twist: np.ndarray, jump: np.ndarray,
                    direction: np.ndarray, amplitude: float, play_arcmin: float
                    ) -> list[tuple[float, float, float]]:
    """Play crossings of a run: (time s, measured torque N*m just before the crossing began,
    loading direction +1/-1). A crossing is a cluster of jumps near zero torque (|T| under
    20 % of the amplitude, each within 0.2 s of the last) that moves the twist by at least
    half the nominal free play in the direction of loading; its torque is the mean of the two
    samples around the first jump."""
    idx = np.flatnonzero(jump & (np.abs(torque[:-1]) < 0.2 * amplitude))
    if idx.size == 0 or not (math.isfinite(play_arcmin) and play_arcmin > 0):
        return []
    events = []
    start = prev = int(idx[0])
    for j in [*idx[1:].tolist(), None]:
        if j is not None and t[j] - t[prev] <= 0.2:
            prev = int(j)
            continue
        end = min(prev + 1, twist.size - 1)
        d = float(direction[start])
        moved = (twist[end] - twist[start]) * d
        if moved >= 0.5 * play_arcmin:
            # the flank changed between the sample before the jump and the next one
            events.append((float(t[start]), 0.5 * float(torque[start] + torque[start + 1]), d))
        if j is not None:
            start = prev = int(j)
    return events


def crossing_zero(events: list[tuple[float, float, float]]) -> CrossingZero | None:
    """Torque zero, friction and drift from a run's crossings (see :class:`CrossingZero`); None
    without a crossing in each direction."""
    up = [(t, T) for t, T, d in events if d > 0]
    down = [(t, T) for t, T, d in events if d < 0]
    if not up or not down:
        return None
    tt = np.array([e[0] for e in events])
    TT = np.array([e[1] for e in events])
    dd = np.array([e[2] for e in events])
    t_mid = float(np.mean(tt))
    if len(up) >= 2 and len(down) >= 2 and np.ptp(tt) > 0:
        X = np.column_stack([np.ones_like(tt), dd, tt - t_mid])
        (zero, fric, drift), *_ = np.linalg.lstsq(X, TT, rcond=None)
    else:
        mu, md = float(np.mean([T for _, T in up])), float(np.mean([T for _, T in down]))
        zero, fric, drift = 0.5 * (mu + md), 0.5 * (mu - md), 0.0
    return CrossingZero(float(zero), float(fric), float(drift), t_mid, len(events))
