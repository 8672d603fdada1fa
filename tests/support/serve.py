"""``rig`` commands as their own processes for the page tests: ``rig serve`` (on the simulated
rig, or on a rig configuration) on a free port, and the lines it prints when it is up."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

RIG = [sys.executable, "-c", "from rig.cli import main; main()"]
"""The ``rig`` console script, run by this interpreter."""


def rig_command(*args: str) -> list[str]:
    """The command line of ``rig ARGS...``."""
    return [*RIG, *args]


@contextlib.contextmanager
def started(cmd: list[str], cwd: Path) -> Iterator[tuple[subprocess.Popen, list[str]]]:
    """``cmd`` as a process with its stdout a pipe and its stderr collected (unbuffered);
    yields (process, stderr lines). Leaving, the process gets SIGINT (Ctrl-C), then is
    killed if it has not ended within 60 s."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=cwd, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    stderr: list[str] = []
    threading.Thread(target=lambda: stderr.extend(proc.stderr), daemon=True).start()
    try:
        yield proc, stderr
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)


def page_lines(proc: subprocess.Popen, stderr: list[str]) -> dict[str, str]:
    """The ``key: value`` lines ``rig serve`` prints on start, up to its operator link
    (control page, operator token, operator link); AssertionError with its stderr if it
    ended before."""
    lines: dict[str, str] = {}
    assert proc.stdout is not None
    for line in proc.stdout:
        key, _, value = line.partition(": ")
        lines[key] = value.strip()
        if key == "operator link":
            break
    assert "operator link" in lines, f"rig serve did not start: {''.join(stderr)}"
    return lines


@contextlib.contextmanager
def served(store: Path, token: str, *options: str) -> Iterator[dict[str, str]]:
    """``rig serve --port 0 --store STORE --token TOKEN OPTIONS...`` (``--simulated``, or
    ``--rig FILE``, ...) in the store's parent folder; yields its start lines."""
    cmd = rig_command("serve", *options, "--port", "0", "--store", str(store), "--token", token)
    with started(cmd, store.parent) as (proc, stderr):
        yield page_lines(proc, stderr)
