"""Safety interlocks of the engine: the torque limit, checked before a plan runs (every
commanded torque) and while it runs (every commanded and every measured torque)."""

from __future__ import annotations

from rig.core.errors import RigError
from rig.plans.steps import Ramp, Step, StepTwist, TurnInput


class PlanRejected(RigError):
    """A plan cannot run on this rig (a torque beyond the limit, a missing device ...)."""


class TorqueLimitExceeded(RigError):
    """A torque beyond the configured limit was commanded (refused) or measured (tripped)."""


def commanded_torques(step: Step) -> list[float]:
    """The torques (N*m) a step may command."""
    if isinstance(step, Ramp):
        return [step.target_Nm]
    if isinstance(step, StepTwist):
        return [step.limit_Nm]
    if isinstance(step, TurnInput):
        return [step.brake_command_Nm]
    return []


def check_command(torque_Nm: float, limit_Nm: float) -> float:
    """``torque_Nm`` as a float if finite and within +-``limit_Nm``, else TorqueLimitExceeded."""
    value = float(torque_Nm)
    if not (abs(value) <= limit_Nm):  # also refuses NaN
        raise TorqueLimitExceeded(
            f"commanded torque {torque_Nm!r} N*m refused: the limit is +-{limit_Nm:g} N*m"
        )
    return value


def check_measured(torque_Nm: float, trip_Nm: float, channel: str) -> str | None:
    """The trip reason if a measured torque (N*m) is beyond ``trip_Nm``, else None."""
    if abs(torque_Nm) > trip_Nm:
        return (f"torque limit: {channel} measured {torque_Nm:+.4g} N*m, beyond the trip level "
                f"+-{trip_Nm:g} N*m")
    return None


def preflight(steps: list[Step], limit_Nm: float, *, has_input_motor: bool,
              has_climate: bool, has_input_encoder: bool = True) -> None:
    """Refuse a plan before anything moves: torques beyond ``limit_Nm`` or steps the rig
    cannot do. The message names the step (1-based) and what is wrong."""
    from rig.plans.steps import LockInput, SetAmbient, WaitTemperature, describe

    problems: list[str] = []
    for i, step in enumerate(steps, start=1):
        for torque in commanded_torques(step):
            if not abs(torque) <= limit_Nm:
                problems.append(f"step {i} ({describe(step)}): {torque:+g} N*m is beyond the "
                                f"torque limit +-{limit_Nm:g} N*m")
        if isinstance(step, LockInput) and not has_input_motor:
            problems.append(f"step {i} ({describe(step)}): the rig has no input motor "
                            "([input_motor] in the rig configuration)")
        if isinstance(step, TurnInput) and not (has_input_motor and has_input_encoder):
            problems.append(f"step {i} ({describe(step)}): a transmission error run needs an "
                            "input motor and an input encoder ([input_motor], "
                            "[input_encoder] in the rig configuration)")
        if isinstance(step, SetAmbient | WaitTemperature) and not has_climate:
            problems.append(f"step {i} ({describe(step)}): the rig has no climate chamber "
                            "([climate] in the rig configuration)")
        if len(problems) >= 5:
            break
    if problems:
        raise PlanRejected("plan refused before it ran: " + "; ".join(problems))
