"""Sample times from a device's steady clock instead of their arrival on a busy PC.

A sample reaches the program some time after the device took it: the transport's own delay,
plus whatever the PC adds (a receive thread waiting for the CPU, lines read in one burst and
stamped alike). That added part is what put the torque and twist channels tens of ms out of
step on a loaded PC (the lag check then made a healthy run incomplete). The device's clock
does not wait: the transducer stamps each line (device time, s), and the output encoder
answers every SYNC of a steady SYNC producer (sample number x SYNC period).

:class:`SteadyClock` maps device times onto the host clock as
``t = t_dev + min(arrival - t_dev)`` over the last ``window_s`` of device time: a sample can
arrive late, never early, so the smallest delay seen is the transport's and the rest is the
PC's, which is removed. A constant lag (a device whose stream is behind) is kept: it is part
of the smallest delay, and the analysis's lag check still sees it. The window follows a slow
drift of the device clock against the host's (50 ppm is 50 us per second) and recovers from a
lost sample or a step within ``window_s``. A device time that goes backwards (a device
restart) or jumps further than ``reset_s`` from what the arrivals say starts afresh.
"""

from __future__ import annotations

import math
from collections import deque

__all__ = ["SteadyClock"]


class SteadyClock:
    """Host times (s) of samples from a device with a steady clock; see the module doc.

    ``modulo_s``: the device clock wraps at this many seconds (None: it never wraps).
    """

    def __init__(self, window_s: float = 1.0, reset_s: float = 5.0,
                 modulo_s: float | None = None) -> None:
        self.window_s = float(window_s)
        self.reset_s = float(reset_s)
        self.modulo_s = modulo_s
        self._delays: deque[tuple[float, float]] = deque()  # (t_dev, arrival - t_dev)
        self._wraps = 0.0
        self._last_raw = -math.inf
        self.restarts = 0

    def stamp(self, t_dev_s: float, arrival_s: float) -> float:
        """The host time (s) at which the device took the sample stamped ``t_dev_s`` (s,
        device clock) that arrived at ``arrival_s`` (s, host clock); never after arrival."""
        t_dev = self._unwrap(float(t_dev_s))
        delay = float(arrival_s) - t_dev
        q = self._delays
        if q and (t_dev < q[-1][0] or abs(delay - q[0][1]) > self.reset_s):
            q.clear()  # the device clock went back or jumped: a restart, start afresh
            self.restarts += 1
        while q and q[-1][1] >= delay:
            q.pop()
        q.append((t_dev, delay))
        while q[0][0] < t_dev - self.window_s:
            q.popleft()
        return t_dev + q[0][1]

    def _unwrap(self, raw: float) -> float:
        m = self.modulo_s
        if m is not None and raw < self._last_raw - 0.5 * m:
            self._wraps += m
        self._last_raw = raw
        return raw + self._wraps
