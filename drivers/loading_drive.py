"""Driver of the Modbus loading drive (register map: ``drivers/modbus/map.py``).

Safety, in two layers: this driver refuses any setpoint beyond its torque limit with
:class:`DeviceOutOfRange` before anything is sent, and the drive refuses it too (exception 3,
fault code 1). The effective limit is the smaller of the configured ``torque_limit_Nm`` and
the drive's own ``torque_limit`` register, read when the driver opens.

Watchdog: on open the driver writes ``watchdog_s`` into the drive. Every write (setpoint,
enable/disable, :meth:`LoadingDrive.keepalive`) feeds it; reads do not. The engine must call
``keepalive()`` (or write) more often than ``watchdog_s``; there is deliberately no
background keep-alive thread, so a hung master lets the drive fall to its safe state.
"""

from __future__ import annotations

import contextlib
import math
import time
from dataclasses import dataclass

from pydantic import ConfigDict, Field

from drivers.errors import DeviceError, DeviceFault, DeviceOutOfRange, DeviceProtocolError
from drivers.lifecycle import ClosedOnExit
from drivers.modbus.link import ModbusLink, ModbusLinkConfig, ReportsModbusHealth
from drivers.modbus.map import (
    DRIVE_DEVICE_ID,
    LOADING_DRIVE_MAP,
    DriveControl,
    DriveFaultCode,
    DriveStatusBits,
    decode_fault_code,
    decode_flags,
    encode_float32,
    table_span,
    values_of,
)

_INPUT_FIRST, _INPUT_COUNT = table_span(LOADING_DRIVE_MAP, "input")
_HOLD_FIRST, _HOLD_COUNT = table_span(LOADING_DRIVE_MAP, "holding")
_CONTROL = LOADING_DRIVE_MAP["control"].address
_SETPOINT = LOADING_DRIVE_MAP["setpoint"].address


class LoadingDriveConfig(ModbusLinkConfig):
    """Loading drive settings: ``torque_limit_Nm`` (N*m, required), ``watchdog_s`` (s)."""

    model_config = ConfigDict(frozen=True)

    device_id: int = Field(default=DRIVE_DEVICE_ID, ge=1, le=247)
    torque_limit_Nm: float = Field(gt=0, allow_inf_nan=False)
    watchdog_s: float = Field(default=0.5, ge=0.01, le=60.0)


@dataclass(frozen=True)
class DriveStatus:
    """The drive's state at ``t_s`` (s, monotonic); torques in N*m."""

    t_s: float
    enabled: bool
    fault_code: DriveFaultCode
    limit_hit: bool
    watchdog_tripped: bool
    actual_torque_Nm: float
    setpoint_Nm: float

    @property
    def faulted(self) -> bool:
        return self.fault_code != DriveFaultCode.NONE


def decode_drive_block(words: list[int], device: str, t_s: float = 0.0) -> DriveStatus:
    """The drive's input registers 0..5 -> :class:`DriveStatus` (DeviceError on bad words)."""
    values = values_of(LOADING_DRIVE_MAP, "input", _INPUT_FIRST, words, device)
    bits = decode_flags(int(values["status"]), DriveStatusBits, device, "status")
    fault = decode_fault_code(int(values["fault_code"]), device)
    if (DriveStatusBits.FAULT in bits) != (fault != DriveFaultCode.NONE):
        raise DeviceProtocolError(device, "status FAULT set exactly when fault_code != 0",
                                  f"status 0x{int(bits):04X} with fault code {int(fault)}")
    return DriveStatus(t_s, DriveStatusBits.ENABLED in bits, fault,
                       DriveStatusBits.LIMIT in bits, DriveStatusBits.WATCHDOG in bits,
                       float(values["actual_torque"]), float(values["active_setpoint"]))


