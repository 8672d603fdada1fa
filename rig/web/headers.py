"""Security headers on every answer of the control page (issue 21 item 1).

A Content-Security-Policy that lets a page run only the scripts served by the app itself
(``/static/app.js``, the vendored uPlot): no inline ``<script>``, no ``onerror=`` attribute,
no ``javascript:`` URL, no ``eval``. So a unit name that carries markup into a page can never
run, even where escaping were missed. Figures are inline ``data:`` PNGs; styles may be inline
(uPlot and the reports set them; a style runs no code). The page cannot be framed.

FastAPI's own API docs (``/docs``, ``/redoc``) load Swagger UI / ReDoc with an inline script
from a CDN and show no stored data: they keep FastAPI's defaults.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any

__all__ = ["CONTENT_SECURITY_POLICY", "SecurityHeadersMiddleware"]

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

CONTENT_SECURITY_POLICY = (
    "default-src 'self'; script-src 'self'; script-src-attr 'none'; object-src 'none'; "
    "base-uri 'none'; form-action 'self'; frame-ancestors 'none'; connect-src 'self'; "
    "img-src 'self' data: blob:; style-src 'self' 'unsafe-inline'; font-src 'self'"
)
API_DOCS = ("/docs", "/docs/oauth2-redirect", "/redoc")

HEADERS = [
    (b"content-security-policy", CONTENT_SECURITY_POLICY.encode()),
    (b"x-content-type-options", b"nosniff"),
    (b"x-frame-options", b"DENY"),
    (b"referrer-policy", b"no-referrer"),
]


class SecurityHeadersMiddleware:
    """Adds :data:`HEADERS` to every HTTP answer (but the API docs' CSP, see module doc)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        docs = scope.get("path") in API_DOCS
        extra = [h for h in HEADERS if not (docs and h[0] == b"content-security-policy")]

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                names = {k.lower() for k, _ in message.get("headers", [])}
                message["headers"] = [*message.get("headers", []),
                                      *(h for h in extra if h[0] not in names)]
            await send(message)

        await self.app(scope, receive, send_with_headers)
