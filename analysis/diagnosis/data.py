"""Input of the diagnosis: one run as arrays, reduced to a few hundred quasi-static points.

Pure numerics. Per run: the twist noise (robust second differences, analysis.loop.branches),
the samples crossing the free play (a twist jump no torque change explains: not quasi-static,
left out), block means of the remaining samples (blocks never span a jump), the honest noise of
a block mean (the scatter of consecutive block means in dwells, where the loop stands still),
the branch (loading/unloading) and the time since the last torque reversal of each point.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from analysis.channels.artefacts import (
    CrossingZero,
    after_restamped,
    crossing_events,
    crossing_zero,
    gap_breaks,
    restamped_rows,
    settling_mask,
    time_base,
    torque_lag_s,
)
from analysis.channels.lag import LAG_EVIDENCE, direction_and_reversal
from analysis.errors import AnalysisError
from analysis.loop import analyse_loop
from analysis.loop.branches import white_noise_std
from analysis.models.by_kind import LoopModel, nominal_model_for_unit

#: Decimated points per run kept for fitting.
TARGET_POINTS = 240
#: Blocks whose mean torque is within this many block-mean torque sigmas (+ 2e-4 of the
#: amplitude) of zero are left out: with no torque on it the unit floats in the free play
#: (a slow drift before the crossing becomes a jump), so its flank is undetermined there.
FLOAT_BAND_SIGMAS = 6.0


@dataclass(frozen=True)
class RunInput:
    """One run as the diagnosis sees it: only what the campaign folder says (no labels).

    ``twist_arcmin``: output twist (arcmin, any zero); ``torque_Nm``: measured torque;
    ``input_angle_deg``: where the eccentric shaft was locked (None: unknown);
    ``temperature_C``: housing temperature per sample (None: unknown); ``unit``: run.json
    ``unit`` mapping."""

    run_id: str
    t_s: np.ndarray
    torque_Nm: np.ndarray
    twist_arcmin: np.ndarray
    rated_torque_Nm: float
    unit: Mapping[str, Any]
    input_angle_deg: float | None = None
    temperature_C: np.ndarray | None = None
    start_flank: int = -1
    torque_full_scale_Nm: float | None = None
    #: The torque the rig read at zero command before and after the loop (N*m; the run's
    #: ``result.torque_zero``): the torque channel's zero as measured, when the rig read it.
    zero_readings_Nm: tuple[float, ...] = ()
    #: When the run started (s on any one clock for the whole campaign, run.json
    #: ``started_at``): the campaign's time axis (None: unknown).
    started_s: float | None = None


@dataclass(frozen=True, eq=False)
class PreparedRun:
    """A run reduced to block means (arrays of equal length) and its summary numbers."""

    run_id: str
    torque_Nm: np.ndarray
    twist_arcmin: np.ndarray
    temperature_C: np.ndarray | None
    t_s: np.ndarray
    branch: np.ndarray  # +1 loading (torque rising), -1 unloading
    since_reversal_s: np.ndarray
    sigma_arcmin: float  # noise of one block mean
    sigma_torque_Nm: float  # noise of one block mean's torque
    raw_sigma_arcmin: float
    block: int
    n_raw: int
    n_transit: int
    rated_torque_Nm: float
    amplitude_Nm: float
    input_angle_deg: float | None
    mean_temperature_C: float | None
    start_flank: int
    nominal: LoopModel | None
    lost_motion_arcmin: float  # measured, analysis.loop (NaN: unavailable)
    raw: RunInput = field(repr=False)
    #: What the measuring system adds (analysis.channels.artefacts), for the report.
    measurement: dict[str, Any] = field(default_factory=dict, repr=False)
    #: Torque zero, friction and drift read at the play crossings (None: not readable).
    crossing: CrossingZero | None = field(default=None, repr=False)
    #: Blocks just after a burst of restamped rows (analysis.channels.artefacts.
    #: after_restamped) or the first block after a play crossing (:func:`landed_blocks`):
    #: where the unit switched flank is not known to the torque noise.
    time_unsure: np.ndarray | None = field(default=None, repr=False)
    #: The torque zero taken out of ``torque_Nm`` (N*m per block; zeros when none).
    zero_removed_Nm: np.ndarray | None = field(default=None, repr=False)


def resolution_of(values: np.ndarray) -> float:
    """The quantum (count) of a quantised channel: the smallest step between the distinct
    readings when readings repeat (fewer distinct values than half the samples) and the
    steps are multiples of it; 0 for a channel that is not visibly quantised."""
    v = np.asarray(values, dtype=float)
    u = np.unique(v)
    if u.size < 3 or u.size > v.size // 2:
        return 0.0
    steps = np.diff(u)
    steps = steps[steps > 1e-12 * max(1.0, float(np.max(np.abs(u))))]
    if steps.size == 0:
        return 0.0
    q = float(np.min(steps))
    ratio = steps / q
    if np.median(np.abs(ratio - np.round(ratio))) > 0.05:
        return 0.0
    return q


def transit_mask(twist_arcmin: np.ndarray, torque_Nm: np.ndarray, sigma_arcmin: float,
                 soft_compliance_arcmin_per_Nm: float) -> tuple[np.ndarray, np.ndarray]:
    """(keep, jump): ``jump[k]`` marks a step k -> k+1 whose twist change exceeds what the
    softest plausible flank and the noise allow (crossing the free play, impacts);
    ``keep`` is False for samples next to a jump (in flight across the play, or at its start
    or end, where a sample is partly in flight and its torque already past the switch while
    its twist is not: with inertia the crossing starts late)."""
    d_twist = np.abs(np.diff(twist_arcmin))
    d_torque = np.abs(np.diff(torque_Nm))
    jump = d_twist > d_torque * soft_compliance_arcmin_per_Nm + 6.0 * math.sqrt(2.0) * max(
        sigma_arcmin, 1e-6)
    keep = np.ones(twist_arcmin.size, dtype=bool)
    keep[:-1] &= ~jump
    keep[1:] &= ~jump
    return keep, jump


def landed_blocks(segments: list[tuple[int, int]], keep: np.ndarray, jump: np.ndarray,
                  block: int) -> np.ndarray:
    """Rows (True) of the first block after each play crossing: the twist jumped across the
    play just before it (the in-flight rows are left out), so the unit has landed on the
    other flank, while the torque read there is at the crossing, inside its noise band. When
    within that block it switched is not known to the torque noise (like the blocks after a
    burst of restamped rows: :func:`analysis.diagnosis.fit.run_float_masks`)."""
    out = np.zeros(keep.size, dtype=bool)
    for a, b in segments:
        if a > 0 and jump[:a].any() and (jump[a - 1] or not keep[a - 1]):
            out[a:min(b, a + block)] = True
    return out


def _segments(keep: np.ndarray, jump: np.ndarray) -> list[tuple[int, int]]:
    """Maximal index ranges [a, b) of kept samples with no jump inside."""
    n = keep.size
    brk = np.zeros(n, dtype=bool)
    brk[0] = True
    brk[1:] = jump | ~keep[1:] | ~keep[:-1]
    starts = np.flatnonzero(brk)
    out = []
    for i, a in enumerate(starts):
        b = starts[i + 1] if i + 1 < starts.size else n
        if keep[a]:
            out.append((int(a), int(b)))
    return out


def _block_means(values: np.ndarray, segments: list[tuple[int, int]], block: int) -> np.ndarray:
    out = []
    for a, b in segments:
        m = (b - a) // block
        if m == 0:
            if b - a >= max(1, block // 2):
                out.append(values[a:b].mean(keepdims=True))
            continue
        out.append(values[a:a + m * block].reshape(m, block).mean(axis=1))
        if b - (a + m * block) >= max(1, block // 2):
            out.append(values[a + m * block:b].mean(keepdims=True))
    return np.concatenate(out) if out else np.empty(0)


def _segment_ids(segments: list[tuple[int, int]], block: int) -> np.ndarray:
    ids = []
    for i, (a, b) in enumerate(segments):
        m = (b - a) // block
        extra = 1 if (b - a - m * block) >= max(1, block // 2) else 0
        ids.extend([i] * (m + extra))
    return np.asarray(ids, dtype=int)


def dwell_lost_motion_arcmin(torque_Nm: np.ndarray, twist_arcmin: np.ndarray,
                             direction: np.ndarray, rated_torque_Nm: float, window_Nm: float,
                             pct: float = 3.0) -> float:
    """Lost motion (arcmin) from the samples standing at +-pct % of rated torque (a plan with
    dwells there): midline ``(median loading + median unloading) / 2`` at +p minus at -p.
    Used when analysis.loop cannot read the run's branches; NaN when a point is missing."""
    p = pct / 100.0 * rated_torque_Nm
    mids = []
    for sign in (1.0, -1.0):
        near = np.abs(torque_Nm - sign * p) < window_Nm
        up = twist_arcmin[near & (direction > 0)]
        down = twist_arcmin[near & (direction < 0)]
        if up.size < 3 or down.size < 3:
            return math.nan
        mids.append(0.5 * (float(np.median(up)) + float(np.median(down))))
    return mids[0] - mids[1]


