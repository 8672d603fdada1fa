"""The steps a measurement plan is made of (plain frozen data; the engine executes them).

A plan (``rig/plans/``) is a generator of these steps, so it can be listed, previewed with
a duration estimate (:func:`rig.plans.estimate.estimate`) and executed by the engine
(``rig/engine/__init__.py``) against real or simulated devices. Units are in the field names:
torques in N*m, angles in deg, twist in arcmin, times in s, temperatures in deg C.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class BeginRun:
    """Start recording a run into the store: every sample until :class:`EndRun` goes into it.

    ``label``: a readable name (``pos090-a100-r0``); ``test``: the run.json ``test`` object
    (rated torque, locking angle, loading mode, rate and dwell ...: results depend on them).
    """

    label: str
    test: dict[str, Any] = field(default_factory=dict)
    label_from_input: bool = False
    """The plan does not set the input angle (a single run without ``--position``): the engine
    records the input angle it measures (input encoder, deg, modulo 360) as
    ``test.input_angle_deg`` and names the run after it (``pos090-...``)."""


@dataclass(frozen=True)
class EndRun:
    """Close the run begun last (completed) and analyse it."""


@dataclass(frozen=True)
class LockInput:
    """Bring the torque to zero, turn the input (eccentric shaft) to ``angle_deg`` and lock it."""

    angle_deg: float
    timeout_s: float = 60.0


@dataclass(frozen=True)
class SetAmbient:
    """Set the climate chamber's ambient/heater setpoint (deg C); does not wait."""

    temperature_C: float


@dataclass(frozen=True)
class WaitTemperature:
    """Wait until the housing temperature is within ``tolerance_C`` of ``temperature_C``.

    ``expected_s`` is only the duration estimate's guess; ``timeout_s`` aborts the plan.
    """

    temperature_C: float
    tolerance_C: float = 0.5
    timeout_s: float = 3600.0
    expected_s: float = 600.0


@dataclass(frozen=True)
class Ramp:
    """Move the torque setpoint to ``target_Nm`` at ``rate_Nm_per_s`` (constant-rate loading).

    The setpoint is updated in small increments (every ``update_s``); ``rate_Nm_per_s`` None
    sets the target in one step.
    """

    target_Nm: float
    rate_Nm_per_s: float | None = None
    update_s: float = 0.02


@dataclass(frozen=True)
class Settle:
    """Wait until the output twist rate stays below ``max_rate_arcmin_per_s`` for ``hold_s``.

    The rate is the slope (least squares) of the twist over the last ``hold_s``; at least
    ``min_s`` is waited, and ``timeout_s`` ends the wait (recorded, not an error: the run
    is kept and the analysis sees the drift).
    """

    max_rate_arcmin_per_s: float = 0.5
    hold_s: float = 0.2
    min_s: float = 0.0
    timeout_s: float = 5.0


@dataclass(frozen=True)
class Dwell:
    """Hold the present setpoint for ``seconds`` (s)."""

    seconds: float


@dataclass(frozen=True)
class Sample:
    """Mark the next ``window_s`` of samples as a settled measurement point (column
    ``sample_window`` = 1); the samples are recorded at full rate either way."""

    window_s: float = 0.2


@dataclass(frozen=True)
class StepTwist:
    """Equal-position steps toward ``limit_Nm``: raise the torque at ``rate_Nm_per_s`` until
    the twist has moved ``delta_arcmin`` (in the direction of the torque change), then settle,
    dwell ``dwell_s`` and sample ``sample_s``; repeat until the torque reaches ``limit_Nm``.

    ``expected_steps`` only feeds the duration estimate (the count depends on the unit).
    Inside |T| < ``zero_band_Nm`` the torque rises at ``zero_rate_Nm_per_s`` instead.
    """

    delta_arcmin: float
    limit_Nm: float
    rate_Nm_per_s: float
    settle: Settle = Settle()
    dwell_s: float = 0.0
    sample_s: float = 0.0
    expected_steps: int = 10
    update_s: float = 0.02
    zero_band_Nm: float = 0.0
    zero_rate_Nm_per_s: float | None = None


