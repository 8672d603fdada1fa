"""Sensor calibrations of a rig: the ``[calibration]`` section of the rig configuration, what
each run records of it, and the refusal to start with one past due.

``[calibration]`` has one table per sensor, named like the device tables (``encoder``,
``input_encoder``, ``transducer``, ``torque_sensor`` ...)::

    [calibration.transducer]
    id = "T40B-123456"            # the sensor's own identifier (serial number, asset tag)
    certificate = "DAkkS 2026-0815"
    date = 2026-01-15             # calibrated on (TOML date or "YYYY-MM-DD")
    due = 2027-01-15              # next calibration due (same forms)
    uncertainty = "0.05 % of full scale"   # text, or a number

The output encoder's table may add its mounting eccentricity found by the reversal of
docs/transmission-error.md (``eccentricity_arcsec``, ``eccentricity_phase_deg``,
``eccentricity_u_arcsec``; ``rig te-calibrate``), which every TE run then subtracts.

A run records them in run.json as ``calibration``: a list of ``{"sensor", "id",
"certificate", "date", "due", "uncertainty"}`` (dates ISO text; the store's index and the
certificate read this shape). A calibration whose ``due`` date is before the day a
measurement starts is *expired*: the measurement is refused (:class:`CalibrationExpired`)
unless an override reason is given; the override is then recorded in run.json as
``calibration_override`` (``reason``, ``operator``, ``time`` UTC, and the ``expired``
messages).
"""

from __future__ import annotations

import datetime as dt
import math
from typing import Annotated, Any

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, model_validator

from rig.core.errors import RigError


class CalibrationExpired(RigError):
    """A sensor's calibration is past due and no override was given (the message says which
    sensor, its due date, and how to override)."""


def _iso_date(value: Any) -> Any:
    """A TOML date, or ISO text ``YYYY-MM-DD``; a date with a time is no calibration date."""
    if isinstance(value, dt.datetime):
        raise ValueError(f"must be a date (YYYY-MM-DD) without a time, got {value.isoformat()}")
    if isinstance(value, str):
        try:
            return dt.date.fromisoformat(value.strip())
        except ValueError:
            raise ValueError("must be an ISO date (YYYY-MM-DD)") from None
    return value


def _uncertainty(value: Any) -> Any:
    """Text, or a finite number (a boolean is neither)."""
    if isinstance(value, bool) or not isinstance(value, str | int | float):
        raise ValueError("must be text (\"0.05 % FS\") or a number")
    if isinstance(value, str) and not value.strip():
        raise ValueError("must not be empty")
    if not isinstance(value, str) and not math.isfinite(value):
        raise ValueError("must be a finite number")
    return float(value) if isinstance(value, int) else value


IsoDate = Annotated[dt.date, BeforeValidator(_iso_date)]


class CalibrationEntry(BaseModel):
    """One sensor's calibration: its ``id``, the ``certificate`` reference, the ``date`` it was
    calibrated and the ``due`` date of the next one, and its ``uncertainty`` (text such as
    "0.05 % FS", or a number in the sensor's unit)."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)

    id: str = Field(min_length=1, max_length=200)
    certificate: str = Field(min_length=1, max_length=200)
    date: IsoDate
    due: IsoDate
    uncertainty: Annotated[str | float, BeforeValidator(_uncertainty)]
    eccentricity_arcsec: float | None = Field(None, ge=0, allow_inf_nan=False)
    """Output encoder only: its mounting eccentricity's once-per-turn error (arcsec), by the
    reversal of docs/transmission-error.md; subtracted from every TE run."""
    eccentricity_phase_deg: float | None = Field(None, allow_inf_nan=False)
    eccentricity_u_arcsec: float | None = Field(None, ge=0, allow_inf_nan=False)

    @model_validator(mode="after")
    def _due_after_date(self) -> CalibrationEntry:
        if self.due < self.date:
            raise ValueError(f"due ({self.due.isoformat()}) is before date "
                             f"({self.date.isoformat()})")
        return self

    def record(self, sensor: str) -> dict[str, Any]:
        """The run.json entry of this sensor (dates as ISO text; the eccentricity keys only
        when set)."""
        out: dict[str, Any] = {"sensor": sensor, "id": self.id, "certificate": self.certificate,
                               "date": self.date.isoformat(), "due": self.due.isoformat(),
                               "uncertainty": self.uncertainty}
        for key in ("eccentricity_arcsec", "eccentricity_phase_deg", "eccentricity_u_arcsec"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        return out


Calibrations = dict[Annotated[str, Field(pattern=r"^[a-z][a-z0-9_]{0,39}$")], CalibrationEntry]
"""The ``[calibration]`` section: sensor name -> its calibration."""


def today_utc() -> dt.date:
    """The UTC date now (the store dates runs in UTC)."""
    return dt.datetime.now(dt.UTC).date()


def calibration_records(calibrations: Calibrations) -> list[dict[str, Any]]:
    """run.json ``calibration``: one entry per sensor, in the configuration's order."""
    return [entry.record(sensor) for sensor, entry in calibrations.items()]


def expired(calibrations: Calibrations, day: dt.date | None = None) -> list[str]:
    """One message per sensor whose calibration is due before ``day`` (default: today UTC)."""
    day = day or today_utc()
    return [f"calibration of {sensor} ({entry.id}, certificate {entry.certificate}) expired "
            f"on {entry.due.isoformat()}" for sensor, entry in calibrations.items()
            if entry.due < day]


def calibration_meta(calibrations: Calibrations, override: str | None = None,
                     operator: str | None = None, *, day: dt.date | None = None,
                     how: str = "--calibration-override REASON") -> dict[str, Any]:
    """The run.json keys of the rig's calibrations: ``calibration`` and, when one is expired
    and ``override`` (a reason) is given, ``calibration_override``. Raises
    :class:`CalibrationExpired` when one is expired and no reason is given (``how`` says how
    to give one)."""
    meta: dict[str, Any] = {}
    if calibrations:
        meta["calibration"] = calibration_records(calibrations)
    late = expired(calibrations, day)
    reason = (override or "").strip()
    if late and not reason:
        raise CalibrationExpired(
            "; ".join(late) + f": a measurement with an expired calibration needs an explicit "
            f"override ({how}), which is recorded with the run")
    if late:
        now = dt.datetime.now(dt.UTC).replace(microsecond=0)
        meta["calibration_override"] = {
            "reason": reason, "operator": operator,
            "time": now.isoformat().replace("+00:00", "Z"), "expired": late}
    return meta


def calibration_status(calibrations: Calibrations, day: dt.date | None = None
                       ) -> list[dict[str, Any]]:
    """The page's view: each sensor's record with ``expired`` (bool) and ``days_left``."""
    day = day or today_utc()
    return [{**entry.record(sensor), "expired": entry.due < day,
             "days_left": (entry.due - day).days} for sensor, entry in calibrations.items()]
