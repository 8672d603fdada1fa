"""``rig`` commands as their own processes for the page tests: ``rig serve`` (on the simulated
rig, or on a rig configuration) on a free port, the lines it prints when it is up, and JSON
to and from its API as the operator (:data:`TOKEN`)."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import threading
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

TOKEN = "e2e-operator-token"
"""The operator token the page tests serve with."""
AUTH = {"Authorization": f"Bearer {TOKEN}", "Content-Type": "application/json"}
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


@contextlib.contextmanager
def rig_serve(store: Path, *options: str) -> Iterator[tuple[str, str]]:
    """``rig serve --simulated`` on a free port (with ``options``: ``--plant FILE`` ...);
    yields (url, operator link)."""
    with served(store, TOKEN, "--simulated", *options) as lines:
        assert lines["operator token"].startswith(TOKEN)
        yield lines["control page"], lines["operator link"]


def get_json(url: str) -> Any:
    """GET ``url``; its JSON."""
    with urllib.request.urlopen(url, timeout=30) as r:
        return json.loads(r.read())


def post(url: str, body: dict | None = None) -> tuple[int, dict]:
    """POST ``body`` as JSON to ``url`` as the operator; (status, the JSON answer)."""
    req = urllib.request.Request(url, data=json.dumps(body or {}).encode(), headers=AUTH,
                                 method="POST")
    try:
        with urllib.request.urlopen(req, timeout=60) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read() or b"{}")