def prepare_run(run: RunInput, target_points: int = TARGET_POINTS, *, correct_lag: bool = True,
                exclude_transients: bool = True, with_lost_motion: bool = True) -> PreparedRun:
    """Reduce one run (see the module docstring). Raises AnalysisError on unusable input.
    ``correct_lag`` / ``exclude_transients``: take the torque channel's lag out and leave the
    transients after impacts out (the report's ``measurement`` compares the null model with
    and without each); ``with_lost_motion``: measure each run's lost motion too."""
    t, torque, twist, temp = _checked(run)
    nominal: LoopModel | None
    try:
        # the nominal model of the unit's kind (seed 000 reference model, seed 002 cycloid,
        # seed 001 beveloid): the diagnosis uses its free play and stiffness
        nominal = nominal_model_for_unit(run.unit, run.rated_torque_Nm)[0] if run.unit else None
    except AnalysisError:
        nominal = None
    # a channel's resolution belongs in its noise floor: a reading that sits on one count
    # for long stretches makes the second-difference estimate collapse, while the error of
    # a reading is still uniform over one count (q^2 / 12)
    q_twist = resolution_of(twist)
    q_torque = resolution_of(torque)
    sigma = math.hypot(white_noise_std(twist), q_twist / math.sqrt(12.0))
    sigma_t = math.hypot(white_noise_std(torque), q_torque / math.sqrt(12.0))
    # the measuring system's own share (analysis.channels.artefacts): time base, the
    # torque channel's lag (a filter or delay: taken out by reading the torque channel at the
    # shifted time), transients after impacts, the torque zero at the play crossings
    tbase = time_base(t)
    # rows stamped on arrival after a stall pair the twist with the torque of a later moment
    restamped = restamped_rows(t)
    unsure = after_restamped(t, restamped)
    if restamped.any() and int((~restamped).sum()) >= 20:
        t, torque, twist = t[~restamped], torque[~restamped], twist[~restamped]
        unsure = unsure[~restamped]
        if temp is not None:
            temp = temp[~restamped]
    amplitude = float(np.percentile(np.abs(torque), 99.5))
    direction0, _ = direction_and_reversal(t, torque, max(8.0 * sigma_t, 0.02 * amplitude))
    lag_s = torque_lag_s(t, torque, twist, direction0, sigma, LAG_EVIDENCE)
    if lag_s:
        inside = (t + lag_s >= t[0]) & (t + lag_s <= t[-1])
        torque = np.interp(t[inside] + lag_s, t, torque) if correct_lag else torque[inside]
        t, twist, unsure = t[inside], twist[inside], unsure[inside]
        if temp is not None:
            temp = temp[inside]
    if nominal is not None and math.isfinite(nominal.stiffness_Nm_per_arcmin):
        soft = 10.0 / nominal.stiffness_Nm_per_arcmin
    else:
        span_t = float(np.ptp(torque)) or 1.0
        soft = 10.0 * float(np.ptp(twist)) / span_t
    keep, jump = transit_mask(twist, torque, sigma, soft)
    ringing = settling_mask(twist, jump)
    if exclude_transients:
        keep &= ~ringing
    gaps = gap_breaks(t)
    segments = _segments(keep, jump | gaps)
    n_keep = int(sum(b - a for a, b in segments))
    block = max(1, int(round(n_keep / target_points)))
    unsure = unsure | landed_blocks(segments, keep, jump, block)
    thr = max(8.0 * sigma_t, 0.02 * amplitude)
    direction, since = direction_and_reversal(t, torque, thr)
    tb = _block_means(torque, segments, block)
    yb = _block_means(twist, segments, block)
    seg = _segment_ids(segments, block)
    sigma_tb = sigma_t / math.sqrt(block)
    sigma_b = _block_noise(tb, yb, seg, block, sigma, sigma_tb, amplitude, nominal, twist,
                           q_twist)
    play = nominal.play_arcmin if nominal is not None else math.nan
    events = crossing_events(t, torque, twist, jump, direction, amplitude, play)
    zero = crossing_zero(events)
    measurement = {
        "time_base": {**tbase.to_dict(), "restamped": int(restamped.sum())},
        "torque_lag_s": lag_s,
        "torque_lag_taken_out": bool(lag_s) and correct_lag,
        "twist_resolution_arcsec": q_twist * 60.0,
        "torque_resolution_Nm": q_torque,
        "twist_noise_arcsec": sigma * 60.0,
        "torque_noise_Nm": sigma_t,
        "transient_samples": int(ringing.sum()),
        "crossings": len(events),
    }
    # blocks at zero torque are kept: with no torque on it the unit floats in the free play,
    # which analysis.diagnosis.fit models (censored between the flank last loaded and the
    # centre of the play); there a torque-sensor offset shows (the unit on the other flank)
    held = np.ones(tb.size, dtype=bool)
    lost_motion = math.nan
    try:
        if with_lost_motion:
            res = analyse_loop(t, torque, twist, rated_torque_Nm=run.rated_torque_Nm)
            if "lost_motion_arcmin" in res.metrics:
                lost_motion = res.metrics["lost_motion_arcmin"].value
    except AnalysisError:
        pass
    if with_lost_motion and not math.isfinite(lost_motion):
        lost_motion = dwell_lost_motion_arcmin(torque, twist, direction, run.rated_torque_Nm,
                                               max(3.0 * sigma_t, 0.01 * run.rated_torque_Nm))
    return PreparedRun(
        run_id=run.run_id, torque_Nm=tb, twist_arcmin=yb,
        temperature_C=None if temp is None else _block_means(temp, segments, block)[held],
        t_s=_block_means(t, segments, block)[held],
        branch=np.sign(_block_means(direction, segments, block))[held],
        since_reversal_s=_block_means(since, segments, block)[held],
        sigma_arcmin=max(sigma_b, 1e-7), sigma_torque_Nm=sigma_tb, raw_sigma_arcmin=sigma,
        block=block, n_raw=int(t.size), n_transit=int((~keep).sum()),
        rated_torque_Nm=float(run.rated_torque_Nm), amplitude_Nm=amplitude,
        input_angle_deg=run.input_angle_deg,
        mean_temperature_C=None if temp is None else float(np.mean(temp)),
        start_flank=run.start_flank, nominal=nominal, lost_motion_arcmin=lost_motion, raw=run,
        measurement=measurement, crossing=zero,
        time_unsure=_block_means(unsure.astype(float), segments, block)[held] > 0,
    )


