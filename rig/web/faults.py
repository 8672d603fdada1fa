"""Faults in plain words: what stopped the rig and what the operator should do.

The engine's stopping reasons name the device, what was expected and what came
(drivers/errors.py); :func:`explain` puts a short headline and an action in front of that
text for the page. The first rule whose words all occur in the reason (case-insensitive) wins.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class Fault:
    """``title``: what happened, in a few words; ``action``: what to do; ``detail``: the
    engine's own message (device, expected, got)."""

    title: str
    action: str
    detail: str

    def to_dict(self) -> dict[str, str]:
        return asdict(self)


RULES: tuple[tuple[tuple[str, ...], str, str], ...] = (
    (("e-stop",), "E-stop pressed: the drive is off and the torque is zero",
     "Check the unit and the fixture. The rig is safe; start a new run when ready."),
    (("aborted by the operator",), "Stopped by the operator: the drive is off",
     "The samples measured so far are kept in the store as an aborted run."),
    (("watchdog",), "The loading drive stopped itself (communication watchdog)",
     "The drive heard nothing from this PC for too long. Check the Modbus cable or network "
     "and that the PC is not overloaded, then start again."),
    (("heartbeat",), "An encoder stopped answering (heartbeat lost)",
     "Check the CAN cable, its termination and the encoder's power, then start again."),
    (("torque limit",), "Torque beyond the limit: stopped to protect the unit",
     "Lower the amplitude or the rated torque of the plan, or check the torque sensor's "
     "zero (tare) before starting again."),
    (("refused", "the limit is"), "A torque beyond the limit was refused: nothing moved there",
     "Lower the amplitude or the rated torque of the plan."),
    (("beyond",), "A reading went beyond its allowed range",
     "Check the sensor named below and the plan's limits, then start again."),
    (("torque transducer",), "The torque transducer did not answer as expected",
     "Check the transducer's serial cable and power; tare it when the unit is unloaded."),
    (("encoder",), "An encoder did not answer as expected",
     "Check the CAN cable and the encoder named below, then start again."),
    (("input motor",), "The input could not be locked",
     "Check the input motor and its brake; confirm the input lock again before starting."),
    (("climate",), "The climate chamber did not reach or report the temperature",
     "Check the chamber and its setpoint, or run without temperatures."),
    (("loading drive",), "The loading drive reported a fault",
     "Read the drive's fault code below, clear its cause, then start again."),
    (("timeout",), "A device did not answer in time",
     "Check the cable and power of the device named below, then start again."),
)


def explain(reason: str | None) -> Fault | None:
    """The plain-words fault for an engine stopping reason (None for no reason)."""
    if not reason:
        return None
    low = reason.lower()
    for words, title, action in RULES:
        if all(w in low for w in words):
            return Fault(title, action, reason)
    return Fault("The measurement stopped", "Read the message below, fix its cause, then "
                 "start again. The samples so far are kept in the store.", reason)