class LoadingDrive(ReportsModbusHealth, ClosedOnExit):
    """A torque-controlled loading drive on Modbus; opening it sets its watchdog time."""

    def __init__(self, config: LoadingDriveConfig, link: ModbusLink | None = None) -> None:
        self.config = config
        self._own_link = link is None
        self.link = link or ModbusLink(config)
        self.name = f"loading drive (Modbus unit {config.device_id} on {self.link.where()})"
        self._keepalive = 0
        try:
            self._drive_limit_Nm = self._read_drive_limit()
            watchdog_ms = max(10, round(config.watchdog_s * 1000))
            self._write(LOADING_DRIVE_MAP["watchdog_ms"].address, [watchdog_ms])
        except DeviceError:
            self.close(safe=False)
            raise

    @property
    def drive_limit_Nm(self) -> float:
        """The drive's own ``torque_limit`` register (N*m), read when the driver opened."""
        return self._drive_limit_Nm

    @property
    def torque_limit_Nm(self) -> float:
        """The most this driver commands (N*m): the configured limit within the drive's own.
        Read-only, like the frozen configuration it comes from (fault-matrix row 13)."""
        return min(self.config.torque_limit_Nm, self._drive_limit_Nm)

    def _write(self, address: int, words: list[int]) -> None:
        self.link.write(self.name, self.config.device_id, address, words)

    def _read_drive_limit(self) -> float:
        words = self.link.read_holding(self.name, self.config.device_id, _HOLD_FIRST,
                                       _HOLD_COUNT)
        limit = float(values_of(LOADING_DRIVE_MAP, "holding", _HOLD_FIRST, words,
                                self.name)["torque_limit"])
        if not limit > 0:
            raise DeviceProtocolError(self.name, "a positive torque_limit register (N*m)",
                                      f"{limit}")
        return limit

    def _explain_fault(self, exc: DeviceFault) -> DeviceFault:
        """Add the drive's latched fault code to an exception reply, if it can be read."""
        try:
            fault = self.status().fault_code
        except DeviceError:
            return exc
        return DeviceFault(self.name, exc.expected,
                           f"{exc.got}; drive fault code {int(fault)} {fault.name}")

    def set_torque(self, torque_Nm: float) -> None:
        """Command ``torque_Nm`` (N*m). Beyond the limit: DeviceOutOfRange, nothing sent."""
        value = float(torque_Nm)
        if not math.isfinite(value) or abs(value) > self.torque_limit_Nm:
            raise DeviceOutOfRange(self.name,
                                   f"a setpoint within +-{self.torque_limit_Nm:g} N*m",
                                   f"{torque_Nm!r} N*m (refused, not sent)")
        try:
            self._write(_SETPOINT, encode_float32(value))
        except DeviceFault as exc:
            raise self._explain_fault(exc) from exc

    def enable(self) -> None:
        """Switch the power stage on (refused by the drive while a fault is latched)."""
        try:
            self._write(_CONTROL, [int(DriveControl.ENABLE)])
        except DeviceFault as exc:
            raise self._explain_fault(exc) from exc

    def disable(self) -> None:
        """Switch the power stage off (zero torque)."""
        self._write(_CONTROL, [0])

    def reset_fault(self) -> None:
        """Clear a latched fault; the drive stays disabled with setpoint 0."""
        self._write(_CONTROL, [int(DriveControl.FAULT_RESET)])

    def safe_state(self) -> None:
        """Disable and set the setpoint to 0 in one request (FC16 on control + setpoint).

        Idempotent and accepted even with a fault latched. If it raises, the drive could not
        be reached: its watchdog will bring it to the same state within ``watchdog_s``.
        """
        self._write(_CONTROL, [0, *encode_float32(0.0)])

    def keepalive(self) -> None:
        """Feed the drive's communication watchdog (writes a rolling counter)."""
        self._keepalive = (self._keepalive + 1) & 0xFFFF
        self._write(LOADING_DRIVE_MAP["keepalive"].address, [self._keepalive])

    def status(self) -> DriveStatus:
        """Read status word, fault code, actual torque and setpoint in force (one FC4)."""
        t0 = time.monotonic()
        words = self.link.read_input(self.name, self.config.device_id, _INPUT_FIRST,
                                     _INPUT_COUNT)
        return decode_drive_block(words, self.name, 0.5 * (t0 + time.monotonic()))

    def _health_check(self) -> tuple[bool, str]:
        """The status once: ok when the drive answers and no fault is latched."""
        st = self.status()
        return not st.faulted, (f"enabled={st.enabled}, fault {int(st.fault_code)} "
                                f"{st.fault_code.name}, actual {st.actual_torque_Nm:.6g} N*m")

    def close(self, safe: bool = True) -> None:
        """Leave the drive safe (best effort, see :meth:`safe_state`) and close the link."""
        if safe:
            with contextlib.suppress(DeviceError):  # unreachable: the watchdog takes over
                self.safe_state()
        if self._own_link:
            self.link.close()
