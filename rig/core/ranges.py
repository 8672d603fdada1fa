"""The physical ranges of every number that enters the rig: one table, used by every entry.

Campaign files, the rig configuration, ``rig import``'s maps and files, the CLI's options and
the page's models take their bounds from here, so a value is checked once where it enters
and every refusal reads alike: ``key: expected from 0.001 to 100000 N·m/s (got 1e-300)``. The
bounds come from the physics of a precision reducer test rig; they are wide enough for any
real unit and narrow enough that no plan or reading built from them overflows:

- torques (N·m): a rated torque or a torque limit above 0 and at most 1e7 (the largest
  wind-turbine gearboxes carry a few MN·m); a torque reading at most
  :data:`TORQUE_READING_MAX_RATED` x the rated torque in magnitude (beyond: an overload
  or a corrupt cell);
- loading rates 1e-3 to 1e5 N·m/s; dwells 0 to 3600 s (an hour's creep hold); settling and
  sampling windows up to 600 s; twist steps and settle rates 1e-3 to 600 arcmin(/s);
- angles (deg): an input locking position within ten turns either way (+-3600); an encoder
  reading within +-1e9 deg (2.8 million turns; a multi-turn encoder holds fewer);
- temperatures (°C): a chamber setpoint or limit -40 to 150 (the climate chamber's range),
  a housing reading -100 to 300; tolerances up to 20 °C, waits up to a day;
- transmission error: input speed 1 to 6000 rpm (below 1 rpm one output revolution of a
  100:1 unit takes more than 100 min);
- the rig configuration: a SYNC period 1 ms to 60 s (shorter floods the CAN bus), a bus's
  ``sleep_after_open`` 0 to 10 s, the master timeout up to an hour, device timeouts up to
  an hour, the input motor's speed up to 10000 rpm;
- pass/fail limits: lost motion, backlash and TE hysteresis up to 10000 arcmin, TE
  peak-to-peak up to 1e6 arcsec, stiffness up to 1e9 N·m/arcmin;
- a plan's expected duration: beyond :data:`PLAN_CONFIRM_S` (8 h, a shift) it runs only
  when confirmed, beyond :data:`PLAN_MAX_S` (30 days) never.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Any


@dataclass(frozen=True)
class Range:
    """A closed range ``low .. high`` in ``unit`` (``low_open``: ``low`` itself excluded)."""

    low: float
    high: float
    unit: str
    low_open: bool = False

    def text(self) -> str:
        """``from 0.001 to 1e+05 N·m/s`` or ``greater than 0 and at most 1e+07 N·m``."""
        unit = f" {self.unit}" if self.unit else ""
        if self.low_open:
            return f"greater than {self.low:g} and at most {self.high:g}{unit}"
        return f"from {self.low:g} to {self.high:g}{unit}"

    def contains(self, value: Any) -> bool:
        """Is ``value`` a finite real number inside the range (a bool is no number)?"""
        if isinstance(value, bool) or not isinstance(value, int | float):
            return False
        if not math.isfinite(value):
            return False
        above = value > self.low if self.low_open else value >= self.low
        return above and value <= self.high

    def problem(self, key: str, value: Any) -> str | None:
        """One line naming ``key``, the range and the value; None inside the range."""
        if self.contains(value):
            return None
        return f"{key}: expected {self.text()} (got {value!r})"

    def _check(self, value: float) -> float:
        if not self.contains(value):
            raise ValueError(f"expected {self.text()}")
        return value

    def schema(self) -> dict[str, float]:
        """The OpenAPI/JSON schema bounds."""
        low = {"exclusiveMinimum": self.low} if self.low_open else {"minimum": self.low}
        return {**low, "maximum": self.high}

    @property
    def type(self) -> Any:
        """A pydantic float type checked against the range (its bounds in the schema)."""
        return self.after()

    def after(self, *first: Any) -> Any:
        """:attr:`type` with the pydantic metadata ``first`` checked before the range."""
        from pydantic import AfterValidator, Field  # here: the CLI's options import no pydantic

        return Annotated[float, *first, AfterValidator(self._check),
                         Field(json_schema_extra=self.schema())]


# -- torques (N·m) -------------------------------------------------------------------------
RATED_TORQUE_NM = Range(0.0, 1e7, "N·m", low_open=True)
TORQUE_LIMIT_NM = Range(0.0, 1e7, "N·m", low_open=True)
ZERO_BAND_NM = Range(0.0, 1e7, "N·m")
TORQUE_READING_MAX_RATED = 1000.0
"""A torque reading beyond this multiple of the rated torque is no reading (a sensor overload
or a corrupt cell), whatever its sign: nothing in a run may rest on it."""

# -- loading -------------------------------------------------------------------------------
RATE_NM_PER_S = Range(1e-3, 1e5, "N·m/s")
DWELL_S = Range(0.0, 3600.0, "s")
SETTLE_HOLD_S = Range(1e-3, 600.0, "s")
SETTLE_TIMEOUT_S = Range(1e-2, 3600.0, "s")
SAMPLE_S = Range(0.0, 600.0, "s")
WINDOW_S = Range(1e-3, 600.0, "s")
TWIST_STEP_ARCMIN = Range(1e-3, 600.0, "arcmin")
SETTLE_RATE_ARCMIN_PER_S = Range(1e-3, 600.0, "arcmin/s")

# -- angles (deg) --------------------------------------------------------------------------
POSITION_DEG = Range(-3600.0, 3600.0, "deg")
ANGLE_READING_DEG = Range(-1e9, 1e9, "deg")

# -- temperatures (°C) and waits -----------------------------------------------------------
TEMPERATURE_SETPOINT_C = Range(-40.0, 150.0, "°C")
TEMPERATURE_READING_C = Range(-100.0, 300.0, "°C")
TEMPERATURE_TOLERANCE_C = Range(0.0, 20.0, "°C", low_open=True)
TEMPERATURE_TIMEOUT_S = Range(0.0, 86_400.0, "s", low_open=True)

# -- transmission error --------------------------------------------------------------------
INPUT_SPEED_RPM = Range(1.0, 6000.0, "rpm")

# -- the rig configuration -----------------------------------------------------------------
SYNC_PERIOD_S = Range(1e-3, 60.0, "s")
SLEEP_AFTER_OPEN_S = Range(0.0, 10.0, "s")
MASTER_TIMEOUT_S = Range(0.0, 3600.0, "s", low_open=True)
DEVICE_TIMEOUT_S = Range(0.0, 3600.0, "s", low_open=True)
MOTOR_SPEED_RPM = Range(0.0, 10_000.0, "rpm", low_open=True)
LOCK_TOLERANCE_DEG = Range(0.0, 10.0, "deg", low_open=True)

# -- pass/fail limits ----------------------------------------------------------------------
LIMIT_ARCMIN = Range(0.0, 10_000.0, "arcmin", low_open=True)
LIMIT_STIFFNESS_NM_PER_ARCMIN = Range(0.0, 1e9, "N·m/arcmin", low_open=True)
LIMIT_ARCSEC = Range(0.0, 1e6, "arcsec", low_open=True)

# -- model and statistics commands (rig batch, rig model, rig montecarlo, rig rotor, ...) ----
BAND_PCT = Range(0.0, 100.0, "% of rated", low_open=True)
BATCH_UNITS = Range(1, 1_000_000, "units")
"""rig batch: a million units take about 90 s and 300 MB on a 2-core PC; memory grows
linearly."""
MONTE_CARLO_SAMPLES = Range(2, 10_000_000, "samples")
"""rig montecarlo draws in chunks: ten million samples take about 80 MB and 13 min."""
WINDOW_REVS = Range(0.0, 100.0, "output revolutions", low_open=True)
SHAFT_FRACTION = Range(0.0, 1.0, "of the shaft's length")
SHAFT_ELEMENTS = Range(1, 96, "elements")
"""rig rotor: 24 elements converge; 96 take about 3 min on a 2-core PC (the eigen solves)."""
SEED = Range(0, 2**63 - 1, "")
PORT = Range(0, 65_535, "")
SIM_SYNC_PERIOD_S = Range(5e-4, 1.0, "s")
STREAM_RATE_HZ = Range(1.0, 100_000.0, "Hz")
ALPHA = Range(1e-6, 0.5, "")
INDEX_DEG = Range(-360.0, 360.0, "deg")

# -- a plan's duration (s) -----------------------------------------------------------------
PLAN_CONFIRM_S = 8 * 3600.0
"""A plan expected to take longer than this (a shift) runs only when confirmed."""
PLAN_MAX_S = 30 * 86_400.0
"""No plan runs longer than this (30 days), confirmed or not."""


def plan_duration_problem(total_s: float, confirmed: bool, how: str) -> str | None:
    """Why a plan of ``total_s`` (s) may not run: beyond :data:`PLAN_MAX_S`, or beyond
    :data:`PLAN_CONFIRM_S` without confirmation (``how`` says how to confirm); None if it
    may."""
    hours = total_s / 3600.0
    if not math.isfinite(total_s) or total_s > PLAN_MAX_S:
        return (f"the plan would take about {hours:.3g} h, more than the most a plan may "
                f"take ({PLAN_MAX_S / 86_400:g} days): fewer runs, or faster loading")
    if total_s > PLAN_CONFIRM_S and not confirmed:
        return (f"the plan would take about {hours:.3g} h, more than "
                f"{PLAN_CONFIRM_S / 3600:g} h: confirm it with {how}, or shorten it")
    return None
