"""A twist that the torque does not explain: an encoder fault, found in a recorded loop.

Issue 33 item 1: with a quiet encoder (0.05 arcsec rms, or none) a 0.45 s freeze at the top of
a ramp, or a position jump of 1,000-3,000 counts, gave a verdict (even OK) from wrong figures.
The engine's live watch (:mod:`rig.engine.frozen`) judges a still reading against 20 % of
rated torque of friction hold, which a short freeze stays inside. Here the whole run is known,
so the unit's own hysteresis sets what a hold can be. Nothing here judges the noise level: a
good encoder is quiet.

The unit is an elastic body with free play and friction (seed 000 Fig. 6): outside the play
(the torque away from the zero band, where the flanks change) its twist follows the torque
at its stiffness ``K``, ``dθ = dT / K``, except where a friction hold lets go (a slip of at
most the loop's hysteresis torque width ``W`` over ``K``). Two findings, each naming the
samples and the run's time:

* **Step**: between two consecutive samples outside the zero band and on one side of it,
  ``|dθ - dT/K| > 2 |dT|/K + S/K + tol``, ``S`` the larger of ``W`` and a stick-slip of
  :data:`SLIP_SHARE` of rated; inside the band (the play is crossed there, fast or slow)
  only a step *against* the branch's motion counts, beyond that and the play (the output
  rebounds inside its play when it strikes a flank, never further). ``tol`` is
  :data:`MIN_COUNTS` encoder counts or 8 noise standard deviations of the twist, the larger.
* **Freeze**: a stretch whose reading does not change (within half a count) while the torque
  moves away from zero, outside the band, by ``ΔT`` (no friction holds a unit that is
  being loaded further), or back towards zero by more than ``W`` (the hold at a reversal):
  the twist owed, ``ΔT / K``, is at least :data:`FREEZE_COUNTS` counts (a noisy reading
  that does not change at all is no noise). ``K`` is the nominal stiffness: real units are
  softer, so this is the least twist owed; the torque's travel in one sample (plus the
  channel lag) and 4 noise standard deviations owe nothing.

``K`` is the unit's nominal stiffness when known, else the run's own; ``W`` is
:data:`HOLD_SHARE` of rated torque. The zero band is :data:`BAND_SHARE` of rated plus ``W``
around the loop's torque offset (a drag on the free output moves the play's crossing off
zero by up to its own torque).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["EncoderFault", "MIN_COUNTS", "find_encoder_faults"]

MIN_COUNTS = 8.0
"""Twist (encoder counts) a step must reach: far above one count of resolution."""
FREEZE_COUNTS = 8.0
"""Twist (encoder counts) a still reading must owe. A quiet reading may keep its count for a
few rows by chance while the unit's twist trails a torque step (a generator of another lab
does so by 4 counts' worth); eight counts it cannot."""
NOISE_SIGMAS = 8.0
"""Twist noise standard deviations a finding must reach (the run's own white noise)."""
BAND_SHARE = 0.05
"""Half-width of the zero band (share of rated torque) around the loop's torque offset."""
HOLD_SHARE = 0.1
"""The friction hold a reversal may show (share of rated torque): the twist stays while the
torque turns back by twice the friction torque, and a unit whose friction is 5 % of its
rated torque is a poor one already. (The loop's own area is no measure of it: the play's
crossing and a jump add to the area as much as the friction does.)"""
SLIP_SHARE = 0.5
"""Largest stick-slip a unit may show (share of rated torque, over its stiffness; the slip
and its overshoot's return): a unit that sticks and lets go of half its rated torque is no
healthy unit, but it is the unit, not its encoder."""
TORQUE_LATE_S = 0.04
"""How late (s) the torque channel may be against the twist without a word: 30-40 ms seen
on a loaded 2-core PC running the simulated devices (docs/reliability.md)."""
MAX_FINDINGS = 5


@dataclass(frozen=True)
class EncoderFault:
    """One finding: ``kind`` ("step" or "freeze"), the samples ``[start, stop]`` (0-based,
    inclusive), the twist seen and the twist the torque explains (arcmin)."""

    kind: str
    start: int
    stop: int
    seen_arcmin: float
    explained_arcmin: float

    def describe(self, t_s: np.ndarray, device: str = "output encoder") -> str:
        """One line: what the torque demanded, what came, where in the run."""
        a, b = float(t_s[self.start]), float(t_s[self.stop])
        where = (f"samples {self.start + 1}-{self.stop + 1}, t = {a:.3f}-{b:.3f} s of the run")
        if self.kind == "step":
            return (f"{device}: expected the twist to follow the torque "
                    f"({self.explained_arcmin:+.4g} arcmin), got a step of "
                    f"{self.seen_arcmin:+.4g} arcmin between {where}: a position jump that no "
                    "torque explains")
        return (f"{device}: expected the twist to follow the torque (at least "
                f"{self.explained_arcmin:.4g} arcmin), got the same reading over {where}: a "
                "frozen encoder reading")


def _steps(torque: np.ndarray, twist: np.ndarray, direction: np.ndarray, outside: np.ndarray,
           k: float, hold: float, slip: float, tol: float, play: float) -> list[EncoderFault]:
    d_t = np.diff(torque)
    d_th = np.diff(twist)
    expected = d_t / k
    moving = direction[1:].astype(float)
    allowed = 2.0 * np.abs(expected) + tol + max(hold, slip) / k
    side = np.sign(torque)
    flank = outside[:-1] & outside[1:] & (side[:-1] == side[1:])
    bad_flank = flank & (np.abs(d_th - expected) > allowed)
    bad_band = ~flank & (moving != 0) & (moving * d_th < -(allowed + play))
    return [EncoderFault("step", int(i), int(i) + 1, float(d_th[i]), float(expected[i]))
            for i in np.flatnonzero(bad_flank | bad_band)]


