"""Device models of the Modbus torque sensor and loading drive (no protocol code here).

Each model keeps the device's state and turns it into register images laid out by
``drivers/modbus/map.py``; the protocol face (``simulators/modbus/server.py``) copies those
images into the pymodbus ``SimDevice`` on every request and hands writes back here. A write
that the device refuses returns a Modbus exception code (``pymodbus.constants.ExcCodes``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence

from pymodbus.constants import ExcCodes

from drivers.modbus.map import (
    LOADING_DRIVE_MAP,
    TORQUE_SENSOR_MAP,
    WATCHDOG_MS_RANGE,
    DriveControl,
    DriveFaultCode,
    DriveStatusBits,
    Register,
    SensorCommand,
    SensorStatus,
    Table,
    encode_float32,
    encode_uint32,
    float_from_words,
    table_span,
)
from simulators.plant.api import Plant

SENSOR_CONVERSION_RATE_HZ = 1000.0
"""Internal conversion rate of the simulated sensor: its ``sample_counter`` counts at this."""


def register_image(register_map: dict[str, Register], table: Table,
                   values: dict[str, float | int]) -> list[int]:
    """Words of ``table`` from address 0 to its end, filled from ``values`` (by name)."""
    first, count = table_span(register_map, table)
    words = [0] * (first + count)
    for reg in register_map.values():
        if reg.table != table:
            continue
        value = values[reg.name]
        if reg.datatype == "float32":
            chunk = encode_float32(float(value))
        elif reg.datatype == "uint32":
            chunk = encode_uint32(int(value))
        else:
            chunk = [int(value) & 0xFFFF]
        words[reg.address:reg.end] = chunk
    return words


def _writes(register_map: dict[str, Register], address: int,
            words: Sequence[int]) -> list[tuple[Register, list[int]]] | ExcCodes:
    """Split a holding-register write into whole values; partial multi-word writes refused."""
    out: list[tuple[Register, list[int]]] = []
    pos = address
    end = address + len(words)
    regs = sorted((r for r in register_map.values() if r.table == "holding"),
                  key=lambda r: r.address)
    while pos < end:
        reg = next((r for r in regs if r.address == pos), None)
        if reg is None or reg.end > end:
            return ExcCodes.ILLEGAL_ADDRESS
        out.append((reg, list(words[pos - address:reg.end - address])))
        pos = reg.end
    return out


class TorqueSensorModel:
    """A strain-gauge torque sensor reading the plant's torque, with a device-side tare.

    The reading is ``plant torque_Nm - tare_offset`` (N*m). ``stuck`` (a backdoor fault)
    freezes the whole input image, sample counter included, as a hung sensor would.
    """

    def __init__(self, plant: Plant, full_scale_Nm: float) -> None:
        self.plant = plant
        self.full_scale_Nm = float(full_scale_Nm)
        self.tare_offset_Nm = 0.0
        self.stuck = False
        self.fault = False
        self._frozen: list[int] | None = None

    def input_words(self) -> list[int]:
        if self.stuck and self._frozen is not None:
            return list(self._frozen)
        snap = self.plant.snapshot()
        torque = snap.torque_Nm - self.tare_offset_Nm
        status = SensorStatus.VALID
        if abs(torque) > self.full_scale_Nm:
            status |= SensorStatus.OVERLOAD
        if self.tare_offset_Nm != 0.0:
            status |= SensorStatus.TARED
        if self.fault:
            status = (status & ~SensorStatus.VALID) | SensorStatus.FAULT
        words = register_image(TORQUE_SENSOR_MAP, "input", {
            "torque": torque,
            "status": int(status),
            "sample_counter": int(snap.t_s * SENSOR_CONVERSION_RATE_HZ),
            "full_scale": self.full_scale_Nm,
        })
        self._frozen = words
        return words

    def holding_words(self) -> list[int]:
        return register_image(TORQUE_SENSOR_MAP, "holding", {
            "command": int(SensorCommand.NONE), "tare_offset": self.tare_offset_Nm})

    def write_holding(self, address: int, words: Sequence[int]) -> ExcCodes | None:
        parts = _writes(TORQUE_SENSOR_MAP, address, words)
        if isinstance(parts, ExcCodes):
            return parts
        for reg, chunk in parts:
            if reg.name == "command":
                if chunk[0] == SensorCommand.TARE:
                    self.tare_offset_Nm = self.plant.snapshot().torque_Nm
                elif chunk[0] == SensorCommand.CLEAR_TARE:
                    self.tare_offset_Nm = 0.0
                elif chunk[0] != SensorCommand.NONE:
                    return ExcCodes.ILLEGAL_VALUE
            elif reg.name == "tare_offset":
                value = float_from_words(chunk)
                if not math.isfinite(value) or abs(value) > self.full_scale_Nm:
                    return ExcCodes.ILLEGAL_VALUE
                self.tare_offset_Nm = value
        return None


class LoadingDriveModel:
    """A torque-controlled loading drive with a torque limit and a communication watchdog.

    - A setpoint with ``|T| > torque_limit_Nm`` (N*m) or not finite is refused with
      exception 3 (ILLEGAL DATA VALUE); the drive latches the fault code, drops the
      setpoint to 0 and disables.
    - Enabling, or a non-zero setpoint, while a fault is latched is refused with exception 4
      (DEVICE FAILURE); setpoint 0 and disable are always accepted (the safe state).
    - Watchdog: while enabled, if no *write* (setpoint, control or keepalive) has come for
      ``watchdog_s`` (s), the drive zeroes the setpoint, disables and latches fault 2.
      Reads do not feed it, so a monitoring client cannot keep a dead master's drive alive.
      The silence is the master's, not the simulator's: a real drive has its own CPU, this
      one shares the PC. Time this process could not run (its server's periodic check,
      :meth:`note_poll`, woke late by that much) is not counted, so writes that waited in
      the socket while the simulator was starved do not trip it.
    """

    def __init__(self, plant: Plant, torque_limit_Nm: float, watchdog_s: float = 0.5,
                 now: Callable[[], float] = time.monotonic) -> None:
        if not torque_limit_Nm > 0:
            raise ValueError(f"torque_limit_Nm must be > 0, got {torque_limit_Nm}")
        self.plant = plant
        self.torque_limit_Nm = float(torque_limit_Nm)
        self.watchdog_ms = int(round(watchdog_s * 1000))
        self.now = now
        self.enabled = False
        self.setpoint_Nm = 0.0
        self.fault = DriveFaultCode.NONE
        self.limit_hit = False
        self.watchdog_tripped = False
        self.keepalive_value = 0
        self.last_write_s = now()
        self._poll_s: float | None = None  # the server's check period (s), once it polls
        self._last_poll_s = self.last_write_s
        self._stalled_s = 0.0  # this process's own stalls since the last write (s)
        self.max_write_gap_s = 0.0
        """The longest silence of the master while the drive was enabled (s): what a load
        test compares with the watchdog."""
        self.watchdog_trips = 0
        self.plant.enable_drive(False)
        self.plant.command_torque(0.0)

    # -- state changes -------------------------------------------------------------------
    def _go_safe(self) -> None:
        self.setpoint_Nm = 0.0
        self.enabled = False
        self.plant.command_torque(0.0)
        self.plant.enable_drive(False)

    def _latch(self, code: DriveFaultCode) -> None:
        self.fault = code
        self._go_safe()

    def note_poll(self, period_s: float) -> None:
        """The server's periodic check (every ``period_s`` s) ran: a wake-up later than that
        is time this process was starved, not the master's silence."""
        now = self.now()
        if self._poll_s is not None:
            self._stalled_s += max(0.0, now - self._last_poll_s - period_s)
        self._poll_s, self._last_poll_s = period_s, now
        self.check_watchdog()

    def master_silence_s(self) -> float:
        """The master's silence since its last write (s): the time since it, less this
        process's own stalls (those seen by :meth:`note_poll`, and the one it may be in now:
        the time since the last check beyond its period)."""
        now = self.now()
        pending = 0.0
        if self._poll_s is not None:
            pending = max(0.0, now - self._last_poll_s - self._poll_s)
        return max(0.0, now - self.last_write_s - self._stalled_s - pending)

    def check_watchdog(self) -> bool:
        """Trip the watchdog if the master has been silent too long; True if it tripped now."""
        silence = self.master_silence_s()
        if self.enabled and silence > self.watchdog_ms / 1000.0:
            self.watchdog_tripped = True
            self.watchdog_trips += 1
            self.max_write_gap_s = max(self.max_write_gap_s, silence)
            self._latch(DriveFaultCode.WATCHDOG_TIMEOUT)
            return True
        return False

    # -- register faces ------------------------------------------------------------------
    def stats(self) -> dict[str, float]:
        """The watchdog's figures: longest master silence while enabled (s), trips, watchdog (s)."""
        return {"drive_max_write_gap_s": self.max_write_gap_s,
                "drive_watchdog_trips": self.watchdog_trips,
                "drive_watchdog_s": self.watchdog_ms / 1000.0}

    def status_bits(self) -> DriveStatusBits:
        bits = DriveStatusBits(0)
        if self.enabled:
            bits |= DriveStatusBits.ENABLED
        if self.fault != DriveFaultCode.NONE:
            bits |= DriveStatusBits.FAULT
        if self.limit_hit:
            bits |= DriveStatusBits.LIMIT
        if self.watchdog_tripped:
            bits |= DriveStatusBits.WATCHDOG
        return bits

    def input_words(self) -> list[int]:
        self.check_watchdog()
        snap = self.plant.snapshot()
        return register_image(LOADING_DRIVE_MAP, "input", {
            "status": int(self.status_bits()),
            "fault_code": int(self.fault),
            "actual_torque": snap.true_torque_Nm if self.enabled else 0.0,
            "active_setpoint": self.setpoint_Nm if self.enabled else 0.0,
        })

    def holding_words(self) -> list[int]:
        return register_image(LOADING_DRIVE_MAP, "holding", {
            "control": int(DriveControl.ENABLE) if self.enabled else 0,
            "setpoint": self.setpoint_Nm,
            "keepalive": self.keepalive_value,
            "watchdog_ms": self.watchdog_ms,
            "torque_limit": self.torque_limit_Nm,
        })

    def write_holding(self, address: int, words: Sequence[int]) -> ExcCodes | None:
        self.check_watchdog()
        parts = _writes(LOADING_DRIVE_MAP, address, words)
        if isinstance(parts, ExcCodes):
            return parts
        now = self.now()
        if self.enabled:
            self.max_write_gap_s = max(self.max_write_gap_s, self.master_silence_s())
        self.last_write_s = now
        # the stall this write ends (if any) is counted by the next poll: only its part
        # after this write is silence to forgive
        self._stalled_s = -(max(0.0, now - self._last_poll_s - self._poll_s)
                            if self._poll_s is not None else 0.0)
        for reg, chunk in parts:
            if reg.name == "setpoint":
                value = float_from_words(chunk)
                if not math.isfinite(value):
                    self._latch(DriveFaultCode.SETPOINT_NOT_FINITE)
                    return ExcCodes.ILLEGAL_VALUE
                if abs(value) > self.torque_limit_Nm:
                    self.limit_hit = True
                    self._latch(DriveFaultCode.SETPOINT_OVER_LIMIT)
                    return ExcCodes.ILLEGAL_VALUE
                if value != 0.0 and self.fault != DriveFaultCode.NONE:
                    return ExcCodes.DEVICE_FAILURE  # no torque while a fault is latched
                self.limit_hit = False
                self.setpoint_Nm = value
                if self.enabled:
                    self.plant.command_torque(value)
            elif reg.name == "control":
                result = self._control(chunk[0])
                if result is not None:
                    return result
            elif reg.name == "keepalive":
                self.keepalive_value = chunk[0]
            elif reg.name == "watchdog_ms":
                lo, hi = WATCHDOG_MS_RANGE
                if not lo <= chunk[0] <= hi:
                    return ExcCodes.ILLEGAL_VALUE
                self.watchdog_ms = chunk[0]
            else:  # read-only values are marked readonly in the SimDevice; belt and braces
                return ExcCodes.ILLEGAL_ADDRESS
        return None

    def _control(self, word: int) -> ExcCodes | None:
        known = int(DriveControl.ENABLE) | int(DriveControl.FAULT_RESET)
        if word & ~known:
            return ExcCodes.ILLEGAL_VALUE
        if word & DriveControl.FAULT_RESET:
            self.fault = DriveFaultCode.NONE
            self.limit_hit = False
            self.watchdog_tripped = False
            self._go_safe()
            return None
        if word & DriveControl.ENABLE:
            if self.fault != DriveFaultCode.NONE:
                return ExcCodes.DEVICE_FAILURE
            if not self.enabled:
                self.enabled = True
                self.plant.enable_drive(True)
                self.plant.command_torque(self.setpoint_Nm)
            return None
        self._go_safe()
        return None
