"""``rig sim --config`` selects the unit kind (issue 23 item 1): the shipped example plants of
a cycloid (seed 002) and a beveloid (seed 001) unit, each as its own ``rig sim`` process,
driven over the real protocols: the twist under torque and the gear ratio are the kind's."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from rig.hardware.config import load_rig_config
from rig.hardware.devices import open_rig
from simulators.plant import GearPlant
from simulators.plant.config import load_plant_config
from tests.support.devices import first_line, mean_angle, wait_alive
from tests.support.paths import REPO as ROOT

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

RIG = [sys.executable, "-c", "from rig.cli import main; main()"]
TORQUE_NM = 8.0


@pytest.mark.parametrize("name, ratio", [("cycloid", 39.0), ("beveloid", 1.0)])
def test_rig_sim_config_runs_the_kinds_plant(name: str, ratio: float) -> None:
    path = ROOT / "simulators" / f"{name}_plant.toml"
    proc = subprocess.Popen([*RIG, "sim", "--config", str(path)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        line = first_line(proc, 90.0)
        assert line, proc.stderr.read() if proc.poll() is not None else "no first line"
        info = json.loads(line)
        truth = GearPlant(load_plant_config(path))
        assert truth.true_parameters()["kind"] == name
        assert truth.true_parameters()["ratio"] == pytest.approx(ratio)
        twist = truth.true_twist_arcmin(np.linspace(0.0, TORQUE_NM, 201))
        with open_rig(load_rig_config(info["rig_config"])) as rig:
            before = mean_angle(rig.encoder)
            rig.drive.set_torque(TORQUE_NM)
            rig.drive.enable()
            wait_alive(rig, 0.6)
            after = mean_angle(rig.encoder)
            in0 = mean_angle(rig.input_encoder)
            state = rig.input_motor.lock_at(in0 + 45.0, timeout_s=10.0)
            assert state.locked
            wait_alive(rig, 0.3)
            moved = mean_angle(rig.encoder)
            in1 = mean_angle(rig.input_encoder)
            assert rig.safe_state()
        # the kind's play (start on the -1 flank) plus its twist under load
        assert (after - before) * 60.0 == pytest.approx(twist[-1] - twist[0], abs=0.01)
        # the output follows the input by the kind's ratio; at a new mesh phase the cycloid's
        # loaded twist changes by the play's change there (at most 0.1')
        assert (moved - after) * 60.0 == pytest.approx(-(in1 - in0) * 60.0 / ratio, abs=0.1)
    finally:
        proc.terminate()
        proc.wait(timeout=20)
