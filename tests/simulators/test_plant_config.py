"""Plant TOML: the default loads; every malformed file names the file and the key."""

from __future__ import annotations

from pathlib import Path

import pytest

from simulators.plant.config import (
    DEFAULT_PLANT_TOML,
    EFFECT_NAMES,
    PlantConfigError,
    load_plant_config,
)

VOCABULARY = ("friction", "stiffness_nonlinearity", "runout", "bearing_clearance",
              "thermal_expansion", "torque_sensor_offset", "shaft_compliance",
              "tooth_spacing_error")


def write(tmp_path: Path, replace: tuple[str, str] | None = None, append: str = "") -> Path:
    text = DEFAULT_PLANT_TOML.read_text(encoding="utf-8")
    if replace is not None:
        assert replace[0] in text
        text = text.replace(replace[0], replace[1], 1)
    path = tmp_path / "plant.toml"
    path.write_text(text + append, encoding="utf-8")
    return path


def test_default_loads_with_every_effect_of_the_vocabulary():
    config = load_plant_config()
    assert config == load_plant_config(DEFAULT_PLANT_TOML)
    assert set(VOCABULARY) < set(EFFECT_NAMES)
    assert {"creep", "direction_gain"} < set(EFFECT_NAMES)
    assert config.effects.enabled_names() == []
    assert config.unit["z_internal"] == 45
    assert config.rig.drive_torque_limit_Nm == 30.0


def test_with_effect_validates_and_names_the_key():
    config = load_plant_config()
    assert config.with_effect("runout", beta_deg=30.0).effects.runout.enabled
    with pytest.raises(PlantConfigError, match="no effect named 'backlash_x'"):
        config.with_effect("backlash_x")
    with pytest.raises(PlantConfigError, match="effects.friction.model"):
        config.with_effect("friction", model="coulomb")


def test_syntax_error_names_file_line_and_column(tmp_path):
    path = write(tmp_path, ("inertia_kgm2 = 0.02", "inertia_kgm2 = = 0.02"))
    with pytest.raises(PlantConfigError) as err:
        load_plant_config(path)
    message = str(err.value)
    assert str(path) in message and "line" in message and "column" in message


@pytest.mark.parametrize("replace,key", [
    (('model = "dahl"', 'model = "coulomb"'), "effects.friction.model"),
    (("drive_time_constant_s = 0.01", "drive_time_constant_s = -1"),
     "rig.drive_time_constant_s"),
    (("inertia_kgm2 = 0.02", "inertia_kg = 0.02"), "rig.inertia_kg"),
    (("seed = 1", 'seed = "one"'), "noise.seed"),
    (("face_width_mm = 10.0\n", ""), "face_width_mm"),
    (("z_internal = 45", "z_internal = 4.5"), "z_internal"),
])
def test_bad_values_name_file_and_key(tmp_path, replace, key):
    path = write(tmp_path, replace)
    with pytest.raises(PlantConfigError) as err:
        load_plant_config(path)
    assert str(path) in str(err.value)
    assert key in str(err.value)


def test_per_tooth_list_of_the_wrong_length(tmp_path):
    path = write(tmp_path, ("seed = 7", "seed = 7\nthickness_internal_um = [1.0, 2.0]"))
    with pytest.raises(PlantConfigError, match="tooth_spacing_error.thickness_internal_um"):
        load_plant_config(path)


def test_missing_file_and_missing_unit(tmp_path):
    with pytest.raises(PlantConfigError, match="nothere.toml"):
        load_plant_config(tmp_path / "nothere.toml")
    path = tmp_path / "empty.toml"
    path.write_text("[rig]\ninertia_kgm2 = 0.1\n", encoding="utf-8")
    with pytest.raises(PlantConfigError, match="key unit: missing"):
        load_plant_config(path)