@dataclass(frozen=True)
class ReadTorqueZero:
    """Bring the setpoint to zero, wait ``settle_s`` and average the measured torque over
    ``window_s``: the torque zero before (``when="before"``) or after (``"after"``) a loop,
    kept with the run."""

    when: str = "before"
    window_s: float = 0.3
    rate_Nm_per_s: float | None = None
    settle_s: float = 0.1


@dataclass(frozen=True)
class TurnInput:
    """One direction of a transmission error run: hold the brake torque ``brake_torque_Nm``
    (magnitude, N*m) against the output's motion, turn the input at ``speed_rpm`` (rpm) in
    ``direction`` (+1 forward, -1 reverse), record (column ``direction``) once the input has
    turned ``lead_in_output_deg`` of output angle times ``|ratio|`` (the start transient
    excluded), until the output encoder has turned ``output_revolutions``; then stop the
    input (``direction`` 0 while it stops).

    Stops the plan (fault) on an input stall (the input encoder moves less than
    ``stall_share`` of the expected angle over ``stall_s``; the output encoder likewise: a
    frozen output), an overspeed (the input encoder's speed over ``stall_s`` beyond
    ``overspeed_factor`` times ``speed_rpm``) and an encoder count jump (the transmission
    error ``output - input / ratio`` changing by more than ``jump_tolerance_deg`` plus 1.5
    samples' output motion, output deg, from one sample to the next)."""

    speed_rpm: float
    direction: int
    brake_torque_Nm: float
    ratio: float
    output_revolutions: float = 1.0
    lead_in_output_deg: float = 10.0
    brake_rate_Nm_per_s: float = 20.0
    stall_s: float = 0.5
    stall_share: float = 0.2
    overspeed_factor: float = 1.5
    jump_tolerance_deg: float = 0.1
    timeout_factor: float = 3.0

    @property
    def brake_command_Nm(self) -> float:
        """The drive's torque (N*m): against the output, whose speed has the sign of
        ``direction / ratio``."""
        return -self.brake_torque_Nm * (1.0 if self.direction / self.ratio > 0 else -1.0)

    @property
    def expected_s(self) -> float:
        """Time to turn the lead-in and the output revolutions (s)."""
        output_deg = 360.0 * self.output_revolutions + self.lead_in_output_deg
        return output_deg * abs(self.ratio) / (6.0 * self.speed_rpm)


@dataclass(frozen=True)
class Checkpoint:
    """A safe point: the engine pauses here when asked to, and reports progress."""

    label: str = ""


Step = (
    BeginRun | EndRun | LockInput | SetAmbient | WaitTemperature | Ramp | Settle | Dwell
    | Sample | StepTwist | ReadTorqueZero | Checkpoint | TurnInput
)


def describe(step: Step) -> str:
    """One line saying what a step does (for ``rig measure --preview`` and the page)."""
    match step:
        case BeginRun(label=label):
            return f"begin run {label}"
        case EndRun():
            return "end run (analyse)"
        case LockInput(angle_deg=a):
            return f"lock input at {a:g} deg"
        case SetAmbient(temperature_C=c):
            return f"set ambient to {c:g} C"
        case WaitTemperature(temperature_C=c, tolerance_C=tol):
            return f"wait for housing {c:g} +- {tol:g} C"
        case Ramp(target_Nm=t, rate_Nm_per_s=r):
            how = "step" if r is None else f"at {r:g} N*m/s"
            return f"torque to {t:+.4g} N*m {how}"
        case Settle(max_rate_arcmin_per_s=r, timeout_s=to):
            return f"settle (twist rate < {r:g} arcmin/s, at most {to:g} s)"
        case Dwell(seconds=s):
            return f"dwell {s:g} s"
        case Sample(window_s=w):
            return f"sample {w:g} s"
        case StepTwist(delta_arcmin=d, limit_Nm=lim):
            return f"twist step {d:g} arcmin toward {lim:+.4g} N*m"
        case ReadTorqueZero(when=w):
            return f"read torque zero ({w})"
        case TurnInput() as t:
            way = "forward" if t.direction > 0 else "reverse"
            return (f"turn input {way} at {t.speed_rpm:g} rpm for {t.output_revolutions:g} "
                    f"output rev under {t.brake_command_Nm:+.4g} N*m brake torque "
                    f"(about {t.expected_s:.1f} s)")
        case Checkpoint(label=label):
            return f"checkpoint {label}".rstrip()
    raise TypeError(f"not a plan step: {step!r}")