def _block_noise(tb: np.ndarray, yb: np.ndarray, seg: np.ndarray, block: int, sigma: float,
                 sigma_tb: float, amplitude: float, nominal: LoopModel | None,
                 twist: np.ndarray, q_twist: float) -> float:
    """The noise of one block mean of the twist (arcmin): from consecutive block means
    standing still, no less than what the second differences of the block means scatter
    by, and no less than the quantisation a block mean keeps without dither."""
    # honest block-mean noise: consecutive blocks of a segment standing still (a dwell)
    still = (np.diff(seg) == 0) & (np.abs(np.diff(tb)) < 3.0 * sigma_tb + 1e-4 * amplitude)
    pairs = np.diff(yb)[still]
    if pairs.size >= 20:
        sigma_b = 1.4826 * float(np.median(np.abs(pairs - np.median(pairs)))) / math.sqrt(2.0)
        sigma_b = max(sigma_b, 0.5 * sigma / math.sqrt(block))
    else:
        sigma_b = sigma / math.sqrt(block)
    # noise that is correlated over a block (a zero that wanders, vibration the torque
    # channel does not see) does not average down as 1/sqrt(block): the second differences
    # of consecutive block means of a segment measure what a block mean really scatters by.
    # What the measured torque explains is taken out first (the twist follows the torque
    # through the flank's compliance: ramps, steps and drive ripple are no error), so only
    # where the flank curves (the play crossing, a take-up) is the difference not noise,
    # and the median ignores those few
    comp = (1.0 / nominal.stiffness_Nm_per_arcmin if nominal is not None
            and math.isfinite(nominal.stiffness_Nm_per_arcmin)
            and nominal.stiffness_Nm_per_arcmin > 0 else 0.0)
    u = yb - comp * tb
    same = (seg[2:] == seg[1:-1]) & (seg[1:-1] == seg[:-2])
    d2b = (u[2:] - 2.0 * u[1:-1] + u[:-2])[same]
    if d2b.size >= 20:
        sigma_b = max(sigma_b, 1.4826 * float(np.median(np.abs(d2b))) / math.sqrt(6.0))
    # without dither (noise below a count) averaging does not shrink the quantisation error
    # of a block mean standing still: it stays up to half a count, uniform -> q / sqrt(12).
    # A block over which the twist sweeps m counts averages the sawtooth of its errors down
    # by about sqrt(m) (continuous loading moves through many counts per block)
    if white_noise_std(twist) < q_twist:
        same1 = seg[1:] == seg[:-1]
        swept = np.abs(np.diff(yb))[same1] / q_twist if same1.any() else np.zeros(1)
        m = max(1.0, float(np.median(swept)))
        sigma_b = max(sigma_b, q_twist / math.sqrt(12.0 * m))
    return sigma_b


