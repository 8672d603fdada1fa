"""Merging the rig's channels onto one time base (pure; no threads, no devices).

How the channels are aligned (docs/campaigns.md, "Acquisition"):

- The **output encoder is the master clock**: one merged row per output-encoder sample
  (CiA 406 TPDO on every SYNC, 1 kHz on the simulated rig). Times are host
  ``time.monotonic()`` seconds (the encoder's receive times, which python-can stamps on the
  ``time.time()`` scale, are shifted onto it by the device adapter).
- **Torque** (the transducer stream, e.g. 500 Hz) is **interpolated linearly** at each encoder
  time between the two transducer samples around it. A row is emitted only once a torque
  sample at or after its time has arrived, so no value is extrapolated; encoder samples
  older than the first torque sample are dropped (the stream starts first).
- The optional **input encoder** is interpolated the same way (held at its last value when it
  is older than the output sample: the input is locked during a loop).
- **Temperature** (housing, polled about once a second) is the latest value read.
- The Modbus torque sensor is not merged: it is the cross-check channel (the engine compares
  it with the transducer and trips on either exceeding the torque limit).

Timestamp error: the times given to the merger come from the devices' clocks
(:mod:`rig.engine.steady_clock`, applied in :class:`rig.engine.devices.DevicesIO`), so a busy
PC's receive delays are removed; what remains is the transport's delay variation (~0.1-1
ms). At the plans' torque rates (<= 50 N*m/s) 1 ms is < 0.05 N*m, and the settled points of
an equal-torque loop do not move at all.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass


@dataclass(frozen=True)
class MergedRow:
    """One row on the master clock: host monotonic time (s), torque (N*m), output and input
    angles (deg; input NaN if absent) and housing temperature (deg C, NaN if absent)."""

    t_mono_s: float
    torque_Nm: float
    output_angle_deg: float
    input_angle_deg: float
    temperature_C: float


class _Series:
    """A time-ordered series with linear interpolation; old points are trimmed."""

    def __init__(self) -> None:
        self.t: deque[float] = deque()
        self.v: deque[float] = deque()

    def add(self, t: float, v: float) -> None:
        if self.t and t <= self.t[-1]:
            return  # a repeated or out-of-order stamp: keep the first (monotonic series)
        self.t.append(t)
        self.v.append(v)

    @property
    def last_t(self) -> float:
        return self.t[-1] if self.t else -math.inf

    def at(self, t: float, hold: bool) -> float:
        """Value at ``t`` (linear between neighbours); before the first point NaN; after the
        last the last value if ``hold`` else NaN."""
        if not self.t or t < self.t[0]:
            return math.nan
        if t >= self.t[-1]:
            return self.v[-1] if (hold or t == self.t[-1]) else math.nan
        ts = self.t
        i = bisect.bisect_right(ts, t)  # ts[i-1] <= t < ts[i]
        t0, t1 = ts[i - 1], ts[i]
        v0, v1 = self.v[i - 1], self.v[i]
        return v0 + (v1 - v0) * (t - t0) / (t1 - t0)

    def exact(self, t: float) -> float | None:
        """The value stamped exactly ``t`` (the same SYNC), None if there is none."""
        ts = self.t
        i = bisect.bisect_left(ts, t)
        if i < len(ts) and ts[i] == t:
            return self.v[i]
        return None

    def trim_before(self, t: float) -> None:
        """Drop points no longer needed for interpolation at times >= ``t``."""
        while len(self.t) > 2 and self.t[1] <= t:
            self.t.popleft()
            self.v.popleft()


class ChannelMerger:
    """Collects the channels' samples and emits :class:`MergedRow`s on the encoder's clock."""

    def __init__(self) -> None:
        self._output: deque[tuple[float, float]] = deque()
        self._torque = _Series()
        self._input = _Series()
        self._temperature = math.nan
        self.dropped_before_torque = 0
        self.wait_input = False
        """A transmission error run (the input turns): a row only once an input-encoder
        sample at or after its time has come, and only with the input sample of the same
        time (both encoders answer the same SYNC and get its send time, see
        rig.engine.devices): interpolating between samples whose times came from another
        clock would err by a part of a sample period of motion. Rows without one are
        counted in ``unpaired`` and left out."""
        self.unpaired = 0
        self._last_paired_t = -math.inf

    def add_output(self, t_s: float, angle_deg: float) -> None:
        self._output.append((t_s, angle_deg))

    def add_torque(self, t_s: float, torque_Nm: float) -> None:
        self._torque.add(t_s, torque_Nm)

    def add_input(self, t_s: float, angle_deg: float) -> None:
        self._input.add(t_s, angle_deg)

    def set_temperature(self, celsius: float) -> None:
        self._temperature = float(celsius)

    @property
    def pending(self) -> int:
        """Encoder samples waiting for a later torque sample."""
        return len(self._output)

    def pop_rows(self) -> list[MergedRow]:
        """Every row whose torque can now be interpolated, oldest first."""
        rows: list[MergedRow] = []
        out = self._output
        last_torque = self._torque.last_t
        if self.wait_input:
            last_torque = min(last_torque, self._input.last_t)
        while out and out[0][0] <= last_torque:
            t, angle = out.popleft()
            torque = self._torque.at(t, hold=False)
            if math.isnan(torque):
                self.dropped_before_torque += 1
                continue
            if self.wait_input:
                value = self._input.exact(t)
                if value is not None and t - self._last_paired_t < 1e-5:
                    value = None  # a time moved on by 1 us (rig.engine.devices._in_order):
                    # two samples given one SYNC's time, at least one of them wrongly
                if value is None:  # no input sample of this SYNC: a gap, not a guess
                    self.unpaired += 1
                    continue
            else:
                value = self._input.at(t, hold=True)
            if self.wait_input:
                self._last_paired_t = t
            rows.append(MergedRow(t, torque, angle, value, self._temperature))
        if rows:
            self._torque.trim_before(rows[-1].t_mono_s)
            self._input.trim_before(rows[-1].t_mono_s)
        return rows


@dataclass(frozen=True)
class ControlState:
    """What the engine was doing at an instant: torque setpoint (N*m), 1-based plan step,
    and 1 inside a Sample step (else 0)."""

    setpoint_Nm: float
    step: int
    sample_window: int
    direction: int = 0
    """A transmission error run: +1 while the input turns forward and is recorded, -1 in
    reverse, 0 otherwise."""


class ControlLog:
    """The engine's control state over time (host monotonic s), so that each merged row gets
    the state in force when it was *measured*, not when a busy PC got round to merging it
    (a row merged 0.5 s late was given the setpoint of 0.5 s later: the loop's branches,
    split on the command, then began and ended at other samples; issue 21 item 11)."""

    def __init__(self, keep_s: float = 60.0) -> None:
        self.keep_s = float(keep_s)
        self._t: deque[float] = deque()
        self._states: deque[ControlState] = deque()

    def set(self, t_s: float, state: ControlState) -> None:
        """``state`` holds from ``t_s`` (host monotonic s; times never go back)."""
        if self._states and self._states[-1] == state:
            return
        if self._t and t_s < self._t[-1]:
            t_s = self._t[-1]
        self._t.append(t_s)
        self._states.append(state)
        while len(self._t) > 1 and self._t[1] < t_s - self.keep_s:
            self._t.popleft()
            self._states.popleft()

    def at(self, t_s: float) -> ControlState | None:
        """The state in force at ``t_s`` (the earliest kept before the log; None if empty)."""
        if not self._t:
            return None
        i = bisect.bisect_right(self._t, t_s) - 1
        return self._states[max(i, 0)]
