"""open_rig / RigDevices against the in-process simulated rig: keepalive, safety, controls.

Real protocols throughout (SLCAN on TCP, Modbus TCP, the transducer on a pty); the plant is
reached in process only to check what the devices did to it.
"""

from __future__ import annotations

import math
import time

import pytest

from drivers.errors import DeviceFault, DeviceOutOfRange, DeviceTimeout
from drivers.modbus.map import encode_float32
from drivers.rig_controls import CLIMATE_MAP, INPUT_MOTOR_MAP
from rig.hardware.config import load_rig_config
from rig.hardware.devices import open_rig
from rig.hardware.simrig import SimulatedRig
from simulators.plant.config import load_plant_config

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

HOUSING_TAU_S = 1.0


@pytest.fixture(scope="module")
def sim():
    plant = load_plant_config().with_changes(housing={"time_constant_s": HOUSING_TAU_S})
    with SimulatedRig(plant, seed=2, sync_period_s=0.005) as rig:
        yield rig


@pytest.fixture
def config(sim):
    return load_rig_config(sim.rig_config_path)


def _wait(devices, seconds: float, alive: bool = True) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if alive:
            devices.alive()
        time.sleep(0.05)


def test_keepalive_holds_the_drive_while_the_program_is_alive(sim, config):
    config = config.model_copy(update={"rig": config.rig.model_copy(
        update={"master_timeout_s": 0.6})})
    with open_rig(config) as rig:
        rig.drive.set_torque(2.0)
        rig.drive.enable()
        _wait(rig, 3 * config.drive.watchdog_s)  # no writes from here: only the thread's
        status = rig.drive.status()
        assert status.enabled and not status.faulted
        assert rig.keepalives_sent >= 5 and rig.keepalive_running
        assert sim.plant.snapshot().drive_enabled
        # the program goes silent: the thread withholds the keepalive, the watchdog trips
        _wait(rig, config.rig.master_timeout_s + 3 * config.drive.watchdog_s, alive=False)
        status = rig.drive.status()
        assert rig.keepalive_withheld
        assert not status.enabled and status.watchdog_tripped
        assert not sim.plant.snapshot().drive_enabled
        rig.drive.reset_fault()
    assert not rig.keepalive_running  # close() stopped it


def test_torque_limit_is_never_exceeded(sim, config):
    with open_rig(config) as rig:
        assert rig.torque_limit_Nm == 20.0  # min(rig, drive config, drive's own 30 N*m)
        rig.drive.enable()
        with pytest.raises(DeviceOutOfRange, match="within \\+-20 N\\*m"):
            rig.drive.set_torque(25.0)
        _wait(rig, 0.2)
        assert sim.plant.snapshot().torque_command_Nm == 0.0
        assert rig.drive.status().actual_torque_Nm == 0.0


def test_safe_state_never_raises_when_the_drive_is_gone(sim, config):
    rig = open_rig(config)
    try:
        assert rig.safe_state() is True
        sim.backdoors["modbus"].silence(None)
        started = time.monotonic()
        assert rig.safe_state() is False  # logged, not raised
        assert time.monotonic() - started < 10 * config.drive.timeout_s
    finally:
        rig.close()  # must not raise either
        sim.backdoors["modbus"].clear()
    with open_rig(config) as again:  # everything was released: the rig opens again
        assert again.drive.status().enabled is False


def test_strict_open_raises_and_releases_what_it_opened(sim, config):
    sim.backdoors["transducer"].silence()
    try:
        with pytest.raises(DeviceTimeout, match="torque transducer at /dev/pts/"):
            open_rig(config)
    finally:
        sim.backdoors["transducer"].clear()
    with open_rig(config) as rig:  # the SLCAN adapter (one client) was let go
        assert rig.encoder.read().angle_deg == pytest.approx(rig.encoder.read().angle_deg,
                                                             abs=0.01)


def test_climate_setpoint_drives_the_housing_temperature(sim, config):
    with open_rig(config) as rig:
        start = rig.climate.state().housing_C
        assert rig.transducer.temperature_C() == pytest.approx(start, abs=0.01)
        t_write0 = time.monotonic()
        rig.climate.set_temperature(40.0)
        t_write1 = time.monotonic()
        _wait(rig, HOUSING_TAU_S)
        t_read0 = time.monotonic()
        state = rig.climate.state()
        t_read1 = time.monotonic()
        with pytest.raises(DeviceOutOfRange):
            rig.climate.set_temperature(400.0)
        rig.climate.set_temperature(20.0)
    assert state.setpoint_C == 40.0

    def first_order(dt: float) -> float:  # housing: first order toward the setpoint
        return 40.0 - (40.0 - start) * math.exp(-dt / HOUSING_TAU_S)

    step = sim.plant.config.rig.step_s
    low, high = first_order(t_read0 - t_write1 - step), first_order(t_read1 - t_write0 + step)
    assert low - 0.01 <= state.housing_C <= high + 0.01


def test_controls_refuse_what_their_map_does_not_allow(sim, config):
    with open_rig(config) as rig:
        link, motor, climate = rig.input_motor.link, rig.input_motor, rig.climate
        unit3, unit4 = config.input_motor.device_id, config.climate.device_id
        with pytest.raises(DeviceFault, match="exception code 2"):  # half a float
            link.write(motor.name, unit3, 0, [encode_float32(10.0)[0]])
        with pytest.raises(DeviceFault, match="exception code 3"):  # unknown command
            link.write(motor.name, unit3, 2, [7])
        with pytest.raises(DeviceFault, match="exception code 3"):  # beyond the chamber
            link.write(climate.name, unit4, 0, encode_float32(151.0))
        with pytest.raises(DeviceOutOfRange):
            motor.start_lock_at(math.nan)  # refused by the driver, nothing sent
        assert motor.state().locked


def test_every_control_register_is_documented(repo_root):
    text = (repo_root / "docs" / "rig-config.md").read_text(encoding="utf-8")
    for reg in [*INPUT_MOTOR_MAP.values(), *CLIMATE_MAP.values()]:
        assert f"`{reg.name}`" in text, reg.name