def _stretches(angle: np.ndarray, half_count: float) -> list[tuple[int, int]]:
    """Runs ``[i, j]`` (j > i) of samples whose reading changes by at most ``half_count``
    from one sample to the next (an encoder's reading moves by whole counts)."""
    still = np.abs(np.diff(angle)) <= half_count
    edges = np.diff(np.concatenate(([0], still.astype(np.int8), [0])))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(int(a), int(b)) for a, b in zip(starts, stops, strict=True)]


def _owed_Nm(torque: np.ndarray, outside: np.ndarray, hold: float, slack: float) -> float:
    """Torque (N·m) a still stretch moved that a still twist cannot explain: the travel away
    from zero outside the band, plus the travel back towards zero beyond the hold."""
    t = torque[outside]
    if t.size < 2:
        return 0.0
    s = np.sign(t[0])
    away = s * (t - t[0])  # > 0: loaded further
    further = max(0.0, float(np.max(away)) - slack)
    peak = int(np.argmax(away))
    back = float(away[peak] - np.min(away[peak:]))
    return further + max(0.0, back - hold - slack)


def find_encoder_faults(
    torque_Nm: np.ndarray,
    twist_arcmin: np.ndarray,
    output_angle_deg: np.ndarray,
    direction: np.ndarray,
    *,
    rated_torque_Nm: float,
    stiffness_Nm_per_arcmin: float,
    count_arcmin: float,
    twist_noise_arcmin: float,
    torque_noise_Nm: float = 0.0,
    torque_offset_Nm: float = 0.0,
    play_arcmin: float = 0.0,
    row_period_s: float = 0.0,
    channel_lag_s: float = 0.0,
) -> list[EncoderFault]:
    """The twist steps and frozen readings of a loop that its torque does not explain (see
    the module docstring). ``direction``: per sample +1 loading, -1 unloading, 0 unknown
    (:meth:`analysis.loop.Branches.sample_direction`); ``count_arcmin`` one encoder count of
    twist (0: unknown); ``output_angle_deg`` the output encoder's own reading (a frozen
    encoder freezes it); ``row_period_s`` the rows' period (s, 0: unknown) and
    ``channel_lag_s`` the torque channel's lag the run shows (s); ``play_arcmin`` the
    unit's free play (arcmin: the output bounces inside it when a flank is struck). At most
    :data:`MAX_FINDINGS` findings, in time order."""
    torque = np.asarray(torque_Nm, dtype=float)
    twist = np.asarray(twist_arcmin, dtype=float)
    angle = np.asarray(output_angle_deg, dtype=float)
    ok = np.isfinite(torque) & np.isfinite(twist) & np.isfinite(angle)
    if ok.sum() < 3 or not (stiffness_Nm_per_arcmin > 0 and rated_torque_Nm > 0):
        return []
    if not ok.all():
        torque, twist, angle, direction = torque[ok], twist[ok], angle[ok], direction[ok]
    index = np.flatnonzero(ok)
    k = float(stiffness_Nm_per_arcmin)
    tol = max(MIN_COUNTS * count_arcmin, NOISE_SIGMAS * twist_noise_arcmin, 1e-6)
    hold = HOLD_SHARE * rated_torque_Nm
    band = BAND_SHARE * rated_torque_Nm + hold + 4.0 * torque_noise_Nm
    # a loop spoilt by a jump has no offset to trust: at most the band's own width
    offset = float(np.clip(torque_offset_Nm, -BAND_SHARE * rated_torque_Nm,
                           BAND_SHARE * rated_torque_Nm))
    centred = torque - offset
    outside = np.abs(centred) > band
    found = _steps(centred, twist, np.asarray(direction), outside, k, hold,
                   SLIP_SHARE * rated_torque_Nm, tol, max(play_arcmin, 0.0))
    # the reading's own quantum: the count, or the finest step the record shows (an export
    # rounded coarser than the encoder counts)
    moved = np.abs(np.diff(angle))
    moved = moved[moved > 0]
    quantum = max(count_arcmin, 60.0 * float(moved.min()) if moved.size else 0.0)
    half_count = 0.5 * quantum / 60.0
    freeze_tol = max(FREEZE_COUNTS * quantum, 1e-6)
    # the torque may trail the twist by a row, the run's own lag, and a loaded PC's
    # stamping: that much of its travel, and its noise, owe nothing
    late_s = abs(channel_lag_s) + TORQUE_LATE_S
    lag_rows = 1 + (int(np.ceil(late_s / row_period_s)) if row_period_s > 0 else 0)
    for i, j in _stretches(angle, half_count):
        seg = centred[i:j + 1]
        late = np.abs(seg[lag_rows:] - seg[:-lag_rows]) if seg.size > lag_rows else \
            np.array([np.ptp(seg)])
        slack = 4.0 * torque_noise_Nm + float(np.max(late))
        owed = _owed_Nm(centred[i:j + 1], outside[i:j + 1], hold, slack) / k
        if owed >= freeze_tol:
            found.append(EncoderFault("freeze", i, j, float(twist[j] - twist[i]), owed))
    found.sort(key=lambda f: f.start)
    return [EncoderFault(f.kind, int(index[f.start]), int(index[f.stop]), f.seen_arcmin,
                         f.explained_arcmin) for f in found[:MAX_FINDINGS]]
