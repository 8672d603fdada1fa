"""A twist that never moves while the torque does is a device fault, not a measurement.

Outside-probe rows 1 and 8 of issue 12: with the output encoder's position frozen (a stuck
sensor, a frozen PDO mapping that still arrives on time) a run completed and reported a lost
motion of 0.374 arcmin, or 0.000, for a unit that measures 2.2. Heartbeats and PDOs keep
coming, so only the physics can tell: under a moving torque the output must twist.

:class:`FrozenTwistWatch` follows the merged rows of a run. Over the stretch since the
output angle last changed by at least half an encoder count it keeps the torque's range and
expects a twist of

- ``span / K`` (arcmin) from the elastic twist, with ``K`` the unit's nominal torsional
  stiffness (seed 004 eq. 8; the measured stiffness of real units is lower, so this is a
  lower bound), and
- the free play (seed 000 eq. 1, nominal; runout only widens it) once the torque has
  crossed zero from below ``-band`` to above ``+band`` or back, ``band`` = 5 % of the rated
  torque (the flanks change there),

and trips when that expected twist is at least :data:`MIN_COUNTS` encoder counts while not a
single count changed, the stretch has lasted :data:`MIN_STILL_S` and the torque has either
crossed the play or moved by :data:`MIN_SPAN_SHARE` of the rated torque. The last two keep it
from tripping on what a working encoder also shows briefly: the lag between the torque and
the encoder channels when the torque changes fast (a drive switched off), and a friction hold
at a load reversal, where the twist stays while the torque changes by twice the friction
torque. Without a stiffness or play from the unit data, that term is left out
(no guess); with neither, the watch cannot judge and never trips.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

__all__ = ["FrozenTwistWatch", "MIN_COUNTS", "MIN_SPAN_SHARE", "MIN_STILL_S"]

MIN_COUNTS = 8.0
"""Expected twist (encoder counts) that must show before a still encoder is a fault: far
above the one or two counts of noise, quantisation and a stick-slip hold."""
BAND_SHARE = 0.05
MIN_STILL_S = 0.5
"""Shortest still stretch (s) that can trip: far longer than the channels' lag (~10 ms)."""
MIN_SPAN_SHARE = 0.3
"""Torque change (share of rated) that no friction hold of a reducer spans (a friction
torque of 15 % of rated is already a defective unit)."""


@dataclass
class FrozenTwistWatch:
    """See the module docstring. Angles in deg, torques in N*m, stiffness N*m/arcmin."""

    counts_per_rev: float
    rated_torque_Nm: float
    stiffness_Nm_per_arcmin: float | None = None
    play_arcmin: float | None = None
    device: str = "encoder"

    def __post_init__(self) -> None:
        self.count_arcmin = 360.0 * 60.0 / self.counts_per_rev
        self.band_Nm = BAND_SHARE * self.rated_torque_Nm
        self.reset()

    def reset(self) -> None:
        """Forget the stretch (a new run, or after a pause)."""
        self._ref: float | None = None
        self._t0 = 0.0
        self._lo = math.inf
        self._hi = -math.inf

    def expected_counts(self) -> float:
        """The twist (counts) the torque range of the still stretch should have made."""
        if self._ref is None or not math.isfinite(self._lo):
            return 0.0
        arcmin = 0.0
        if self.stiffness_Nm_per_arcmin:
            arcmin += (self._hi - self._lo) / self.stiffness_Nm_per_arcmin
        if self.play_arcmin and self._lo < -self.band_Nm and self._hi > self.band_Nm:
            arcmin += self.play_arcmin
        return arcmin / self.count_arcmin

    def update(self, rows: Iterable[tuple[float, float, float]]) -> str | None:
        """Feed ``(t_s, torque_Nm, output_angle_deg)`` rows; a fault message, or None."""
        half_count_deg = 0.5 * 360.0 / self.counts_per_rev
        for t, torque, angle in rows:
            if not (math.isfinite(torque) and math.isfinite(angle)):
                continue
            if self._ref is None or abs(angle - self._ref) > half_count_deg:
                self._ref, self._t0 = angle, t
                self._lo = self._hi = torque
                continue
            self._lo = min(self._lo, torque)
            self._hi = max(self._hi, torque)
            expected = self.expected_counts()
            crossed = self._lo < -self.band_Nm and self._hi > self.band_Nm
            spanned = self._hi - self._lo >= MIN_SPAN_SHARE * self.rated_torque_Nm
            if expected >= MIN_COUNTS and t - self._t0 >= MIN_STILL_S and (crossed or spanned):
                return (f"{self.device}: expected the output twist to follow the torque "
                        f"({self._lo:+.3g} .. {self._hi:+.3g} N*m: at least "
                        f"{expected:.0f} counts), got the same position for "
                        f"{t - self._t0:.2f} s: a frozen encoder reading, not a measurement")
        return None
