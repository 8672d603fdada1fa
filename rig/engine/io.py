"""What the engine needs from the rig: a narrow interface over the devices.

:class:`RigIO` is implemented by :class:`rig.engine.devices.DevicesIO` over
:class:`rig.hardware.devices.RigDevices` (real or simulated devices over their real protocols).
Every method raises a :class:`drivers.errors.DeviceError` naming the device on a fault.
Times are host ``time.monotonic()`` seconds; units are in the names.
"""

from __future__ import annotations

from typing import Any, Protocol


class RigIO(Protocol):
    """The rig as the engine sees it."""

    description: str
    torque_limit_Nm: float
    has_input_encoder: bool
    has_input_motor: bool
    has_climate: bool

    def sensors_meta(self) -> dict[str, Any]:
        """run.json ``sensors``: encoder counts per rev, torque full scale (N*m), names."""
        ...

    def start_acquisition(self) -> None:
        """Start the streams (torque transducer stream; the encoders' PDOs run already)."""
        ...

    def stop_acquisition(self) -> None:
        """Stop the streams (best effort; never raises)."""
        ...

    def take_output(self) -> list[tuple[float, float]]:
        """New output-encoder samples (t_s, angle_deg), oldest first; never blocks."""
        ...

    def take_input(self) -> list[tuple[float, float]]:
        """New input-encoder samples (t_s, angle_deg); empty without an input encoder."""
        ...

    def samples_dropped(self) -> int:
        """Encoder samples the drivers dropped (full queues) since they opened (count)."""
        ...

    def take_torque(self, timeout_s: float) -> list[tuple[float, float]]:
        """New streamed torque samples (t_s, torque_Nm); blocks up to ``timeout_s`` for one."""
        ...

    def read_temperature(self) -> float | None:
        """Housing temperature (deg C), None if the rig cannot measure it."""
        ...

    def read_crosscheck_torque(self) -> float | None:
        """The cross-check torque sensor (N*m), None if there is none."""
        ...

    def set_torque(self, torque_Nm: float) -> None:
        """Command the loading drive's torque setpoint (N*m)."""
        ...

    def enable_drive(self) -> None: ...

    def safe_state(self) -> None:
        """Torque setpoint zero and drive disabled, at once; callable from any thread."""
        ...

    def alive(self) -> None:
        """Tell the drive keepalive that the measuring program is alive."""
        ...

    def check(self) -> None:
        """Raise the first device fault found (heartbeats, latched drive faults)."""
        ...

    def lock_input(self, angle_deg: float, timeout_s: float) -> float:
        """Turn the input to ``angle_deg`` and lock it; return the locked angle (deg)."""
        ...

    def set_ambient(self, celsius: float) -> None: ...

    def turn_input(self, speed_rpm: float) -> None:
        """Turn the input at a constant ``speed_rpm`` (rpm, signed: + forward)."""
        ...

    def stop_input(self) -> None:
        """Stop the input where it is and hold it."""
        ...
