"""Drivers of the rig's two auxiliary Modbus units: the input motor and the climate chamber.

On the rig the eccentric shaft (input) of the unit under test is turned to a measuring
position and locked there by the input motor; the housing temperature is set by a heater or
climate chamber. Both are small Modbus devices (register maps below, declared as data with
:class:`drivers.modbus.map.Register`; conventions as in ``docs/modbus.md``: 0-based
addresses, float32 high word first). ``docs/rig-config.md`` documents them for a technician.

Input motor (default unit 3):

- input registers: ``angle`` (deg, actual input angle), ``target_actual`` (deg), ``status``
  (bit 0 LOCKED: at the target and holding, bit 1 MOVING, bit 2 FAULT, bit 3 TURNING: at
  constant speed), ``speed_actual`` (rpm, signed, measured);
- holding registers: ``target`` (deg), ``command`` (1 = move to the target and lock,
  2 = turn at ``speed``, 3 = stop and hold), ``speed`` (rpm, signed: + forward, within the
  motor's range) for the transmission error test's constant-speed turn.

Climate chamber (default unit 4):

- input registers: ``housing_temperature`` (deg C, measured at the housing),
  ``setpoint_actual``;
- holding register: ``setpoint`` (deg C, the ambient/heater setpoint, within the range).
"""

from __future__ import annotations

import enum
import math
import time
from dataclasses import dataclass
from typing import Generic, TypeVar

from pydantic import Field

from drivers.errors import DeviceFault, DeviceOutOfRange, DeviceTimeout
from drivers.lifecycle import ClosedOnExit
from drivers.modbus.link import ModbusLink, ModbusLinkConfig, ReportsModbusHealth
from drivers.modbus.map import (
    Register,
    decode_flags,
    encode_float32,
    register_block,
    table_span,
    values_of,
)

INPUT_MOTOR_DEVICE_ID = 3
"""Default Modbus unit id of the input motor (eccentric shaft positioner)."""
CLIMATE_DEVICE_ID = 4
"""Default Modbus unit id of the climate chamber (housing temperature)."""

CLIMATE_RANGE_C = (-40.0, 150.0)
"""Setpoints the simulated climate chamber accepts (deg C, others get exception 3), and the
default bounds the driver sends."""


class InputMotorStatus(enum.IntFlag):
    """Input motor status word."""

    LOCKED = 0x0001  # at the target and holding it (brake on)
    MOVING = 0x0002  # turning toward the target
    FAULT = 0x0004  # drive fault: the input cannot be positioned
    TURNING = 0x0008  # turning at the commanded constant speed


class InputMotorCommand(enum.IntEnum):
    """Values of the input motor's ``command`` holding register."""

    NONE = 0
    LOCK_AT_TARGET = 1  # turn to ``target`` and lock there
    TURN_AT_SPEED = 2  # turn at ``speed`` (rpm, signed) until STOP or LOCK_AT_TARGET
    STOP = 3  # stop where it is and hold


INPUT_MOTOR_MAP: dict[str, Register] = register_block(
    Register("angle", "input", 0, "float32", "r", "deg", "actual input (eccentric) angle"),
    Register("target_actual", "input", 2, "float32", "r", "deg", "target in force"),
    Register("status", "input", 4, "uint16", "r", "-", "status word, see InputMotorStatus"),
    Register("target", "holding", 0, "float32", "rw", "deg", "input angle to lock at"),
    Register("command", "holding", 2, "uint16", "rw", "-",
             "write 1 = turn to target and lock, 2 = turn at speed, 3 = stop (reads back 0)"),
    Register("speed", "holding", 3, "float32", "rw", "rpm",
             "constant input speed for command 2, signed (+ forward)"),
    Register("speed_actual", "input", 5, "float32", "r", "rpm",
             "measured input speed, signed"),
)

CLIMATE_MAP: dict[str, Register] = register_block(
    Register("housing_temperature", "input", 0, "float32", "r", "degC",
             "temperature measured at the unit's housing"),
    Register("setpoint_actual", "input", 2, "float32", "r", "degC", "setpoint in force"),
    Register("setpoint", "holding", 0, "float32", "rw", "degC",
             "ambient/heater setpoint, within the chamber's range"),
)


class InputMotorConfig(ModbusLinkConfig):
    """Input motor link and settings; ``lock_tolerance_deg`` (deg) for :meth:`lock_at`."""

    device_id: int = Field(default=INPUT_MOTOR_DEVICE_ID, ge=1, le=247)
    lock_tolerance_deg: float = Field(default=0.01, gt=0)
    move_timeout_s: float = Field(default=30.0, gt=0)
    max_speed_rpm: float = Field(default=3000.0, gt=0)


class ClimateConfig(ModbusLinkConfig):
    """Climate chamber link; ``min_C``/``max_C`` (deg C) bound the setpoints we send."""

    device_id: int = Field(default=CLIMATE_DEVICE_ID, ge=1, le=247)
    min_C: float = CLIMATE_RANGE_C[0]
    max_C: float = CLIMATE_RANGE_C[1]


@dataclass(frozen=True)
class InputState:
    """The input motor at ``t_s`` (s, monotonic): angles in deg."""

    t_s: float
    angle_deg: float
    target_deg: float
    locked: bool
    moving: bool
    fault: bool
    turning: bool = False
    speed_rpm: float = 0.0


@dataclass(frozen=True)
class ClimateState:
    """The climate chamber at ``t_s`` (s, monotonic): temperatures in deg C."""

    t_s: float
    housing_C: float
    setpoint_C: float


ConfigT = TypeVar("ConfigT", bound=ModbusLinkConfig)
"""The link config of a Modbus unit (InputMotorConfig, ClimateConfig)."""


