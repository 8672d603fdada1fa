"""A twist that does not follow the torque is a device fault, not a measurement.

Outside-probe rows 1 and 8 of issue 12, and issue 21 item 4: with the output encoder's
position frozen (a stuck sensor, a frozen PDO mapping that still arrives on time) a run
completed with a wrong lost motion, and a freeze of 0.45 s at the top of a ramp gave a
stiffness 4 % too high and a wrong OK. Heartbeats and PDOs keep coming, so only the physics
and the encoder's own noise can tell.

:class:`FrozenTwistWatch` follows the merged rows of a run. A *still stretch* is the rows
since the output angle last changed by at least half an encoder count. Two tests judge it,
and the first that fails trips the run (the engine then stops it: zero torque, drive
disabled, the run kept as aborted with the message, which names the encoder and the
stretch's interval in the run's time):

**Twist against torque** (any encoder). The torque range ``[lo, hi]`` of the stretch, each
torque taken :data:`LAG_S` later than it was measured (so the twist may trail the torque by
that much, far more than the 10 ms at which the analysis calls the channels out of step),
demands a twist of

- ``max(0, hi - lo - F) / K`` (arcmin), ``K`` the unit's nominal torsional stiffness (seed
  004 eq. 8; real units are softer, so this is a lower bound) and ``F`` =
  :data:`FRICTION_SHARE` x 2 x rated torque the most a friction hold can take at a load
  reversal (the twist stays while the torque changes by twice the friction torque), plus
- the free play (seed 000 eq. 1, nominal; runout only widens it) once the torque has
  crossed zero from below ``-band`` to above ``+band`` or back, ``band`` =
  :data:`BAND_SHARE` of the rated torque (the flanks change there).

It trips when that twist is at least :data:`MIN_COUNTS` encoder counts, whatever the
stretch's length. Without a stiffness or play from the unit data, that term is left out (no
guess); with neither, this test cannot judge.

**Reading against noise** (an encoder whose reading jitters). While the torque stands still
(it changes by less than :data:`QUIET_COUNTS` counts' worth between two rows) a healthy
encoder whose noise spans more than a count changes its reading in most rows: the run's own
closed stretches give the share ``p`` of quiet row pairs with an unchanged reading. A
stretch of ``n`` unchanged pairs has probability ``p**n``; with ``p``'s upper bound (3
sigma) it trips when that is below :data:`NOISE_FALSE_ALARM` (1e-9 per stretch: about 1e-6
per run of 2,500 rows). Used only after :data:`MIN_QUIET_PAIRS` quiet pairs and when
``p <= MAX_P_STILL`` (noise well above the quantisation, where the chance of an unchanged
reading does not depend on where in its count the shaft stands). A freeze is caught there
within a few dozen rows at any torque, amplitude or phase: with the simulated encoder's
noise (0.3 arcsec = 1.9 counts rms, ``p`` ~ 0.15) about 15 rows, 60 ms.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass

__all__ = ["FrozenTwistWatch", "MIN_COUNTS", "FRICTION_SHARE", "LAG_S", "NOISE_FALSE_ALARM"]

MIN_COUNTS = 8.0
"""Demanded twist (encoder counts) that must show before a still reading is a fault: far
above the one count of resolution and the twist hidden by the torque noise."""
BAND_SHARE = 0.05
FRICTION_SHARE = 0.1
"""Friction torque (share of rated) a friction hold may show: a reducer with a friction
torque of 10 % of its rated torque is a defective unit already."""
LAG_S = 0.1
"""The twist may trail the torque by this (s): the channels' stamping under a loaded PC."""
QUIET_COUNTS = 0.25
"""A row pair is *quiet* when its torque change demands less than this twist (counts)."""
MIN_QUIET_PAIRS = 50
MAX_P_STILL = 0.5
NOISE_FALSE_ALARM = 1e-9