def _checked(run: RunInput) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """A run's samples as arrays, checked (AnalysisError on unusable input); missing
    temperatures filled with the run's mean."""
    t = np.asarray(run.t_s, dtype=float)
    torque = np.asarray(run.torque_Nm, dtype=float)
    twist = np.asarray(run.twist_arcmin, dtype=float)
    if not (t.shape == torque.shape == twist.shape) or t.ndim != 1:
        raise AnalysisError(f"run {run.run_id!r}: t, torque and twist must be 1-D, same length")
    if t.size < 20:
        raise AnalysisError(f"run {run.run_id!r}: {t.size} samples, at least 20 needed")
    if not (np.all(np.isfinite(torque)) and np.all(np.isfinite(twist))):
        raise AnalysisError(f"run {run.run_id!r}: torque or twist has missing values")
    if not run.rated_torque_Nm > 0:
        raise AnalysisError(f"run {run.run_id!r}: rated torque must be > 0 N*m")
    temp = None if run.temperature_C is None else np.asarray(run.temperature_C, dtype=float)
    if temp is not None and not np.all(np.isfinite(temp)):
        finite = np.isfinite(temp)
        temp = None if not finite.any() else np.where(finite, temp, np.nanmean(temp))
    return t, torque, twist, temp

def smallest_zero_reading(runs: Sequence[PreparedRun]) -> tuple[float, str] | None:
    """The zero reading (N*m) nearest zero among the runs' readings at zero command
    (:attr:`RunInput.zero_readings_Nm`), with its run id; None when the rig read none."""
    best: tuple[float, str] | None = None
    for r in runs:
        for z in r.raw.zero_readings_Nm:
            if math.isfinite(z) and (best is None or abs(z) < abs(best[0])):
                best = (float(z), r.run_id)
    return best