class _ModbusUnit(ReportsModbusHealth, ClosedOnExit, Generic[ConfigT]):
    """Shared plumbing: a name, a (possibly shared) link, reads of the input block."""

    kind = "device"
    register_map: dict[str, Register] = {}

    def __init__(self, config: ConfigT, link: ModbusLink | None = None) -> None:
        self.config: ConfigT = config
        self._own_link = link is None
        self.link = link or ModbusLink(config)
        self.name = f"{self.kind} (Modbus unit {config.device_id} on {self.link.where()})"

    def _inputs(self) -> tuple[dict[str, float | int], float]:
        first, count = table_span(self.register_map, "input")
        t0 = time.monotonic()
        words = self.link.read_input(self.name, self.config.device_id, first, count)
        t_s = 0.5 * (t0 + time.monotonic())
        return values_of(self.register_map, "input", first, words, self.name), t_s

    def _write(self, register: str, words: list[int]) -> None:
        address = self.register_map[register].address
        self.link.write(self.name, self.config.device_id, address, words)

    def close(self) -> None:
        """Close the connection (unless the link was handed in and is shared)."""
        if self._own_link:
            self.link.close()


class InputMotor(_ModbusUnit[InputMotorConfig]):
    """Turns the input (eccentric shaft) to an angle (deg) and locks it there."""

    kind = "input motor"
    register_map = INPUT_MOTOR_MAP

    def state(self) -> InputState:
        """Read angle, target and status (one FC4 request)."""
        values, t_s = self._inputs()
        bits = decode_flags(int(values["status"]), InputMotorStatus, self.name, "status")
        return InputState(t_s, float(values["angle"]), float(values["target_actual"]),
                          InputMotorStatus.LOCKED in bits, InputMotorStatus.MOVING in bits,
                          InputMotorStatus.FAULT in bits, InputMotorStatus.TURNING in bits,
                          float(values["speed_actual"]))

    def turn_at(self, speed_rpm: float) -> None:
        """Turn the input at a constant ``speed_rpm`` (rpm, signed: + forward): speed and
        command in one FC16 request; does not wait. Beyond ``max_speed_rpm``:
        DeviceOutOfRange, not sent."""
        value = float(speed_rpm)
        limit = self.config.max_speed_rpm
        if not (math.isfinite(value) and abs(value) <= limit):
            raise DeviceOutOfRange(self.name, f"an input speed within +-{limit:g} rpm",
                                   f"{speed_rpm!r} rpm (refused, not sent)")
        address = self.register_map["command"].address
        self.link.write(self.name, self.config.device_id, address,
                        [int(InputMotorCommand.TURN_AT_SPEED), *encode_float32(value)])

    def stop(self) -> None:
        """Stop the input where it is and hold it (command 3)."""
        self._write("command", [int(InputMotorCommand.STOP)])

    def start_lock_at(self, angle_deg: float) -> None:
        """Send the target (deg) and the lock command in one FC16 request; do not wait."""
        value = float(angle_deg)
        if not math.isfinite(value):
            raise DeviceOutOfRange(self.name, "a finite input angle (deg)", f"{angle_deg!r}")
        self._write("target", [*encode_float32(value), int(InputMotorCommand.LOCK_AT_TARGET)])

    def lock_at(self, angle_deg: float, timeout_s: float | None = None) -> InputState:
        """Turn to ``angle_deg`` (deg), lock, and wait (at most ``timeout_s``) for LOCKED."""
        self.start_lock_at(angle_deg)
        wait = self.config.move_timeout_s if timeout_s is None else timeout_s
        deadline = time.monotonic() + wait
        while True:
            st = self.state()
            if st.fault:
                raise DeviceFault(self.name, f"the input locked at {angle_deg:g} deg",
                                  "status FAULT")
            if st.locked and abs(st.angle_deg - float(angle_deg)) <= \
                    self.config.lock_tolerance_deg:
                return st
            if time.monotonic() > deadline:
                raise DeviceTimeout(self.name, f"the input locked at {angle_deg:g} deg within "
                                    f"{wait:g} s", f"angle {st.angle_deg:.4f} deg, "
                                    f"locked={st.locked}, moving={st.moving}")
            time.sleep(0.02)

    def _health_check(self) -> tuple[bool, str]:
        """Read once; ok when the motor answers without a fault."""
        st = self.state()
        return not st.fault, f"angle {st.angle_deg:.6g} deg, locked={st.locked}, moving={st.moving}"


class ClimateChamber(_ModbusUnit[ClimateConfig]):
    """Sets the ambient/heater setpoint (deg C) and reads the housing temperature."""

    kind = "climate chamber"
    register_map = CLIMATE_MAP

    def state(self) -> ClimateState:
        """Read housing temperature and setpoint in force (one FC4 request)."""
        values, t_s = self._inputs()
        return ClimateState(t_s, float(values["housing_temperature"]),
                            float(values["setpoint_actual"]))

    def set_temperature(self, celsius: float) -> None:
        """Write the setpoint (deg C); outside [min_C, max_C]: DeviceOutOfRange, not sent."""
        value = float(celsius)
        lo, hi = self.config.min_C, self.config.max_C
        if not (math.isfinite(value) and lo <= value <= hi):
            raise DeviceOutOfRange(self.name, f"a setpoint in [{lo:g}, {hi:g}] deg C",
                                   f"{celsius!r} deg C (refused, not sent)")
        self._write("setpoint", encode_float32(value))

    def _health_check(self) -> tuple[bool, str]:
        """Read once; ok when the chamber answers."""
        st = self.state()
        return True, f"housing {st.housing_C:.4g} C, setpoint {st.setpoint_C:.4g} C"
