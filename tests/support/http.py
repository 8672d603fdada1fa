"""Plain HTTP to a served control page (a real socket, no TestClient): one request, and the
wait for a freshly started page to find its rig idle."""

from __future__ import annotations

import http.client
import json
import time
from typing import Any
from urllib.parse import urlsplit


def request(host: str, port: int, method: str, path: str, body: bytes | None = None,
            headers: dict[str, str] | None = None) -> tuple[int, Any]:
    """One request; (status, the JSON answer, or the text when it is not JSON)."""
    conn = http.client.HTTPConnection(host, port, timeout=60)
    try:
        conn.request(method, path, body=body, headers=headers or {})
        r = conn.getresponse()
        data = r.read()
        try:
            return r.status, json.loads(data)
        except ValueError:
            return r.status, data.decode(errors="replace")
    finally:
        conn.close()


def wait_until_idle(url: str, timeout_s: float = 90.0) -> tuple[str, int]:
    """Poll the page at ``url`` until its state is idle (at most ``timeout_s`` s, then go on:
    the tests' own requests say what is wrong); returns (host, port)."""
    parts = urlsplit(url)
    host, port = parts.hostname, parts.port
    assert host is not None and port is not None, url
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if request(host, port, "GET", "/api/status")[1].get("state") == "idle":
            break
        time.sleep(0.5)
    return host, port
