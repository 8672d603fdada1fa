"""What reaches the control page's routes: a pure ASGI middleware in front of the app.

Outside-probe findings it answers (issue 12, fault matrix rows 5, 9 and 10):

- **Host header** (DNS rebinding): when the page listens on the loopback, a request whose
  ``Host`` is not ``127.0.0.1``, ``localhost`` or ``[::1]`` (any port) is refused with 421.
  A page bound to another address (which needs an operator token anyway) accepts any host.
- **Cross-site requests**: a state-changing request (POST, PUT, PATCH, DELETE) that a browser
  marks as coming from another site (``Sec-Fetch-Site: cross-site`` or ``same-site``) or whose
  ``Origin`` is not this page's own host is refused with 403. The E-stop stays token-free, but
  only the page itself (or a non-browser client, which sends neither header) can press it.
- **Body size**: a request body larger than :data:`MAX_BODY_BYTES` is refused with 413 before
  anything parses it (by ``Content-Length``, or while it streams in).
- **One strict body parser** (issue 21 item 9): every request body is read by
  :func:`rig.web.body.canonical_json_body` whatever its ``Content-Type`` says (compared
  case-insensitively; no header means JSON; another media type is 415). NaN, Infinity and
  ``1e999`` are refused with 422 naming the field (the FastAPI validation error shape),
  instead of reaching a model or the response renderer; the route reads the body re-written
  from the parsed value as ``application/json``. The E-stop's body is never looked at: a stop
  is never refused for what came with it.
"""

from __future__ import annotations

import json
from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any
from urllib.parse import urlsplit

from rig.web.body import BodyRejected, canonical_json_body, non_finite_paths

__all__ = ["GuardMiddleware", "MAX_BODY_BYTES", "non_finite_paths"]

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

MAX_BODY_BYTES = 256 * 1024
"""The largest request body (bytes): a campaign request is a few kB."""
LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "[::1]", "::1")
UNSAFE_METHODS = ("POST", "PUT", "PATCH", "DELETE")
BODY_IGNORED = ("/api/control/estop",)
"""Routes whose body is never read (the E-stop answers whatever came with it)."""


def _host_name(host_header: str) -> str:
    host = host_header.strip().lower()
    if host.startswith("["):
        return host[: host.find("]") + 1] if "]" in host else host
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


class GuardMiddleware:
    """See the module docstring. ``loopback_only``: check the Host header."""

    def __init__(self, app: ASGIApp, *, loopback_only: bool = True,
                 max_body_bytes: int = MAX_BODY_BYTES) -> None:
        self.app = app
        self.loopback_only = loopback_only
        self.max_body_bytes = max_body_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1")
                   for k, v in scope.get("headers", [])}
        host = headers.get("host", "")
        if self.loopback_only and _host_name(host) not in LOOPBACK_HOSTS:
            await _reply(send, 421, f"the control page answers only to 127.0.0.1 or localhost, "
                                    f"not to the host {host[:80]!r}")
            return
        method = scope.get("method", "GET")
        if method in UNSAFE_METHODS:
            site = headers.get("sec-fetch-site", "")
            origin = headers.get("origin")
            if site in ("cross-site", "same-site"):
                await _reply(send, 403, "a request from another site is refused "
                                        f"(Sec-Fetch-Site: {site})")
                return
            if origin is not None and origin != "null" and \
                    urlsplit(origin).netloc.lower() != host.lower():
                await _reply(send, 403, f"a request from another origin is refused "
                                        f"(Origin: {origin[:80]})")
                return
            if origin == "null":
                await _reply(send, 403, "a request from an opaque origin is refused")
                return
        length = headers.get("content-length")
        if length is not None and length.isdigit() and int(length) > self.max_body_bytes:
            await _reply(send, 413, f"request body of {int(length)} bytes: at most "
                                    f"{self.max_body_bytes}")
            return
        if method not in UNSAFE_METHODS:
            await self.app(scope, receive, send)
            return
        # read the body (bounded), check it, then hand it to the app as it came
        chunks: list[bytes] = []
        size = 0
        while True:
            message = await receive()
            if message["type"] != "http.request":
                await self.app(scope, _replay([message], receive), send)
                return
            chunk = message.get("body", b"")
            size += len(chunk)
            if size > self.max_body_bytes:
                await _reply(send, 413, f"request body over {self.max_body_bytes} bytes")
                return
            chunks.append(chunk)
            if not message.get("more_body", False):
                break
        body = b"".join(chunks)
        if body and scope.get("path") not in BODY_IGNORED:
            try:
                body = canonical_json_body(body, headers.get("content-type"))
            except BodyRejected as exc:
                await _reply(send, exc.status, exc.detail)
                return
            scope = _as_json(scope, len(body))
        await self.app(scope, _replay([{"type": "http.request", "body": body,
                                        "more_body": False}], receive), send)


def _as_json(scope: Scope, length: int) -> Scope:
    """``scope`` with ``Content-Type: application/json`` and the re-written body's length."""
    kept = [(k, v) for k, v in scope.get("headers", [])
            if k.lower() not in (b"content-type", b"content-length", b"transfer-encoding")]
    return {**scope, "headers": [*kept, (b"content-type", b"application/json"),
                                 (b"content-length", str(length).encode())]}


def _replay(messages: list[Message], then: Receive) -> Receive:
    """The messages already read, then the connection's own (a disconnect, later)."""
    queue = list(messages)

    async def receive() -> Message:
        if queue:
            return queue.pop(0)
        return await then()
    return receive


async def _reply(send: Send, status: int, detail: Any) -> None:
    body = json.dumps({"detail": detail}).encode()
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", b"application/json"),
                            (b"content-length", str(len(body)).encode())]})
    await send({"type": "http.response.body", "body": body})
