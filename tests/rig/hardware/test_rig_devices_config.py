"""The rig configuration TOML: example files, defaults, and errors naming file and key."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from rig.hardware.config import (
    RigConfigError,
    dump_rig_toml,
    load_rig_config,
    rig_config_from_mapping,
)
from tests.support.paths import REPO

EXAMPLES = REPO / "examples" / "rigs"
SIMULATED = EXAMPLES / "simulated.toml"


def _tables() -> dict:
    return tomllib.loads(SIMULATED.read_text(encoding="utf-8"))


def _write(tmp_path: Path, tables: dict) -> Path:
    path = tmp_path / "rig.toml"
    path.write_text(dump_rig_toml(tables), encoding="utf-8")
    return path


@pytest.mark.parametrize("name", ["simulated.toml", "real-hardware.toml"])
def test_example_rigs_load(name):
    config = load_rig_config(EXAMPLES / name)
    assert config.rig.rig_id
    assert {"encoder", "transducer", "torque_sensor", "drive"} <= set(config.device_names())
    assert config.encoder.bus == config.can  # the encoders ride on the [can] bus
    assert config.torque_limit_Nm <= config.transducer.full_scale_Nm


def test_simulated_example_matches_rig_sim_port_base():
    config = load_rig_config(SIMULATED)
    assert (config.torque_sensor.port, config.can.channel, config.transducer.url) == (
        15020, "socket://127.0.0.1:15021", "socket://127.0.0.1:15022")
    units = [config.torque_sensor.device_id, config.drive.device_id,
             config.input_motor.device_id, config.climate.device_id]
    assert units == [1, 2, 3, 4]


def test_drive_limit_defaults_to_the_rig_limit(tmp_path):
    tables = _tables()
    tables["drive"].pop("torque_limit_Nm", None)
    tables["rig"]["torque_limit_Nm"] = 12.5
    config = load_rig_config(_write(tmp_path, tables))
    assert config.drive.torque_limit_Nm == 12.5 == config.torque_limit_Nm


def test_dump_round_trips(tmp_path):
    tables = _tables()
    tables["transducer"]["terminator"] = "\r\n"
    tables["rig"]["rig_id"] = 'rig "quoted" \\ name'
    path = _write(tmp_path, tables)
    assert tomllib.loads(path.read_text(encoding="utf-8")) == tables
    assert load_rig_config(path).rig.rig_id == 'rig "quoted" \\ name'


@pytest.mark.parametrize(
    ("table", "key", "value", "expected"),
    [
        ("drive", "torque_limit_Nm", -1.0, "drive.torque_limit_Nm: Input should be greater than 0"),
        ("rig", "torque_limit_Nm", 0, "rig.torque_limit_Nm: Input should be greater than 0"),
        ("encoder", "node_id", 300, "encoder.node_id: Input should be less than or equal to 127"),
        ("torque_sensor", "port", "fifteen", "torque_sensor.port: Input should be a valid integer"),
        ("transducer", "speed", 1, "transducer.speed: Extra inputs are not permitted"),
        ("drive", "torque_limit_Nm", 25.0, "drive.torque_limit_Nm: 25 N*m exceeds "
                                           "rig.torque_limit_Nm = 20 N*m"),
        ("rig", "keepalive_period_s", 0.3, "rig.keepalive_period_s: 0.3 s must be at most half"),
        ("input_encoder", "node_id", 1, "input_encoder.node_id: 1 is also encoder.node_id"),
        ("climate", "device_id", 2, "climate.device_id: 2 is also drive.device_id"),
        ("encoder", "bus", {"interface": "virtual"}, "encoder.bus: not allowed here"),
    ],
)
def test_errors_name_the_file_and_the_key(tmp_path, table, key, value, expected):
    path, message = _refused(tmp_path, table, key, value)
    assert f"{path}: {expected}" in message


def _refused(tmp_path, table: str, key: str, value) -> tuple:
    """The rig file with ``table.key = value`` and the one error loading it gives."""
    tables = _tables()
    tables[table][key] = value
    path = _write(tmp_path, tables)
    with pytest.raises(RigConfigError) as info:
        load_rig_config(path)
    return path, str(info.value)


def test_rig_limit_above_the_transducer_range_is_refused(tmp_path):
    tables = _tables()
    tables["rig"]["torque_limit_Nm"] = 30.0
    tables["drive"]["torque_limit_Nm"] = 30.0
    with pytest.raises(RigConfigError, match=r"rig\.torque_limit_Nm: 30 N\*m exceeds the "
                                             r"transducer's range"):
        load_rig_config(_write(tmp_path, tables))


def test_missing_table_and_unknown_table(tmp_path):
    tables = _tables()
    del tables["drive"]
    tables["drvie"] = {"port": 1}
    with pytest.raises(RigConfigError) as info:
        load_rig_config(_write(tmp_path, tables))
    text = str(info.value)
    assert "rig.toml: drive: Field required" in text
    assert "rig.toml: drvie: Extra inputs are not permitted" in text


def test_toml_syntax_error_names_line_and_column(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text('[rig]\nrig_id = "a"\ntorque_limit_Nm = = 3\n', encoding="utf-8")
    with pytest.raises(RigConfigError, match=rf"^{path}:3:19: TOML syntax error: "):
        load_rig_config(path)


def test_unreadable_file(tmp_path):
    with pytest.raises(RigConfigError, match="nothing.toml: cannot read the rig configuration"):
        load_rig_config(tmp_path / "nothing.toml")
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"\xff\xfe[rig]")
    with pytest.raises(RigConfigError, match="binary.toml: not UTF-8 text"):
        load_rig_config(binary)


def test_mapping_must_be_a_table():
    with pytest.raises(RigConfigError, match="<memory>: expected a table of tables"):
        rig_config_from_mapping([1, 2])  # type: ignore[arg-type]


def test_rig_devices_exits_2_on_a_bad_config(tmp_path):
    tables = _tables()
    tables["drive"]["torque_limit_Nm"] = -1.0
    path = _write(tmp_path, tables)
    proc = subprocess.run(
        [sys.executable, "-c", "from rig.cli import main; main()", "devices", "--rig", str(path),
         "--seconds", "1"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert f"rig: error: {path}: drive.torque_limit_Nm: Input should be greater than 0" \
        in proc.stderr


def test_the_loaded_limits_are_immutable(tmp_path: Path):
    """Fault-matrix row 13: assigning a limit after load_rig_config is refused."""
    from pydantic import ValidationError

    config = load_rig_config(_write(tmp_path, _tables()))
    limit = config.torque_limit_Nm
    for assign in (lambda: setattr(config.rig, "torque_limit_Nm", 1000.0),
                   lambda: setattr(config.drive, "torque_limit_Nm", 1000.0),
                   lambda: setattr(config, "drive", None)):
        with pytest.raises(ValidationError, match="frozen"):
            assign()
    assert config.torque_limit_Nm == limit


# issue 33 item 5: every number of the configuration has a physical range (rig/core/ranges.py)
@pytest.mark.parametrize(
    ("table", "key", "value", "expected"),
    [
        ("can", "sync_period_s", 1e-9,
         "can.sync_period_s: expected from 0.001 to 60 s (got 1e-09)"),
        ("can", "bus_options", {"sleep_after_open": 1e9},
         "can.bus_options.sleep_after_open: expected from 0 to 10 s (got 1000000000.0)"),
        ("rig", "master_timeout_s", 1e300,
         "rig.master_timeout_s: expected greater than 0 and at most 3600 s (got 1e+300)"),
        ("climate", "min_C", -300.0, "climate.min_C: expected from -40 to 150 °C (got -300.0)"),
        ("climate", "max_C", 1e6, "climate.max_C: expected from -40 to 150 °C (got 1000000.0)"),
        ("input_motor", "move_timeout_s", 1e12, "input_motor.move_timeout_s: expected greater "
                                                "than 0 and at most 3600 s"),
        ("transducer", "full_scale_Nm", 1e31, "transducer.full_scale_Nm: expected greater "
                                              "than 0 and at most 1e+07 N·m"),
    ],
)
def test_numbers_outside_their_physical_range_are_refused(tmp_path, table, key, value,
                                                         expected):
    path, message = _refused(tmp_path, table, key, value)
    assert f"{path}: {expected}" in message
    assert len(message.splitlines()) == 1, message


def test_climate_limits_must_be_in_order(tmp_path):
    tables = _tables()
    tables["climate"].update(min_C=100.0, max_C=20.0)
    with pytest.raises(RigConfigError, match=r"climate\.min_C: 100 °C must be below"):
        load_rig_config(_write(tmp_path, tables))


def test_rig_devices_refuses_a_sleep_after_open_of_a_billion_seconds(tmp_path):
    """``rig devices`` hung on it (the bus slept before its first frame): now exit 2, one
    line naming the file, the key and the range, before any device is opened."""
    tables = _tables()
    tables["can"]["bus_options"] = {"sleep_after_open": 1e9}
    path = _write(tmp_path, tables)
    proc = subprocess.run(
        [sys.executable, "-m", "rig", "devices", "--rig", str(path), "--seconds", "1"],
        capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip() == (f"rig: error: {path}: can.bus_options.sleep_after_open: "
                                   "expected from 0 to 10 s (got 1000000000.0)"), proc.stderr
