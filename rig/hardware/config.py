"""The rig configuration: one TOML file naming every device's interface and address.

Switching from the simulated rig to real hardware is a change of this file only. Tables
(``docs/rig-config.md`` describes every key; ``examples/rigs/`` has a simulated and a
real-hardware template):

- ``[rig]``: ``rig_id``, ``torque_limit_Nm`` (N*m, the most any step may command),
  ``sample_rate_Hz`` (acquisition), ``keepalive_period_s`` and ``master_timeout_s`` (s);
- ``[can]``: the CAN bus of the encoders (:class:`drivers.encoder_canopen.CanBusConfig`);
- ``[encoder]`` and optional ``[input_encoder]``: :class:`EncoderConfig` without ``bus``;
- ``[transducer]``: :class:`drivers.transducer.serial.TransducerConfig`;
- ``[torque_sensor]``, ``[drive]``: the Modbus drivers' configs (``drive.torque_limit_Nm``
  defaults to ``rig.torque_limit_Nm`` and may not exceed it);
- optional ``[input_motor]``, ``[climate]``: :mod:`drivers.rig_controls` configs;
- optional ``[calibration]``: per sensor (``[calibration.transducer]`` ...) ``id``,
  ``certificate``, ``date``, ``due`` and ``uncertainty`` (:mod:`rig.hardware.calibration`).

The drivers' own pydantic models validate their tables. Every error names the file and the
key (``rig.toml: drive.torque_limit_Nm: Input should be greater than 0 (got -1)``), a TOML
syntax error the file, line and column (``rig.toml:3:9: ...``).
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from drivers.encoder_canopen import CanBusConfig, EncoderConfig
from drivers.loading_drive import LoadingDriveConfig
from drivers.modbus.torque_sensor import ModbusTorqueSensorConfig
from drivers.rig_controls import ClimateConfig, InputMotorConfig
from drivers.transducer.serial import TransducerConfig
from rig.core.errors import RigError
from rig.core.ranges import (
    DEVICE_TIMEOUT_S,
    LOCK_TOLERANCE_DEG,
    MASTER_TIMEOUT_S,
    MOTOR_SPEED_RPM,
    SLEEP_AFTER_OPEN_S,
    SYNC_PERIOD_S,
    TEMPERATURE_SETPOINT_C,
    TORQUE_LIMIT_NM,
    Range,
)
from rig.core.toml_files import describe_validation_error, read_toml
from rig.hardware.calibration import Calibrations


class RigConfigError(RigError):
    """A rig configuration is malformed: the message names the file and the key (or line
    and column for TOML syntax)."""


class RigSection(BaseModel):
    """``[rig]``: identity and rig-wide limits. Torques in N*m, rates in Hz, times in s.

    ``master_timeout_s``: the drive keepalive of :class:`rig.hardware.devices.RigDevices` stops when
    the measuring program has not called ``alive()`` for this long (None: never stops).
    ``realtime_priority`` (1-99, optional): SCHED_FIFO for the measuring process when the
    system permits it (rig/core/realtime.py); None: the normal scheduler.
    ``keepalive_process``: write the drive keepalive from a small process of its own when
    the drive is on Modbus TCP (rig/hardware/keepalive_process.py); False: the thread alone.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    rig_id: str = Field(min_length=1)
    torque_limit_Nm: float = Field(gt=0, allow_inf_nan=False)
    sample_rate_Hz: float = Field(default=100.0, gt=0, le=2000)
    keepalive_period_s: float = Field(default=0.1, gt=0, le=10)
    master_timeout_s: float | None = Field(default=2.0, gt=0)
    realtime_priority: int | None = Field(default=None, ge=1, le=99, strict=True)
    keepalive_process: bool = Field(default=True, strict=True)


