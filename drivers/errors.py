"""Device errors. Every message names the device, what was expected and what came."""

from __future__ import annotations


class DeviceError(Exception):
    """A device did not behave as expected.

    ``device`` names it (e.g. ``"encoder node 5 on slcan socket://127.0.0.1:15030"``),
    ``expected`` says what the driver waited for and ``got`` what came instead.
    """

    def __init__(self, device: str, expected: str, got: str) -> None:
        self.device = device
        self.expected = expected
        self.got = got
        super().__init__(f"{device}: expected {expected}, got {got}")


class DeviceTimeout(DeviceError):
    """Nothing (or not enough) came within the timeout."""


class DeviceProtocolError(DeviceError):
    """Something came, but it is not what the protocol allows."""


class DeviceDisconnected(DeviceError):
    """The link to the device is gone (port closed, socket reset, heartbeat lost)."""


class DeviceOutOfRange(DeviceError):
    """A value outside the limits the driver knows (e.g. a setpoint above the torque limit)."""


class DeviceFault(DeviceError):
    """The device reports a fault of its own (fault code, error reply, exception response)."""
