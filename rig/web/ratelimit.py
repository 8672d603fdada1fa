"""Rate limits for requests without the operator token (issue 21 item 10).

Sixty token-less clients asking for plan previews as fast as they could made runs abort:
every request was read, parsed and validated before a limit said no, and that CPU was taken
from acquisition. This pure ASGI middleware sits in front of everything else and answers a
client over its limit with **429** and ``Retry-After`` (whole seconds) before its body is
read.

- Per client address, two token buckets: every token-less request
  (:data:`GENERAL_RATE`), and the plan preview on top (:data:`PREVIEW_RATE`: a page
  previews on a click).
- A request with the operator token is never limited here (the operator's own page keeps
  working under a flood from the same address); a wrong token counts as none.
- The E-stop is never limited: a stop must never wait.
- A refused request gets its 429 after :data:`TARPIT_S` (an ``asyncio`` sleep: no thread,
  no CPU): a flood that ignores ``Retry-After`` and asks again at once on the same
  connection is slowed to one request per second per connection, and the server's event
  loop stays free for the E-stop. Measured with 60 such clients beside a campaign: 240
  refusals a second without it.
"""

from __future__ import annotations

import asyncio
import json
import math
import secrets
import time
from collections.abc import Awaitable, Callable, MutableMapping
from dataclasses import dataclass
from typing import Any

__all__ = ["RateLimitMiddleware", "TokenBucket", "GENERAL_RATE", "PREVIEW_RATE",
           "NEVER_LIMITED", "RATE_LIMITED"]

Scope = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[MutableMapping[str, Any]]]
Send = Callable[[MutableMapping[str, Any]], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

GENERAL_RATE = (20.0, 100.0)
"""Token-less requests per client address: 20 per second, bursts of 100 (a page load is
about 20 requests, a viewer polls the status once a second)."""
PREVIEW_RATE = (1.0, 10.0)
"""Token-less plan previews per client address: 1 per second, bursts of 10."""
PREVIEW_PATH = "/api/plan/preview"
NEVER_LIMITED = ("/api/control/estop",)
TARPIT_S = 1.0
"""Delay (s) of a 429 answer."""
RATE_LIMITED = {429: {"description": "Too many requests without the operator token from this "
                                     "address: retry after the Retry-After seconds.",
                      "content": {"application/json": {"schema": {
                          "type": "object", "properties": {"detail": {"type": "string"}}}}}}}
"""The 429 answer, for the OpenAPI description of every route."""
MAX_CLIENTS = 1000
"""Client addresses remembered; beyond it the idle (full) buckets are forgotten."""


@dataclass
class TokenBucket:
    """``rate`` tokens per second up to ``burst``; a request takes one (times in s)."""

    rate: float
    burst: float
    tokens: float = math.nan
    t: float = 0.0

    def take(self, now: float) -> float:
        """0 if a token was taken, else the seconds until one is there."""
        if math.isnan(self.tokens):
            self.tokens, self.t = self.burst, now
        self.tokens = min(self.burst, self.tokens + (now - self.t) * self.rate)
        self.t = now
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return 0.0
        return (1.0 - self.tokens) / self.rate

    def full(self, now: float) -> bool:
        return math.isnan(self.tokens) or \
            self.tokens + (now - self.t) * self.rate >= self.burst


class RateLimitMiddleware:
    """See the module docstring. ``token``: returns the operator token (None: no limits
    apply to anyone, the page has no operator)."""

    def __init__(self, app: ASGIApp, *, token: Callable[[], str | None],
                 general: tuple[float, float] = GENERAL_RATE,
                 preview: tuple[float, float] = PREVIEW_RATE) -> None:
        self.app = app
        self.token = token
        self.general = general
        self.preview = preview
        self._buckets: dict[tuple[str, str], TokenBucket] = {}

    def _operator(self, scope: Scope) -> bool:
        expected = self.token()
        if not expected:
            return True
        for key, value in scope.get("headers", []):
            if key.lower() == b"authorization":
                scheme, _, given = value.decode("latin-1").partition(" ")
                return scheme.lower() == "bearer" and secrets.compare_digest(
                    given.strip().encode(), expected.encode())
        return False

    def _wait_s(self, client: str, kind: str, rate: tuple[float, float], now: float
                ) -> float:
        bucket = self._buckets.get((client, kind))
        if bucket is None:
            if len(self._buckets) >= MAX_CLIENTS:
                self._forget_idle(now)
            bucket = self._buckets[(client, kind)] = TokenBucket(*rate)
        return bucket.take(now)

    def _forget_idle(self, now: float) -> None:
        for key in [k for k, b in self._buckets.items() if b.full(now)]:
            del self._buckets[key]

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        path = scope.get("path", "")
        if scope["type"] != "http" or path in NEVER_LIMITED or self._operator(scope):
            await self.app(scope, receive, send)
            return
        client = (scope.get("client") or ("?", 0))[0]
        now = time.monotonic()
        wait = self._wait_s(client, "all", self.general, now)
        what = "requests without the operator token"
        if not wait and path == PREVIEW_PATH and scope.get("method") == "POST":
            wait = self._wait_s(client, "preview", self.preview, now)
            what = "plan previews without the operator token"
            rate = self.preview
        else:
            rate = self.general
        if not wait:
            await self.app(scope, receive, send)
            return
        retry = max(1, math.ceil(wait))
        await asyncio.sleep(TARPIT_S)
        body = json.dumps({"detail": f"too many {what} from {client} (at most "
                                     f"{rate[0]:g} per second, bursts of {rate[1]:g}): "
                                     f"retry after {retry} s"}).encode()
        await send({"type": "http.response.start", "status": 429,
                    "headers": [(b"content-type", b"application/json"),
                                (b"content-length", str(len(body)).encode()),
                                (b"retry-after", str(retry).encode())]})
        await send({"type": "http.response.body", "body": body})
