"""Driver of the Modbus torque sensor (register map: ``drivers/modbus/map.py``).

``ModbusTorqueSensor(config).read()`` returns a :class:`TorqueReading` (one FC4 request of
seven input registers). Timestamps are ``time.monotonic()`` seconds at the midpoint of the
request/reply exchange. Errors: see ``drivers/modbus/link.py``; in addition

- status FAULT or not VALID -> :class:`DeviceFault`;
- status OVERLOAD (|torque| beyond the sensor's full scale) -> :class:`DeviceOutOfRange`;
- the sensor's conversion counter not advancing for ``stale_after_s`` -> the sensor hangs
  and repeats a stale value -> :class:`DeviceProtocolError`;
- values the map does not allow (NaN, undefined status bits) -> :class:`DeviceProtocolError`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from pydantic import Field

from drivers.errors import DeviceFault, DeviceOutOfRange, DeviceProtocolError
from drivers.lifecycle import ClosedOnExit
from drivers.modbus.link import ModbusLink, ModbusLinkConfig, ReportsModbusHealth
from drivers.modbus.map import (
    SENSOR_DEVICE_ID,
    TORQUE_SENSOR_MAP,
    SensorCommand,
    SensorStatus,
    decode_flags,
    table_span,
    values_of,
)

_INPUT_FIRST, _INPUT_COUNT = table_span(TORQUE_SENSOR_MAP, "input")


class ModbusTorqueSensorConfig(ModbusLinkConfig):
    """Torque sensor settings; ``stale_after_s`` (s, None = off) bounds a frozen counter."""

    device_id: int = Field(default=SENSOR_DEVICE_ID, ge=1, le=247)
    stale_after_s: float | None = Field(default=1.0, gt=0)


@dataclass(frozen=True)
class TorqueReading:
    """One torque sample: ``t_s`` (s, monotonic clock), ``torque_Nm`` (N*m, tare removed)."""

    t_s: float
    torque_Nm: float
    status: SensorStatus
    sample_counter: int
    latency_s: float


def decode_torque_block(words: list[int], device: str, full_scale_Nm: float | None = None
                        ) -> tuple[float, SensorStatus, int, float]:
    """The sensor's input registers 0..6 -> (torque_Nm, status, sample_counter, full_scale_Nm).

    Raises only :class:`drivers.errors.DeviceError` subclasses (fuzzed in the tests).
    """
    values = values_of(TORQUE_SENSOR_MAP, "input", _INPUT_FIRST, words, device)
    status = decode_flags(int(values["status"]), SensorStatus, device, "status")
    torque = float(values["torque"])
    full_scale = float(values["full_scale"])
    if not full_scale > 0:
        raise DeviceProtocolError(device, "a positive full scale (N*m)", f"{full_scale}")
    if full_scale_Nm is not None and full_scale != full_scale_Nm:
        raise DeviceProtocolError(device, f"full scale {full_scale_Nm} N*m as at connect",
                                  f"{full_scale} N*m")
    if SensorStatus.FAULT in status or SensorStatus.VALID not in status:
        raise DeviceFault(device, "a valid measurement (status VALID, no FAULT)",
                          f"status 0x{int(status):04X} ({status!r})")
    if SensorStatus.OVERLOAD in status:
        raise DeviceOutOfRange(device, f"|torque| <= full scale {full_scale:g} N*m",
                               f"{torque:g} N*m (status OVERLOAD)")
    if abs(torque) > full_scale * (1 + 1e-6):
        raise DeviceProtocolError(device, "status OVERLOAD with a torque beyond full scale",
                                  f"{torque:g} N*m with status 0x{int(status):04X}")
    return torque, status, int(values["sample_counter"]), full_scale


class ModbusTorqueSensor(ReportsModbusHealth, ClosedOnExit):
    """A torque sensor on Modbus (TCP or RTU); pass ``link`` to share an RS-485 line."""

    def __init__(self, config: ModbusTorqueSensorConfig, link: ModbusLink | None = None
                 ) -> None:
        self.config = config
        self._own_link = link is None
        self.link = link or ModbusLink(config)
        self.name = f"torque sensor (Modbus unit {config.device_id} on {self.link.where()})"
        self.full_scale_Nm: float | None = None
        self._last_counter: int | None = None
        self._counter_changed_s = 0.0

    def _read_block(self) -> tuple[list[int], float, float]:
        t0 = time.monotonic()
        words = self.link.read_input(self.name, self.config.device_id, _INPUT_FIRST,
                                     _INPUT_COUNT)
        t1 = time.monotonic()
        return words, 0.5 * (t0 + t1), t1 - t0

    def read(self) -> TorqueReading:
        """One sample of the torque (N*m) with its monotonic timestamp (s)."""
        words, t_s, latency = self._read_block()
        torque, status, counter, full_scale = decode_torque_block(
            words, self.name, self.full_scale_Nm)
        self.full_scale_Nm = full_scale
        self._check_fresh(counter, t_s)
        return TorqueReading(t_s, torque, status, counter, latency)

    def _check_fresh(self, counter: int, t_s: float) -> None:
        if counter != self._last_counter:
            self._last_counter, self._counter_changed_s = counter, t_s
            return
        stale = self.config.stale_after_s
        if stale is not None and t_s - self._counter_changed_s > stale:
            raise DeviceProtocolError(
                self.name, f"the sample counter advancing within {stale} s",
                f"counter stuck at {counter} for {t_s - self._counter_changed_s:.3f} s "
                "(the sensor repeats a stale value)")

    def tare(self) -> float:
        """Zero the sensor at the present torque (device-side); return the offset (N*m)."""
        self.link.write(self.name, self.config.device_id,
                        TORQUE_SENSOR_MAP["command"].address, [SensorCommand.TARE])
        return self.tare_offset_Nm()

    def clear_tare(self) -> None:
        """Forget the tare offset (the sensor reads its raw torque again)."""
        self.link.write(self.name, self.config.device_id,
                        TORQUE_SENSOR_MAP["command"].address, [SensorCommand.CLEAR_TARE])

    def tare_offset_Nm(self) -> float:
        """The offset (N*m) the sensor subtracts, read back from the device."""
        first, count = table_span(TORQUE_SENSOR_MAP, "holding")
        words = self.link.read_holding(self.name, self.config.device_id, first, count)
        return float(values_of(TORQUE_SENSOR_MAP, "holding", first, words,
                               self.name)["tare_offset"])

    def _health_check(self) -> tuple[bool, str]:
        """One reading: ok when the sensor answers sensibly."""
        reading = self.read()
        return True, f"torque {reading.torque_Nm:.6g} N*m, status {reading.status!r}"

    def close(self) -> None:
        """Close the connection (unless the link was handed in and is shared)."""
        if self._own_link:
            self.link.close()