def beyond_allowance_probability(zeros: Sequence[CrossingZero], allowance_Nm: float) -> float:
    """Probability (one-sided Student's t over the runs) of crossings as far beyond the zero
    allowance as these, were the torque zero within it: the larger of the rising and the
    falling crossings' own tests, each on the side of the runs' common zero. A sensor offset
    moves both by itself; a friction, and a channel lag under unequal crossing rates (a
    sine's), move them apart, and their mean may then sit beyond the allowance while the
    two directions disagree. 1.0 with fewer than 3 runs."""
    from scipy.stats import t as student_t

    if len(zeros) < 3:
        return 1.0
    zero = np.array([c.zero_Nm for c in zeros])
    fric = np.array([c.friction_Nm for c in zeros])
    side = 1.0 if float(np.mean(zero)) >= 0.0 else -1.0
    worst = 0.0
    for torque in (zero + fric, zero - fric):  # rising, falling crossings
        mean = side * float(np.mean(torque))
        se = float(np.std(torque, ddof=1)) / math.sqrt(torque.size)
        if se > 0:
            p = float(student_t.sf((mean - allowance_Nm) / se, torque.size - 1))
        else:
            p = 0.0 if mean > allowance_Nm else 1.0
        worst = max(worst, p)
    return worst


def remove_torque_zero(runs: Sequence[PreparedRun], alpha: float, allowance_Nm: float = 0.0
                       ) -> tuple[list[PreparedRun], dict[str, Any]]:
    """Take each run's torque zero, read at its play crossings
    (:func:`analysis.channels.artefacts.crossing_zero`), out of its torque.

    A torque zero re-tared before every run leaves a small residual that differs from run to
    run and may wander during the run: the measuring system's, not the unit's. A sensor
    offset (an effect) is the same in every run. So the zeros of three or more runs are
    compared with their own scatter (Student's t, two-sided, at ``alpha``): when their mean is
    not distinguishable from the scatter the whole zero of each run is taken out; when it is,
    only each run's departure from the mean (and its drift) is taken out and the common part
    is left for the torque_sensor_offset candidate to find. With one or two runs read, only
    the departures. A common zero within ``allowance_Nm`` (what a re-tare and the zero's
    drift over a campaign leave on a sound transducer) is the measuring system's too, and is
    taken out whole. So is a common zero when the rig itself read the torque channel within
    the allowance at zero command (before or after a run's loop, :func:`smallest_zero_reading`):
    a sensor offset would show in every such reading, so what the crossings hold is the zero's
    drift since the last re-tare (a campaign measured without re-taring between its runs).
    Returns the runs and the report's ``torque_zero`` entry."""
    from scipy.stats import t as student_t

    est = [(i, r.crossing) for i, r in enumerate(runs) if r.crossing is not None]
    out = list(runs)
    if not est:
        return out, {"runs_read": 0, "note": "no play crossing readable: zero not estimated"}
    zeros = np.array([c.zero_Nm for _, c in est])
    common = float(np.mean(zeros))
    p_common: float | None = None
    p_beyond: float | None = None
    keep_common = True
    if len(est) >= 3:
        se = float(np.std(zeros, ddof=1)) / math.sqrt(len(est))
        if se > 0:
            p_common = float(2.0 * student_t.sf(abs(common) / se, len(est) - 1))
        else:
            p_common = 0.0 if common != 0.0 else 1.0
        p_beyond = beyond_allowance_probability([c for _, c in est], allowance_Nm)
        keep_common = p_common <= alpha and abs(common) > allowance_Nm
    read = smallest_zero_reading(runs)
    # the readings overrule the crossings only where the crossings alone would leave a common
    # offset: the zero then wandered beyond the allowance since the last re-tare
    read_within = read is not None and abs(read[0]) <= allowance_Nm and keep_common
    if read_within:
        keep_common = False
    from_readings = []
    for i, c in est:
        r = runs[i]
        removed = c.zero_at(r.t_s) - (common if keep_common else 0.0)
        if read_within and len(r.raw.zero_readings_Nm) == 2 and r.t_s.size > 1:
            # the rig read this run's zero at zero command before and after its loop: the
            # zero wanders from the one through the crossings' to the other (piecewise
            # linear), where the crossings alone give one level for the whole run
            z0, z1 = r.raw.zero_readings_Nm
            t0, t1 = float(r.t_s[0]), float(r.t_s[-1])
            tm = min(max(c.t_mid_s, t0), t1)
            if t0 < tm < t1:
                removed = np.interp(r.t_s, [t0, tm, t1], [z0, c.zero_Nm, z1])
                from_readings.append(r.run_id)
        out[i] = replace(r, torque_Nm=r.torque_Nm - removed, zero_removed_Nm=removed)
    return out, {
        "runs_read": len(est),
        "per_run_Nm": {runs[i].run_id: c.zero_Nm for i, c in est},
        "drift_Nm_per_s": {runs[i].run_id: c.drift_Nm_per_s for i, c in est},
        "friction_at_crossings_Nm": {runs[i].run_id: c.friction_Nm for i, c in est},
        "common_Nm": common,
        "scatter_Nm": float(np.std(zeros, ddof=1)) if len(est) > 1 else None,
        "common_false_alarm_probability": p_common,
        "allowance_Nm": allowance_Nm,
        "beyond_allowance_false_alarm_probability": p_beyond,
        "read_at_zero_command_Nm": None if read is None else read[0],
        "from_zero_readings": from_readings,
        "treated_as": ("common offset left for the diagnosis; run-to-run departures removed"
                       if keep_common else
                       "drift of the zero since the last re-tare, removed (the rig read the "
                       "torque channel within the zero allowance at zero command)"
                       if read_within else
                       "re-tare residual of each run, removed (their common part is within "
                       "the zero allowance)" if p_common is not None and p_common <= alpha
                       else "re-tare residual of each run, removed"),
    }
