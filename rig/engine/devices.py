"""The engine's view (:class:`rig.engine.io.RigIO`) of the opened drivers (:class:`RigDevices`).

Time bases: the transducer, Modbus and input-motor drivers stamp samples with host
``time.monotonic()``; python-can stamps CAN frames on the ``time.time()`` scale, so encoder
samples are shifted by ``time.time() - time.monotonic()`` (taken at each call, a few us of
jitter) onto the monotonic scale.

Those are arrival times, late by whatever a busy PC adds. The streamed channels are given
the times of their devices' clocks instead (:class:`rig.engine.steady_clock.SteadyClock`):
the transducer's device time of each line; for an encoder on the SYNC this program produces,
the send time of the SYNC each PDO answers; for an encoder on its event timer (or a SYNC from
elsewhere), its sample number times its period.
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from typing import Any

from drivers.errors import DeviceError, DeviceFault, DeviceProtocolError
from drivers.transducer.protocol import DEVICE_TIME_MODULO_S
from rig.engine.steady_clock import SteadyClock, SyncClock
from rig.hardware.devices import RigDevices

MAX_BAD_LINES_IN_A_ROW = 10
log = logging.getLogger(__name__)


class DevicesIO:
    """Implements :class:`rig.engine.io.RigIO` over :class:`rig.hardware.devices.RigDevices`."""

    def __init__(self, devices: RigDevices) -> None:
        if devices.encoder is None or devices.transducer is None or devices.drive is None:
            missing = [n for n in ("encoder", "transducer", "drive") if getattr(devices, n) is None]
            raise DeviceFault("rig", "an output encoder, a torque transducer and a loading "
                              "drive to measure with", f"missing: {', '.join(missing)}")
        self.devices = devices
        self.description = f"rig {devices.config.rig.rig_id} ({devices.config.source})"
        self.has_input_encoder = devices.input_encoder is not None
        self.has_input_motor = devices.input_motor is not None
        self.has_climate = devices.climate is not None
        self._bad_lines = 0
        self._commanding = False
        self._turning = False
        self._torque_clock = SteadyClock(modulo_s=DEVICE_TIME_MODULO_S)
        self._output_clock = SteadyClock()
        self._input_clock = SteadyClock()
        self._last_t: dict[str, float] = {}  # the latest time given per channel (s)
        self._output_sync = SyncClock(devices.encoder.config.sync_every)
        self._input_sync = SyncClock(devices.input_encoder.config.sync_every
                                     if devices.input_encoder is not None else 1)

    @property
    def torque_limit_Nm(self) -> float:
        """The rig's torque limit (N*m): the frozen configuration's within the drive's."""
        return self.devices.torque_limit_Nm

    @staticmethod
    def _can_to_monotonic() -> float:
        return time.time() - time.monotonic()

    def sensors_meta(self) -> dict[str, Any]:
        d = self.devices
        meta: dict[str, Any] = {
            "encoder_counts_per_rev": d.encoder.identity().counts_per_rev,
            "torque_full_scale_Nm": d.transducer.config.full_scale_Nm,
            "output_encoder": d.encoder.device,
            "torque_transducer": d.transducer.device,
            "stream_rate_Hz": d.transducer.config.stream_rate_Hz,
        }
        if d.encoder.period_s is not None:
            meta["encoder_period_s"] = d.encoder.period_s
        if d.input_encoder is not None:
            meta["input_encoder"] = d.input_encoder.device
            meta["input_encoder_counts_per_rev"] = d.input_encoder.identity().counts_per_rev
        if d.torque_sensor is not None:
            meta["crosscheck_torque_sensor"] = d.torque_sensor.name
        return meta

    def start_acquisition(self) -> None:
        self.devices.encoder.readings()  # drop samples from before the plan
        if self.devices.input_encoder is not None:
            self.devices.input_encoder.readings()
        self.devices.transducer.start_stream()

    def stop_acquisition(self) -> None:
        with contextlib.suppress(DeviceError, OSError, RuntimeError):
            self.devices.transducer.stop_stream()

    def samples_dropped(self) -> int:
        """Encoder samples the drivers had to drop (full queues) since they opened."""
        total = self.devices.encoder.dropped
        if self.devices.input_encoder is not None:
            total += self.devices.input_encoder.dropped
        return total

    def take_output(self) -> list[tuple[float, float]]:
        return self._encoder_samples("output", self.devices.encoder, self._output_clock,
                                     self._output_sync)

    def take_input(self) -> list[tuple[float, float]]:
        enc = self.devices.input_encoder
        if enc is None:
            return []
        return self._encoder_samples("input", enc, self._input_clock, self._input_sync)

    def _in_order(self, channel: str, t: float) -> float:
        """``t``, or just after the channel's previous time: a better estimate of the smallest
        delay can move the times back by less than a period, and a channel's times must rise."""
        t = max(t, self._last_t.get(channel, -math.inf) + 1e-6)
        self._last_t[channel] = t
        return t

    def _encoder_samples(self, channel: str, encoder: Any, clock: SteadyClock,
                         sync: SyncClock) -> list[tuple[float, float]]:
        """(t_s, angle_deg) of the new samples (module doc): the send time of the SYNC each
        answers; else sample number x period on the encoder's steady clock; else the receive
        time."""
        shift = self._can_to_monotonic()
        readings = encoder.readings()
        period = encoder.period_s
        network = encoder.network
        ours = (encoder.config.transmission == "sync"
                and network.config.sync_period_s is not None)
        syncs = list(network.sync_log) if ours and readings else []
        out = []
        for r in readings:
            arrival = r.t_s - shift
            t = sync.stamp(r.seq, arrival, syncs) if syncs else None
            if t is None:
                t = clock.stamp(r.seq * period, arrival) if period else arrival
            out.append((self._in_order(channel, t), r.angle_deg))
        return out

    def take_torque(self, timeout_s: float) -> list[tuple[float, float]]:
        try:
            r = self.devices.transducer.next_reading(timeout_s)
        except DeviceProtocolError:
            self._bad_lines += 1  # a garbled line: the stream goes on, unless it keeps failing
            if self._bad_lines >= MAX_BAD_LINES_IN_A_ROW:
                raise
            return []
        self._bad_lines = 0
        t = self._torque_clock.stamp(r.device_t_s, r.t_s)
        if t <= self._last_t.get("torque", -math.inf):
            return []  # a repeated device time (a frozen or re-sent line): no new sample
        self._last_t["torque"] = t
        return [(t, r.torque_Nm)]

    def read_temperature(self) -> float | None:
        climate = self.devices.climate
        return None if climate is None else climate.state().housing_C

    def read_crosscheck_torque(self) -> float | None:
        sensor = self.devices.torque_sensor
        return None if sensor is None else sensor.read().torque_Nm

    def set_torque(self, torque_Nm: float) -> None:
        self.devices.drive.set_torque(torque_Nm)

    def enable_drive(self) -> None:
        self.devices.drive.enable()
        self._commanding = True

    def safe_state(self) -> None:
        self._commanding = False
        drive_safe = self.devices.safe_state()
        if self._turning:  # a transmission error run: the input stops too
            self._turning = False
            motor = self.devices.input_motor
            try:
                if motor is not None:
                    motor.stop()
            except DeviceError as exc:
                log.error("input motor stop not confirmed: %s", exc)
        if not drive_safe:
            raise DeviceFault(self.devices.drive.name, "the safe state confirmed",
                              "no reply (the drive watchdog disables it)")

    def turn_input(self, speed_rpm: float) -> None:
        motor = self.devices.input_motor
        if motor is None:
            raise DeviceFault("input motor", "an input motor to turn the input", "none")
        self._turning = True
        motor.turn_at(speed_rpm)

    def stop_input(self) -> None:
        motor = self.devices.input_motor
        if motor is None:
            return
        motor.stop()
        self._turning = False

    def alive(self) -> None:
        self.devices.alive()

    def check(self) -> None:
        d = self.devices
        d.encoder.check()
        if d.input_encoder is not None:
            d.input_encoder.check()
        status = d.drive.status()
        if status.faulted:
            raise DeviceFault(d.drive.name, "no latched drive fault",
                              f"fault {int(status.fault_code)} {status.fault_code.name}")
        if self._commanding and not status.enabled:
            # fault-matrix row 2: the commanded torque can no longer be reached; whatever
            # the loop measures from here is not the unit's
            raise DeviceFault(d.drive.name, "the power stage enabled while the rig commands "
                              f"torque ({status.setpoint_Nm:+.3g} N*m)",
                              "disabled by someone else (another Modbus master, the drive's "
                              "panel or its enable input): interlock, the run is incomplete")

    def lock_input(self, angle_deg: float, timeout_s: float) -> float:
        motor = self.devices.input_motor
        if motor is None:
            raise DeviceFault("input motor", "an input motor to lock the input", "none")
        return motor.lock_at(angle_deg, timeout_s).angle_deg

    def set_ambient(self, celsius: float) -> None:
        climate = self.devices.climate
        if climate is None:
            raise DeviceFault("climate chamber", "a climate chamber", "none")
        climate.set_temperature(celsius)
