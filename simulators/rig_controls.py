"""Simulated input motor and climate chamber, served on the rig's Modbus server.

A real rig turns the eccentric shaft (input) to a measuring position with a motor and locks
it; a heater or climate chamber sets the housing temperature. Here both are device models
fed by the plant (``GearPlant.lock_input_at`` and ``set_ambient_temperature``), laid out by
the register maps of ``drivers/rig_controls.py``, and served as two more units (3 and 4 by
default) of the same pymodbus server as the torque sensor and the loading drive
(:class:`RigModbusServer`), so the backdoor of ``simulators/modbus/backdoor.py`` covers them
too. Writes the device refuses return a Modbus exception code.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import partial
from typing import Protocol

from pymodbus.constants import ExcCodes
from pymodbus.simulator import DataType, SimData, SimDevice

from drivers.modbus.map import Register, float_from_words
from drivers.rig_controls import (
    CLIMATE_DEVICE_ID,
    CLIMATE_MAP,
    CLIMATE_RANGE_C,
    INPUT_MOTOR_DEVICE_ID,
    INPUT_MOTOR_MAP,
    InputMotorCommand,
    InputMotorStatus,
)
from simulators.modbus.devices import register_image
from simulators.modbus.server import ModbusRigServer
from simulators.plant.api import Plant

ARRIVED_DEG = 1e-6
"""The input counts as at its target (and LOCKED) within this many deg."""

_DATATYPES = {"uint16": DataType.UINT16, "uint32": DataType.UINT32,
              "float32": DataType.FLOAT32}


class ClimatePlant(Plant, Protocol):
    """A plant whose ambient/heater setpoint can be set (``GearPlant`` is one)."""

    def set_ambient_temperature(self, celsius: float) -> None: ...


def _split_write(register_map: dict[str, Register], address: int, words: Sequence[int]
                 ) -> dict[str, list[int]] | ExcCodes:
    """Holding-register write -> {name: words}; a partial multi-word value is refused."""
    regs = {r.address: r for r in register_map.values() if r.table == "holding"}
    out: dict[str, list[int]] = {}
    pos, end = address, address + len(words)
    while pos < end:
        reg = regs.get(pos)
        if reg is None or reg.end > end:
            return ExcCodes.ILLEGAL_ADDRESS
        out[reg.name] = list(words[pos - address:reg.end - address])
        pos = reg.end
    return out


class InputMotorModel:
    """Positions the plant's input: a LOCK_AT_TARGET command turns it to ``target`` (deg);
    TURN_AT_SPEED turns it at ``speed`` (rpm, signed) until STOP (the plant's
    ``turn_input``/``stop_input``). Backdoor for tests: :meth:`stall` (the shaft stops while
    the motor goes on reporting TURNING) and :meth:`overspeed` (it turns ``factor`` times
    the commanded speed)."""

    def __init__(self, plant: Plant, max_speed_rpm: float = 3000.0) -> None:
        self.plant = plant
        self.target_deg = plant.snapshot().input_angle_deg
        self.commanded_deg = self.target_deg
        self.fault = False
        self.max_speed_rpm = float(max_speed_rpm)
        self.speed_rpm = 0.0
        self.turning = False
        self.stalled = False
        self.speed_factor = 1.0

    def stall(self, on: bool = True) -> None:
        """Backdoor: the input shaft stops (a jammed unit or motor) while the motor goes on
        reporting TURNING at its setpoint; off: it turns again if it was turning."""
        self.stalled = bool(on)
        self._apply()

    def overspeed(self, factor: float = 1.5) -> None:
        """Backdoor: the input turns ``factor`` times the commanded speed (a runaway)."""
        self.speed_factor = float(factor)
        self._apply()

    def _apply(self) -> None:
        turn = getattr(self.plant, "turn_input", None)
        if turn is None or not self.turning:
            return
        turn(0.0 if self.stalled else 6.0 * self.speed_rpm * self.speed_factor)

    def _actual_rpm(self) -> float:
        speed = getattr(self.plant, "input_speed_deg_per_s", None)
        return 0.0 if speed is None else speed() / 6.0

    def input_words(self) -> list[int]:
        angle = self.plant.snapshot().input_angle_deg
        if self.turning:
            status = InputMotorStatus.TURNING | InputMotorStatus.MOVING
        else:
            arrived = abs(angle - self.commanded_deg) <= ARRIVED_DEG
            status = InputMotorStatus.LOCKED if arrived else InputMotorStatus.MOVING
        if self.fault:
            status = InputMotorStatus.FAULT
        return register_image(INPUT_MOTOR_MAP, "input", {
            "angle": angle, "target_actual": self.commanded_deg, "status": int(status),
            "speed_actual": self._actual_rpm()})

    def holding_words(self) -> list[int]:
        return register_image(INPUT_MOTOR_MAP, "holding", {
            "target": self.target_deg, "command": int(InputMotorCommand.NONE),
            "speed": self.speed_rpm})

    def write_holding(self, address: int, words: Sequence[int]) -> ExcCodes | None:
        parts = _split_write(INPUT_MOTOR_MAP, address, words)
        if isinstance(parts, ExcCodes):
            return parts
        if "target" in parts:
            value = float_from_words(parts["target"])
            if not math.isfinite(value):
                return ExcCodes.ILLEGAL_VALUE
            self.target_deg = value
        if "speed" in parts:
            speed = float_from_words(parts["speed"])
            if not (math.isfinite(speed) and abs(speed) <= self.max_speed_rpm):
                return ExcCodes.ILLEGAL_VALUE
            self.speed_rpm = speed
        if "command" in parts:
            command = parts["command"][0]
            if command in (InputMotorCommand.LOCK_AT_TARGET,
                           InputMotorCommand.TURN_AT_SPEED) and self.fault:
                return ExcCodes.DEVICE_FAILURE
            if command == InputMotorCommand.LOCK_AT_TARGET:
                self.turning = False
                self.commanded_deg = self.target_deg
                self.plant.lock_input_at(self.target_deg)
            elif command == InputMotorCommand.TURN_AT_SPEED:
                if getattr(self.plant, "turn_input", None) is None:
                    return ExcCodes.ILLEGAL_FUNCTION
                self.turning = True
                self._apply()
            elif command == InputMotorCommand.STOP:
                self.turning = False
                stop = getattr(self.plant, "stop_input", None)
                held = stop() if stop is not None else self.plant.snapshot().input_angle_deg
                self.commanded_deg = self.target_deg = float(held)
            elif command != InputMotorCommand.NONE:
                return ExcCodes.ILLEGAL_VALUE
        return None


class ClimateModel:
    """The ambient/heater setpoint (deg C) the plant's housing temperature follows."""

    def __init__(self, plant: ClimatePlant, setpoint_C: float) -> None:
        self.plant = plant
        self.setpoint_C = float(setpoint_C)

    def input_words(self) -> list[int]:
        return register_image(CLIMATE_MAP, "input", {
            "housing_temperature": self.plant.snapshot().temperature_C,
            "setpoint_actual": self.setpoint_C})

    def holding_words(self) -> list[int]:
        return register_image(CLIMATE_MAP, "holding", {"setpoint": self.setpoint_C})

    def write_holding(self, address: int, words: Sequence[int]) -> ExcCodes | None:
        parts = _split_write(CLIMATE_MAP, address, words)
        if isinstance(parts, ExcCodes):
            return parts
        value = float_from_words(parts["setpoint"])
        lo, hi = CLIMATE_RANGE_C
        if not (math.isfinite(value) and lo <= value <= hi):
            return ExcCodes.ILLEGAL_VALUE
        self.setpoint_C = value
        self.plant.set_ambient_temperature(value)
        return None


