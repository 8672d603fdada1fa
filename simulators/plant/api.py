"""The narrow interface between the plant model and the protocol faces.

The protocol faces (Modbus server, CANopen encoder node, serial transducer) never reach into
the plant's internals: they read a :class:`PlantSnapshot` and send commands through
:class:`Plant`. The plant advances itself to its clock's time on every call and is
thread-safe (faces run on their own threads or event loops).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol


@dataclass(frozen=True)
class PlantSnapshot:
    """What the rig's sensors would see at time ``t_s`` (s).

    Angles in deg (absolute, unwrapped), torques in N*m, temperature in deg C. The sensor
    values include the plant's sensor effects (noise, torque offset); encoder quantisation is
    applied by the encoder face from its resolution.
    """

    t_s: float
    output_angle_deg: float
    input_angle_deg: float
    torque_Nm: float  # what the torque sensor/transducer reads (offset and noise included)
    true_torque_Nm: float  # torque actually transmitted through the unit
    temperature_C: float
    torque_command_Nm: float
    drive_enabled: bool


class Plant(Protocol):
    """A simulated gear unit on the rig, as the protocol faces see it."""

    def snapshot(self) -> PlantSnapshot:
        """Advance to the clock's time and return the sensors' view."""
        ...

    def command_torque(self, torque_Nm: float) -> None:
        """Set the loading drive's torque setpoint (N*m); the drive limits it itself."""
        ...

    def enable_drive(self, enabled: bool) -> None:
        """Enable or disable the loading drive (disabled: zero torque)."""
        ...

    def lock_input_at(self, angle_deg: float) -> None:
        """Turn the eccentric shaft (input) to ``angle_deg`` and lock it there."""
        ...
