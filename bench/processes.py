"""Helpers for the benchmarks' child processes (simulators run with ``python -m``)."""

from __future__ import annotations

import subprocess


def stop_process(proc: subprocess.Popen, timeout_s: float) -> None:
    """Terminate ``proc``; kill it if it has not exited within ``timeout_s`` (s)."""
    proc.terminate()
    try:
        proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