def _simdata(register_map: dict[str, Register], table: str) -> list[SimData]:
    return [SimData(r.address, values=0.0 if r.datatype == "float32" else 0,
                    datatype=_DATATYPES[r.datatype], readonly=r.access == "r")
            for r in sorted(register_map.values(), key=lambda r: r.address)
            if r.table == table]


class RigModbusServer(ModbusRigServer):
    """The rig's Modbus server: torque sensor (1), loading drive (2), input motor (3) and
    climate chamber (4) as units of one pymodbus server (one RS-485 line or TCP port).

    Arguments as :class:`simulators.modbus.server.ModbusRigServer`, plus the two unit ids
    and ``ambient_C`` (deg C), the chamber's initial setpoint.
    """

    def __init__(self, plant: ClimatePlant, torque_limit_Nm: float, *,
                 input_motor_id: int = INPUT_MOTOR_DEVICE_ID,
                 climate_id: int = CLIMATE_DEVICE_ID, ambient_C: float = 20.0,
                 input_max_speed_rpm: float = 3000.0, **options) -> None:
        super().__init__(plant, torque_limit_Nm, **options)
        ids = {self.sensor_id, self.drive_id, input_motor_id, climate_id}
        if len(ids) != 4:
            raise ValueError("the four Modbus unit ids must differ, got sensor "
                             f"{self.sensor_id}, drive {self.drive_id}, input motor "
                             f"{input_motor_id}, climate {climate_id}")
        self.input_motor_id, self.climate_id = input_motor_id, climate_id
        self.input_motor = InputMotorModel(plant, input_max_speed_rpm)
        self.climate = ClimateModel(plant, ambient_C)

    def _devices(self) -> list[SimDevice]:
        # ModbusRigServer builds its two units here; the two more ride on the same hook and
        # on its ``_action`` (backdoor faults, live register images, writes to the model).
        unused = [SimData(0, values=[False] * 16, datatype=DataType.BITS)]
        extra = [
            SimDevice(id=unit, simdata=(unused, list(unused), _simdata(m, "holding"),
                                        _simdata(m, "input")),
                      action=partial(self._action, model, unit))
            for unit, m, model in ((self.input_motor_id, INPUT_MOTOR_MAP, self.input_motor),
                                   (self.climate_id, CLIMATE_MAP, self.climate))
        ]
        return [*super()._devices(), *extra]
