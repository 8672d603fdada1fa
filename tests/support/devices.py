"""Reading a simulated rig's devices from a test: the encoder's mean angle, the drive kept
alive while waiting, and the first line ``rig sim`` prints."""

from __future__ import annotations

import select
import subprocess
import time
from typing import Any

import numpy as np


def mean_angle(encoder: Any, seconds: float = 0.3) -> float:
    """The mean of the encoder's readings over the next ``seconds`` (deg; at least 10)."""
    encoder.readings()
    time.sleep(seconds)
    samples = encoder.readings()
    assert len(samples) >= 10
    return float(np.mean([s.angle_deg for s in samples]))


def wait_alive(devices: Any, seconds: float) -> None:
    """Wait ``seconds``, telling the devices' keepalive every 50 ms that this process lives."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        devices.alive()
        time.sleep(0.05)


def first_line(proc: subprocess.Popen, timeout_s: float = 60.0) -> str:
    """The first line of the process' stdout, or "" if none came within ``timeout_s``."""
    ready, _, _ = select.select([proc.stdout], [], [], timeout_s)
    return proc.stdout.readline() if ready and proc.stdout is not None else ""
