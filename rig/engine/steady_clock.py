"""Sample times from a device's steady clock instead of their arrival on a busy PC.

A sample reaches the program some time after the device took it: the transport's own delay,
plus whatever the PC adds (a receive thread waiting for the CPU, lines read in one burst and
stamped alike). That added part is what put the torque and twist channels tens of ms out of
step on a loaded PC (the lag check then made a healthy run incomplete). The device's clock
does not wait: the transducer stamps each line (device time, s), and the output encoder
answers every SYNC of a steady SYNC producer (sample number x SYNC period).

:class:`SteadyClock` maps device times onto the host clock as ``t = t_dev + f`` with ``f``
the transport's delay floor: a sample can arrive late, never early, so every sample's delay
``d_i = arrival_i - t_dev_i`` bounds the floor from above, and with the two clocks drifting
apart by at most ``drift`` (200 ppm: two crystals of +-100 ppm) the floor now is at most
``d_i + drift * (t_dev - t_dev_i)``. The smallest of those bounds over the last ``window_s``
(30 s) of device time is the estimate: the rest of a delay is the PC's, and is removed. A PC
busy for seconds (no sample read in time for a whole second, which moved a 1 s minimum by
the whole stall, 0.3-0.4 s on a loaded CI machine, and put torque and twist out of step)
now shifts the times by at most ``2 * drift`` per second of stall (0.4 ms/s). A constant lag
(a device whose stream is behind from the start) is kept: it is part of the floor, and the
analysis's lag check and the cross-check sensor still see it. The bound follows a drift of
the device clock against the host's and a lost sample or a step down of the delay at once;
a device time that goes backwards (a device restart) or jumps further than ``reset_s`` from
what the arrivals say starts afresh.

An encoder that answers the SYNC this program produces sampled when that SYNC went out, and
the SYNC producer (a thread of this program) can itself be late on a busy PC, so a grid of
sample number x period is late-blind there. :class:`SyncClock` stamps each position PDO with
the recorded send time of the SYNC it answers: PDO ``n`` answers SYNC ``c + n * every``, where
``c`` is the smallest (number of the last SYNC sent before the PDO arrived - ``n * every``)
over the last ``window`` PDOs (a PDO comes after its SYNC, and later SYNCs may have gone out
while it waited to be read, never fewer). The window (2,000 PDOs: 8 s at the simulated rig's
4 ms SYNC) must outlast a backlog: on a loaded CI machine the PDOs of a rig simulated in the
test's own process reached the engine 0.2-1.5 s late for over a second at a time, and a
window of 250 PDOs (1 s) then took the backlog for the offset, stamped the positions up to
1 s late against the torque and tripped the frozen-encoder watch on a healthy unit. The price
is a lost PDO: the stamps stay one SYNC period early until the offsets from before the loss
have left the window.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from collections.abc import Sequence

__all__ = ["SteadyClock", "SyncClock"]


class SteadyClock:
    """Host times (s) of samples from a device with a steady clock; see the module doc.

    ``modulo_s``: the device clock wraps at this many seconds (None: it never wraps).
    ``drift``: the largest rate difference of the device clock against the host's (s/s).
    """

    def __init__(self, window_s: float = 30.0, reset_s: float = 5.0,
                 modulo_s: float | None = None, drift: float = 2e-4) -> None:
        self.window_s = float(window_s)
        self.reset_s = float(reset_s)
        self.modulo_s = modulo_s
        self.drift = float(drift)
        # (t_dev, d - drift * t_dev): the bound of each sample, without the part that grows
        # with the time since (the same for every sample), smallest first
        self._bounds: deque[tuple[float, float]] = deque()
        self._wraps = 0.0
        self._last_raw = -math.inf
        self.restarts = 0

    def floor_s(self, t_dev_s: float) -> float:
        """The transport's delay floor (s) at device time ``t_dev_s`` (unwrapped), as
        bounded by the samples so far; inf before the first."""
        q = self._bounds
        return q[0][1] + self.drift * t_dev_s if q else math.inf

    def stamp(self, t_dev_s: float, arrival_s: float) -> float:
        """The host time (s) at which the device took the sample stamped ``t_dev_s`` (s,
        device clock) that arrived at ``arrival_s`` (s, host clock); never after arrival."""
        t_dev = self._unwrap(float(t_dev_s))
        delay = float(arrival_s) - t_dev
        q = self._bounds
        if q and (t_dev < q[-1][0] or abs(delay - self.floor_s(t_dev)) > self.reset_s):
            q.clear()  # the device clock went back or jumped: a restart, start afresh
            self.restarts += 1
        key = delay - self.drift * t_dev
        while q and q[-1][1] >= key:
            q.pop()
        q.append((t_dev, key))
        while q[0][0] < t_dev - self.window_s:
            q.popleft()
        return t_dev + self.floor_s(t_dev)

    def _unwrap(self, raw: float) -> float:
        m = self.modulo_s
        if m is not None and raw < self._last_raw - 0.5 * m:
            self._wraps += m
        self._last_raw = raw
        return raw + self._wraps


class SyncClock:
    """Host times (s) of an encoder's PDOs from the send times of the SYNCs they answer; see
    the module doc. ``every``: the encoder answers every n-th SYNC."""

    def __init__(self, every: int = 1, window: int = 2000) -> None:
        self.every = int(every)
        self.window = int(window)
        self._offsets: deque[tuple[int, int]] = deque()  # (PDO number, SYNC offset)

    def stamp(self, n: int, arrival_s: float, syncs: Sequence[tuple[int, float]]
              ) -> float | None:
        """The send time (s, host clock) of the SYNC that PDO number ``n`` (arrived at
        ``arrival_s``) answers, from ``syncs`` ((SYNC number, send time s), oldest first);
        None when that SYNC is no longer (or not yet) in ``syncs``."""
        if not syncs:
            return None
        i = bisect.bisect_right(syncs, arrival_s, key=lambda s: s[1]) - 1
        if i < 0:
            return None
        offset = syncs[i][0] - n * self.every
        q = self._offsets
        if q and n < q[-1][0]:
            q.clear()  # the PDO numbers started again: a new encoder session
        while q and q[-1][1] >= offset:
            q.pop()
        q.append((n, offset))
        while q[0][0] <= n - self.window:
            q.popleft()
        k = q[0][1] + n * self.every
        j = k - syncs[0][0]
        if 0 <= j < len(syncs) and syncs[j][0] == k:
            return syncs[j][1]
        return None
