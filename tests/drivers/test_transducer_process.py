"""The driver against the simulator running in a separate process (python -m ...)."""

from __future__ import annotations

import json
import math
import os
import select
import subprocess
import sys
from collections.abc import Iterator

import pytest

from drivers.transducer.serial import SerialTorqueTransducer, TransducerConfig
from tests.support.paths import REPO


@pytest.fixture(params=["pty", "tcp"])
def served(request: pytest.FixtureRequest) -> Iterator[str]:
    """Start ``python -m simulators.transducer`` and yield the address it prints."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "simulators.transducer", "--transport", request.param,
         "--amplitude", "4.0"],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    try:
        assert proc.stdout is not None
        ready, _, _ = select.select([proc.stdout], [], [], 60.0)
        assert ready, "the simulator printed no address within 60 s"
        info = json.loads(proc.stdout.readline())
        assert info["transport"] == request.param
        yield info["transducer"]
    finally:
        proc.terminate()
        try:
            assert proc.wait(timeout=30) == 0  # SIGTERM: a clean stop
        finally:
            if proc.poll() is None:
                proc.kill()


def test_driver_talks_to_a_simulator_in_another_process(served: str) -> None:
    config = TransducerConfig(url=served, timeout_s=3.0)
    with SerialTorqueTransducer(config) as tt:
        assert tt.identity().model == "TT-20"
        assert abs(tt.read().torque_Nm) <= 4.0 + 1e-9
        tt.start_stream(500)
        readings = list(tt.readings(500))
        stats = tt.stop_stream()
    assert stats.received == 500
    # the 4 N*m, 0.5 Hz sine, at the device's own timestamps
    for r in readings[::50]:
        expected = 4.0 * math.sin(2 * math.pi * 0.5 * r.device_t_s)
        assert r.torque_Nm == pytest.approx(expected, abs=5e-5)