class RigConfig(BaseModel):
    """A whole rig configuration (validated). ``source`` names the file it came from."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    rig: RigSection
    can: CanBusConfig = Field(default_factory=CanBusConfig)
    encoder: EncoderConfig
    input_encoder: EncoderConfig | None = None
    transducer: TransducerConfig
    torque_sensor: ModbusTorqueSensorConfig
    drive: LoadingDriveConfig
    input_motor: InputMotorConfig | None = None
    climate: ClimateConfig | None = None
    calibration: Calibrations = Field(default_factory=dict)
    source: str = "<memory>"

    def device_names(self) -> list[str]:
        """The configured devices, in opening order."""
        names = ["encoder", "input_encoder", "transducer", "torque_sensor", "drive",
                 "input_motor", "climate"]
        return [n for n in names if getattr(self, n) is not None]

    @property
    def torque_limit_Nm(self) -> float:
        """The most torque (N*m) anything may command: the drive's, within the rig's."""
        return min(self.rig.torque_limit_Nm, self.drive.torque_limit_Nm)


def _prepared(data: dict[str, Any], source: str) -> dict[str, Any]:
    """Copy of the mapping with the rig-level defaults filled in (encoder bus, drive limit)."""
    data = dict(data)
    for name in ("encoder", "input_encoder"):
        table = data.get(name)
        if isinstance(table, dict) and "bus" in table:
            raise RigConfigError(f"{source}: {name}.bus: not allowed here: the encoders "
                                 "share the bus of the [can] table")
    drive = data.get("drive")
    rig = data.get("rig")
    if isinstance(drive, dict) and "torque_limit_Nm" not in drive and isinstance(rig, dict) \
            and "torque_limit_Nm" in rig:
        data["drive"] = {**drive, "torque_limit_Nm": rig["torque_limit_Nm"]}
    return data


CONFIG_RANGES: dict[str, Range] = {
    "rig.torque_limit_Nm": TORQUE_LIMIT_NM,
    "rig.master_timeout_s": MASTER_TIMEOUT_S,
    "can.sync_period_s": SYNC_PERIOD_S,
    "can.bus_options.sleep_after_open": SLEEP_AFTER_OPEN_S,
    **{f"{enc}.{key}": DEVICE_TIMEOUT_S for enc in ("encoder", "input_encoder")
       for key in ("timeout_s", "stuck_after_s")},
    "transducer.full_scale_Nm": TORQUE_LIMIT_NM,
    "torque_sensor.stale_after_s": DEVICE_TIMEOUT_S,
    "drive.torque_limit_Nm": TORQUE_LIMIT_NM,
    "input_motor.move_timeout_s": DEVICE_TIMEOUT_S,
    "input_motor.max_speed_rpm": MOTOR_SPEED_RPM,
    "input_motor.lock_tolerance_deg": LOCK_TOLERANCE_DEG,
    "climate.min_C": TEMPERATURE_SETPOINT_C,
    "climate.max_C": TEMPERATURE_SETPOINT_C,
}
"""The physical range of each number of the configuration the drivers' models leave open
(:mod:`rig.core.ranges`); a key of a table that is absent, or a value left out, is not
checked."""


def _value(config: RigConfig, key: str) -> Any:
    """The value of the dotted ``key`` (None when its table or the key is absent)."""
    value: Any = config
    for part in key.split("."):
        value = value.get(part) if isinstance(value, dict) else getattr(value, part, None)
        if value is None:
            return None
    return value


def _range_problems(config: RigConfig) -> list[str]:
    """One line per value outside its physical range (:data:`CONFIG_RANGES`)."""
    problems = [p for key, rng in CONFIG_RANGES.items()
                if (value := _value(config, key)) is not None
                and (p := rng.problem(key, value)) is not None]
    climate = config.climate
    if climate is not None and not climate.min_C < climate.max_C:
        problems.append(f"climate.min_C: {climate.min_C:g} °C must be below climate.max_C = "
                        f"{climate.max_C:g} °C")
    return problems


def _cross_check(config: RigConfig, source: str) -> None:
    """Rules between tables; each error names the key to change."""
    rig = config.rig
    problems = _range_problems(config)
    if problems:
        raise RigConfigError("\n".join(f"{source}: {p}" for p in problems))
    if config.drive.torque_limit_Nm > rig.torque_limit_Nm:
        problems.append(f"drive.torque_limit_Nm: {config.drive.torque_limit_Nm:g} N*m exceeds "
                        f"rig.torque_limit_Nm = {rig.torque_limit_Nm:g} N*m")
    if rig.torque_limit_Nm > config.transducer.full_scale_Nm:
        problems.append(f"rig.torque_limit_Nm: {rig.torque_limit_Nm:g} N*m exceeds the "
                        f"transducer's range transducer.full_scale_Nm = "
                        f"{config.transducer.full_scale_Nm:g} N*m")
    if rig.keepalive_period_s > config.drive.watchdog_s / 2:
        problems.append(f"rig.keepalive_period_s: {rig.keepalive_period_s:g} s must be at most "
                        f"half of drive.watchdog_s = {config.drive.watchdog_s:g} s")
    if config.input_encoder is not None and config.input_encoder.node_id == \
            config.encoder.node_id:
        problems.append(f"input_encoder.node_id: {config.input_encoder.node_id} is also "
                        "encoder.node_id (one CAN bus: node ids must differ)")
    units: dict[tuple, str] = {}
    for name in ("torque_sensor", "drive", "input_motor", "climate"):
        cfg = getattr(config, name)
        if cfg is None:
            continue
        key = (*link_key(cfg), cfg.device_id)
        if key in units:
            problems.append(f"{name}.device_id: {cfg.device_id} is also {units[key]}.device_id "
                            f"on {cfg.where()}")
        units[key] = name
    if problems:
        raise RigConfigError("\n".join(f"{source}: {p}" for p in problems))


def link_key(cfg: Any) -> tuple:
    """What identifies one Modbus connection: devices with equal keys share a link."""
    if cfg.transport == "tcp":
        return ("tcp", cfg.host, cfg.port)
    return ("rtu", cfg.serial_url, cfg.baudrate)


def rig_config_from_mapping(data: dict[str, Any], source: str = "<memory>") -> RigConfig:
    """Validate a mapping (a parsed TOML) into a RigConfig; errors name ``source`` and key."""
    if not isinstance(data, dict):
        raise RigConfigError(f"{source}: expected a table of tables, got {type(data).__name__}")
    prepared = _prepared(data, source)
    try:
        config = RigConfig.model_validate({**prepared, "source": source})
    except ValidationError as exc:
        raise RigConfigError(describe_validation_error(exc, source)) from exc
    config = config.model_copy(update={
        name: enc.model_copy(update={"bus": config.can})
        for name in ("encoder", "input_encoder")
        if (enc := getattr(config, name)) is not None})
    _cross_check(config, source)
    return config


def load_rig_config(path: str | Path) -> RigConfig:
    """Read and validate a rig TOML. Raises RigConfigError naming file and key/line:col."""
    data = read_toml(path, RigConfigError, "rig configuration")
    return rig_config_from_mapping(data, str(Path(path)))


# -- writing (the simulated rig writes the configuration that connects to it) -------------

def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str | Path):
        return json.dumps(str(value))  # a JSON string is a valid TOML basic string
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        items = ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()
                          if v is not None)
        return "{" + items + "}" if items else "{}"
    raise TypeError(f"cannot write {type(value).__name__} {value!r} as TOML")


def _toml_key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else json.dumps(key)


def dump_rig_toml(tables: dict[str, dict[str, Any]], header: str = "") -> str:
    """TOML text of ``{table: {key: value}}`` (None values left out; nested dicts inline)."""
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    for name, table in tables.items():
        if lines:
            lines.append("")
        lines.append(f"[{_toml_key(name)}]")
        for key, value in table.items():
            if value is not None:
                lines.append(f"{_toml_key(key)} = {_toml_value(value)}")
    return "\n".join(lines) + "\n"
