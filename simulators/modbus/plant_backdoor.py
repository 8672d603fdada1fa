"""A small deterministic plant to feed the Modbus faces in tests and stand-alone runs.

This is test input, not a model of a gear unit (that is ``simulators/plant/__init__.py``,
``GearPlant``). It implements the :class:`simulators.plant.api.Plant` protocol with
closed-form signals, so tests can check the numbers that come over the wire:

- with the drive disabled, the sensor torque is ``offset + amplitude * sin(2 pi f t)`` (N*m);
- with the drive enabled, the transmitted torque is the commanded torque (an ideal drive),
  and the sensor adds ``offset``;
- the output angle is ``torque / stiffness`` (deg), the input angle is where it was locked.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

from simulators.clock import Clock, MonotonicClock
from simulators.plant.api import PlantSnapshot


@dataclass
class SineTestPlant:
    """Closed-form plant: a sine torque while idle, the commanded torque while driven.

    Units: ``amplitude_Nm`` and ``offset_Nm`` in N*m, ``frequency_Hz`` in Hz,
    ``stiffness_Nm_per_deg`` in N*m/deg, ``temperature_C`` in deg C.
    """

    amplitude_Nm: float = 1.0
    frequency_Hz: float = 0.5
    offset_Nm: float = 0.0
    stiffness_Nm_per_deg: float = 100.0
    temperature_C: float = 20.0
    clock: Clock | None = None

    def __post_init__(self) -> None:
        self._clock: Clock = self.clock or MonotonicClock()
        self._lock = threading.Lock()
        self._command_Nm = 0.0
        self._enabled = False
        self._input_deg = 0.0
        self.commands: list[tuple[float, float]] = []  # (t_s, torque_Nm) as commanded

    def true_torque_at(self, t_s: float) -> float:
        """Torque transmitted at ``t_s`` (N*m) with the present drive state."""
        if self._enabled:
            return self._command_Nm
        return self.amplitude_Nm * math.sin(2.0 * math.pi * self.frequency_Hz * t_s)

    def snapshot(self) -> PlantSnapshot:
        with self._lock:
            t_s = self._clock.now_s()
            true_Nm = self.true_torque_at(t_s)
            return PlantSnapshot(
                t_s=t_s,
                output_angle_deg=true_Nm / self.stiffness_Nm_per_deg,
                input_angle_deg=self._input_deg,
                torque_Nm=true_Nm + self.offset_Nm,
                true_torque_Nm=true_Nm,
                temperature_C=self.temperature_C,
                torque_command_Nm=self._command_Nm,
                drive_enabled=self._enabled,
            )

    def command_torque(self, torque_Nm: float) -> None:
        with self._lock:
            self._command_Nm = float(torque_Nm)
            self.commands.append((self._clock.now_s(), self._command_Nm))

    def enable_drive(self, enabled: bool) -> None:
        with self._lock:
            self._enabled = bool(enabled)
            if not enabled:
                self._command_Nm = 0.0

    def lock_input_at(self, angle_deg: float) -> None:
        with self._lock:
            self._input_deg = float(angle_deg)
