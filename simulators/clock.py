"""Clocks for the simulators: the real monotonic clock, or a manual one tests can step."""

from __future__ import annotations

import threading
import time
from typing import Protocol


class Clock(Protocol):
    """Anything that tells the simulation time in seconds."""

    def now_s(self) -> float: ...


class MonotonicClock:
    """Wall-clock time (time.monotonic) counted from construction, in s."""

    def __init__(self) -> None:
        self._t0 = time.monotonic()

    def now_s(self) -> float:
        return time.monotonic() - self._t0

    def at_monotonic(self, t_mono_s: float) -> float:
        """This clock's time (s) at host ``time.monotonic()`` time ``t_mono_s`` (s)."""
        return t_mono_s - self._t0


class ManualClock:
    """A clock that moves only when told to: deterministic tests of the plant."""

    def __init__(self, t_s: float = 0.0) -> None:
        self._t = float(t_s)
        self._lock = threading.Lock()

    def now_s(self) -> float:
        with self._lock:
            return self._t

    def advance(self, dt_s: float) -> float:
        """Move time forward by ``dt_s`` seconds and return the new time."""
        if dt_s < 0:
            raise ValueError(f"a clock cannot go back (dt_s={dt_s})")
        with self._lock:
            self._t += dt_s
            return self._t