@dataclass
class FrozenTwistWatch:
    """See the module docstring. Angles in deg, torques in N*m, stiffness N*m/arcmin, times
    in s (``t0_mono_s``: the run's start on the rows' clock, for the message)."""

    counts_per_rev: float
    rated_torque_Nm: float
    stiffness_Nm_per_arcmin: float | None = None
    play_arcmin: float | None = None
    device: str = "encoder"
    t0_mono_s: float = 0.0

    def __post_init__(self) -> None:
        self.count_arcmin = 360.0 * 60.0 / self.counts_per_rev
        self.half_count_deg = 0.5 * 360.0 / self.counts_per_rev
        self.band_Nm = BAND_SHARE * self.rated_torque_Nm
        self.friction_Nm = 2.0 * FRICTION_SHARE * self.rated_torque_Nm
        k = self.stiffness_Nm_per_arcmin
        self.quiet_Nm = (QUIET_COUNTS * self.count_arcmin * k if k
                         else 1e-3 * self.rated_torque_Nm)
        self.quiet_pairs = 0
        self.quiet_still_pairs = 0
        self.reset()

    def reset(self) -> None:
        """Forget the stretch (a new run, or after a pause); the noise statistics stay."""
        self._ref: float | None = None
        self._t0 = 0.0
        self._lo = math.inf
        self._hi = -math.inf
        self._pending: deque[tuple[float, float]] = deque()
        self._still_pairs = 0
        self._still_quiet = 0
        self._prev_torque = math.nan

    def expected_counts(self) -> float:
        """The twist (counts) the lagged torque range of the still stretch demands."""
        if self._ref is None or not math.isfinite(self._lo):
            return 0.0
        arcmin = 0.0
        if self.stiffness_Nm_per_arcmin:
            arcmin += max(0.0, self._hi - self._lo - self.friction_Nm) / \
                self.stiffness_Nm_per_arcmin
        if self.play_arcmin and self._lo < -self.band_Nm and self._hi > self.band_Nm:
            arcmin += self.play_arcmin
        return arcmin / self.count_arcmin

    def p_still_bound(self) -> float | None:
        """Upper bound (3 sigma) of the chance that a quiet row pair keeps its reading, from
        the run's closed stretches; None while too few, or when the reading is too quiet for
        the noise test."""
        n, k = self.quiet_pairs, self.quiet_still_pairs
        if n < MIN_QUIET_PAIRS:
            return None
        bound = min(1.0, (k + 3.0 * math.sqrt(k) + 3.0) / n)
        return bound if bound <= MAX_P_STILL else None

    def _close_stretch(self) -> None:
        self.quiet_pairs += self._still_quiet
        self.quiet_still_pairs += self._still_quiet

    def update(self, rows: Iterable[tuple[float, float, float]]) -> str | None:
        """Feed ``(t_s, torque_Nm, output_angle_deg)`` rows; a fault message, or None."""
        for t, torque, angle in rows:
            if not (math.isfinite(torque) and math.isfinite(angle)):
                continue
            quiet = abs(torque - self._prev_torque) < self.quiet_Nm
            self._prev_torque = torque
            if self._ref is None or abs(angle - self._ref) > self.half_count_deg:
                if self._ref is not None:
                    self._close_stretch()
                    self.quiet_pairs += int(quiet)
                self._ref, self._t0, self._t_last = angle, t, t
                self._lo, self._hi = math.inf, -math.inf
                self._pending = deque([(t, torque)])
                self._still_pairs = self._still_quiet = 0
                continue
            self._t_last = t
            self._still_pairs += 1
            self._still_quiet += int(quiet)
            self._pending.append((t, torque))
            while self._pending and self._pending[0][0] <= t - LAG_S:
                _, lagged = self._pending.popleft()
                self._lo = min(self._lo, lagged)
                self._hi = max(self._hi, lagged)
            reason = self._judge()
            if reason is not None:
                return reason
        return None

    def _interval(self) -> str:
        a, b = self._t0 - self.t0_mono_s, self._t_last - self.t0_mono_s
        return f"from t = {a:.3f} s to {b:.3f} s of the run ({b - a:.3f} s)"

    def _judge(self) -> str | None:
        expected = self.expected_counts()
        if expected >= MIN_COUNTS:
            return (f"{self.device}: expected the output twist to follow the torque "
                    f"({self._lo:+.3g} .. {self._hi:+.3g} N*m: at least {expected:.0f} "
                    f"counts), got the same position {self._interval()}: a frozen encoder "
                    "reading, not a measurement")
        p = self.p_still_bound()
        if p is not None and self._still_pairs * math.log(max(p, 1e-300)) < \
                math.log(NOISE_FALSE_ALARM):
            return (f"{self.device}: expected the reading to change with the encoder's own "
                    f"noise (at rest it kept its value in at most {100 * p:.0f} % of rows), "
                    f"got the same position for {self._still_pairs + 1} rows "
                    f"{self._interval()}: a frozen encoder reading, not a measurement")
        return None
