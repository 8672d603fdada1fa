"""Duration estimate of a plan: walk its steps, tracking the torque setpoint and input angle.

Each step's expected time (s): a ramp |dT| / rate; a settle its ``hold_s`` (at least
``min_s``), a dwell or sample its length; the torque zero a ramp to zero plus its window; an
input move |d angle| / ``input_speed_deg_per_s`` plus ``lock_s``; a temperature wait its
``expected_s``; equal-position steps their ramp plus ``expected_steps`` settles and dwells.
The engine adds its own overhead (bench/bench_sequencer.py measures it).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from rig.core.errors import RigError
from rig.core.ranges import plan_duration_problem
from rig.plans.steps import (
    BeginRun,
    Dwell,
    LockInput,
    Ramp,
    ReadTorqueZero,
    Sample,
    Settle,
    Step,
    StepTwist,
    TurnInput,
    WaitTemperature,
)


@dataclass
class PlanEstimate:
    """Expected duration (s) of a plan and of each step, the number of runs and the time
    spent dwelling (s: settles, dwells, samples, torque zeros)."""

    total_s: float = 0.0
    dwell_s: float = 0.0
    n_steps: int = 0
    n_runs: int = 0
    step_s: list[float] = field(default_factory=list)

    def remaining_s(self, done_steps: int) -> float:
        """Expected time left after ``done_steps`` steps (s)."""
        return float(sum(self.step_s[done_steps:]))


def _ramp_s(start: float, end: float, rate: float | None) -> float:
    return 0.0 if rate is None else abs(end - start) / rate


def estimate(steps: Iterable[Step], *, input_speed_deg_per_s: float = 360.0,
             lock_s: float = 0.2, start_torque_Nm: float = 0.0,
             start_input_deg: float = 0.0) -> PlanEstimate:
    """Walk ``steps`` and add up their expected durations (see the module docstring)."""
    out = PlanEstimate()
    torque, angle = start_torque_Nm, start_input_deg
    for step in steps:
        dt = dwell = 0.0
        match step:
            case Ramp(target_Nm=target, rate_Nm_per_s=rate):
                dt = _ramp_s(torque, target, rate)
                torque = target
            case Settle(hold_s=hold, min_s=low):
                dt = dwell = max(hold, low)
            case Dwell(seconds=s):
                dt = dwell = s
            case Sample(window_s=w):
                dt = dwell = w
            case ReadTorqueZero(window_s=w, rate_Nm_per_s=rate, settle_s=settle):
                dwell = w + settle
                dt = _ramp_s(torque, 0.0, rate) + settle + w
                torque = 0.0
            case LockInput(angle_deg=a):
                dt = _ramp_s(torque, 0.0, None) + abs(a - angle) / input_speed_deg_per_s
                dt += lock_s
                torque, angle = 0.0, a
            case WaitTemperature(expected_s=e):
                dt = dwell = e
            case StepTwist() as st:
                per_step = max(st.settle.hold_s, st.settle.min_s) + st.dwell_s + st.sample_s
                dwell = st.expected_steps * per_step
                dt = _ramp_s(torque, st.limit_Nm, st.rate_Nm_per_s) + dwell
                torque = st.limit_Nm
            case TurnInput() as turn:
                dt = (_ramp_s(torque, turn.brake_command_Nm, turn.brake_rate_Nm_per_s)
                      + turn.expected_s + 0.5)
                torque = turn.brake_command_Nm
            case BeginRun():
                out.n_runs += 1
        out.step_s.append(dt)
        out.total_s += dt
        out.dwell_s += dwell
        out.n_steps += 1
    return out


def check_duration(est: PlanEstimate, *, confirmed: bool, how: str) -> None:
    """RigError when the plan may not run for its expected duration: longer than
    :data:`rig.core.ranges.PLAN_MAX_S`, or than :data:`rig.core.ranges.PLAN_CONFIRM_S`
    unless ``confirmed`` (``how`` names the flag or key that confirms)."""
    problem = plan_duration_problem(est.total_s, confirmed, how)
    if problem is not None:
        raise RigError(problem)
