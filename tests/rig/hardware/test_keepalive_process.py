"""The drive keepalive in its own process (rig/hardware/keepalive_process.py), against the simulated
rig in its own process (``rig sim``): the drive's watchdog and its Modbus server are the
simulated devices', reached over Modbus TCP.

The measuring process's interpreter is held on purpose with one long C call (``sum`` over a
range does not release the interpreter lock): no thread of this process can run, as when a
busy PC leaves the thread holding the lock waiting for the CPU.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from drivers.loading_drive import LoadingDrive
from drivers.modbus.link import ModbusLink
from rig.hardware.config import RigConfig, load_rig_config
from rig.hardware.devices import open_rig
from rig.hardware.simrig import SimulatedRig
from tests.support.paths import REPO as ROOT

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    with SimulatedRig(in_process=False, seed=4,
                      rig_config_path=tmp_path_factory.mktemp("ka") / "rig.toml") as rig:
        yield rig


@pytest.fixture(autouse=True)
def drive_reset(sim):
    """Each test leaves the drive as it found it: no latched fault, safe."""
    yield
    drive = _drive(load_rig_config(sim.rig_config_path))
    drive.reset_fault()
    drive.safe_state()
    drive.close()


def _config(sim: SimulatedRig, **rig_changes) -> RigConfig:
    config = load_rig_config(sim.rig_config_path)
    return config.model_copy(update={"rig": config.rig.model_copy(update=rig_changes)})


def _hold_interpreter(at_least_s: float) -> float:
    """Hold the interpreter lock for at least ``at_least_s`` (s) in one C call; the time
    held. The call's length is not known in advance (the machine's speed and load change),
    so shorter holds grow until one lasts long enough; each of them holds the lock too."""
    n = 1_000_000
    while True:
        t0 = time.perf_counter()
        sum(range(n))
        held = time.perf_counter() - t0
        if held >= at_least_s:
            return held
        n = int(n * min(10.0, 1.5 * at_least_s / max(held, 1e-3)))


HOLD_WATCHDOGS = 4  # the hold, in watchdog times


def _drive(config: RigConfig) -> LoadingDrive:
    """A second master on the drive, to read its status after the test's own rig closed."""
    return LoadingDrive(config.drive, link=ModbusLink(config.drive))


def _enable_and_hold(rig, watchdog_s: float):
    """Enable the drive at 1 N*m, hold the interpreter for HOLD_WATCHDOGS watchdogs; the
    drive's status after."""
    rig.drive.set_torque(1.0)
    rig.drive.enable()
    held = _hold_interpreter(HOLD_WATCHDOGS * watchdog_s)
    assert held >= HOLD_WATCHDOGS * watchdog_s, held
    return rig.drive.status()


def test_the_process_feeds_the_drive_while_the_interpreter_is_held(sim):
    # master timeout far beyond the hold: the program is slow, not dead
    config = _config(sim, master_timeout_s=30.0)
    with open_rig(config) as rig:
        assert rig.keepalive_process_running
        deadline = time.monotonic() + 10.0
        while rig.keepalives_sent < 3 and time.monotonic() < deadline:
            time.sleep(0.05)  # the process is up and acknowledged
        status = _enable_and_hold(rig, config.drive.watchdog_s)
        assert status.enabled and not status.watchdog_tripped, status
        rig.safe_state()


def test_without_the_process_the_same_hold_trips_the_watchdog(sim):
    """Why the process exists: the thread alone cannot write while the lock is held."""
    config = _config(sim, master_timeout_s=30.0, keepalive_process=False)
    with open_rig(config) as rig:
        assert not rig.keepalive_process_running and rig.keepalive_running
        status = _enable_and_hold(rig, config.drive.watchdog_s)
        assert status.watchdog_tripped and not status.enabled, status
        rig.drive.reset_fault()


def test_a_silent_program_gets_no_keepalive_from_the_process(sim):
    config = _config(sim, master_timeout_s=0.6)
    with open_rig(config) as rig:
        assert rig.keepalive_process_running
        rig.drive.enable()
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            rig.alive()
            time.sleep(0.05)
        assert rig.drive.status().enabled
        # silent (no alive()) beyond the master timeout: both withhold, the watchdog trips
        time.sleep(config.rig.master_timeout_s + 3 * config.drive.watchdog_s)
        status = rig.drive.status()
        assert rig.keepalive_withheld
        assert status.watchdog_tripped and not status.enabled, status
        rig.drive.reset_fault()
    assert not rig.keepalive_process_running


KILLED_PROGRAM = textwrap.dedent("""
    import sys, time
    from rig.hardware.config import load_rig_config
    from rig.hardware.devices import open_rig
    rig = open_rig(load_rig_config(sys.argv[1]))
    while rig.keepalives_sent < 3:
        rig.alive(); time.sleep(0.05)
    rig.drive.set_torque(1.0)
    rig.drive.enable()
    print(rig._keepalive_process._proc.pid, rig._keepalive_process._path, flush=True)
    while True:
        rig.alive(); time.sleep(0.05)
""")


def test_the_process_stops_when_the_measuring_program_is_killed(sim):
    """kill -9 of the measuring program: its keepalive process stops feeding at once (it does
    not wait for the master timeout) and the drive's watchdog makes the drive safe."""
    config = _config(sim)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    program = subprocess.Popen([sys.executable, "-c", KILLED_PROGRAM,
                                str(sim.rig_config_path)], stdout=subprocess.PIPE, text=True,
                               env=env)
    try:
        assert program.stdout is not None
        child_pid, page = program.stdout.readline().split()
        child = int(child_pid)
        assert Path(page).is_file()
        drive = _drive(config)
        assert drive.status().enabled
        program.send_signal(signal.SIGKILL)
        program.wait(10)
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline and Path(f"/proc/{child}").exists() \
                and "zombie" not in _state(child):
            time.sleep(0.02)
        assert not Path(f"/proc/{child}").exists() or "zombie" in _state(child)
        assert not Path(page).exists()  # its shared page removed by the child itself
        time.sleep(2 * config.drive.watchdog_s)
        status = drive.status()
        assert status.watchdog_tripped and not status.enabled, status
        drive.reset_fault()
        drive.close()
    finally:
        if program.poll() is None:
            program.kill()


def _state(pid: int) -> str:
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return "gone"
    return next((line for line in text.splitlines() if line.startswith("State:")), "")


def test_an_rtu_drive_is_fed_by_the_thread_alone(tmp_path):
    """One master on an RS-485 line: no second connection, the thread feeds the drive."""
    with SimulatedRig(in_process=False, modbus="rtu-tcp", seed=5,
                      rig_config_path=tmp_path / "rig.toml") as rtu_sim:
        config = load_rig_config(rtu_sim.rig_config_path)
        assert config.drive.transport == "rtu"
        with open_rig(config) as rig:
            assert not rig.keepalive_process_running
            deadline = time.monotonic() + 5.0
            while rig.keepalives_sent < 3 and time.monotonic() < deadline:
                rig.alive()
                time.sleep(0.05)
            assert rig.keepalives_sent >= 3
