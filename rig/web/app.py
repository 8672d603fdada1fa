"""The FastAPI app of the control page: ``create_app(settings, controller)``.

The lifespan opens the rig (``controller.start()``: on a thread, the page answers meanwhile)
and starts the live pump; leaving it stops any measurement (safe state) and closes the rig.
The page itself is plain HTML/CSS/JS from the package's static files (no build step, no
CDN: it works offline), uPlot vendored under ``static/vendor/uplot``; no inline script, so a
Content-Security-Policy forbids any (rig/web/headers.py).
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from importlib import resources

from fastapi import FastAPI, Request
from fastapi.exception_handlers import (
    http_exception_handler,
    request_validation_exception_handler,
)
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, Response
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException as StarletteHTTPException

from rig import __version__
from rig.core.redact import redact_text, without_paths
from rig.store import Store
from rig.web.controller import RigController
from rig.web.guard import GuardMiddleware
from rig.web.headers import SecurityHeadersMiddleware
from rig.web.live import LiveHub
from rig.web.models import plain_unit_loc
from rig.web.ratelimit import RATE_LIMITED, RateLimitMiddleware
from rig.web.settings import WebSettings
from rig.web.workers import shutdown_workers, warm_up

STATIC = resources.files("rig.web") / "static"

DESCRIPTION = """
The control page of backlash-rig: lab operators run the rig from a browser.

* **Viewers** (no token) can read the status, the history and watch the live stream.
* **Operators** send `Authorization: Bearer <token>` (printed by `rig serve`) to start,
  pause, resume, abort, tare and lock the input. The E-stop never needs a token.
* Live data: `GET /api/live` (server-sent events). Units are in the field names.
"""


def create_app(settings: WebSettings, controller: RigController | None = None, *,
               store: Store | None = None, hub: LiveHub | None = None) -> FastAPI:
    """The app. ``controller`` None: no rig (history only) on ``settings.store_root``."""
    store = store or (controller.store if controller is not None
                      else Store(settings.store_root))
    hub = hub or (controller.hub if controller is not None else LiveHub())
    controller = controller or RigController(store, hub, None)

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        hub.start()
        controller.start()
        warm_up("preview")
        try:
            yield
        finally:
            # the workers and the live pump stop while the rig closes (the slow part: the
            # safe state, the devices, a simulated rig's processes)
            shutdown_workers()
            await hub.stop()
            await asyncio.to_thread(controller.close)

    app = FastAPI(title="backlash-rig control page", version=__version__,
                  description=DESCRIPTION, lifespan=lifespan, responses=RATE_LIMITED)
    app.state.settings = settings
    app.state.store = store
    app.state.hub = hub
    app.state.controller = controller

    from rig.web.routes import control as routes_control
    from rig.web.routes import history as routes_history
    from rig.web.routes import live as routes_live

    app.include_router(routes_control.router)
    app.include_router(routes_history.router)
    store_roots = routes_history.store_roots
    app.include_router(routes_live.router)
    from rig.web.routes import spc as routes_spc

    app.include_router(routes_spc.router)
    app.add_middleware(GuardMiddleware, loopback_only=settings.check_host)
    # before the guard: a client over its limit is answered before its body is read
    app.add_middleware(RateLimitMiddleware, token=lambda: settings.token)
    app.add_middleware(SecurityHeadersMiddleware)  # outermost: on every answer (CSP), a 429 too
    app.mount("/static", StaticFiles(directory=str(STATIC)), name="static")

    @app.exception_handler(StarletteHTTPException)
    async def redacted_error(request: Request, exc: StarletteHTTPException) -> Response:
        """Every error message without a password or token (a store error names the store
        by its connection string; rig/core/redact.py), and without a folder path of the
        server (an unreadable run or campaign names its file: its last part is kept)."""
        if isinstance(exc.detail, str):
            exc.detail = without_paths(redact_text(exc.detail), store_roots(store))
        return await http_exception_handler(request, exc)

    @app.exception_handler(RequestValidationError)
    async def field_errors(request: Request, exc: RequestValidationError) -> Response:
        """A 422 naming each wrong field by its path in the body; a unit's field as
        ``body.unit.FIELD`` whatever the unit's kind (without pydantic's union tag)."""
        errors = [{**e, "loc": plain_unit_loc(e.get("loc") or ())} for e in exc.errors()]
        return await request_validation_exception_handler(
            request, RequestValidationError(errors, body=exc.body))

    @app.get("/", include_in_schema=False)
    def index(request: Request) -> FileResponse:
        return FileResponse(str(STATIC / "index.html"), media_type="text/html",
                            headers={"Cache-Control": "no-cache"})

    return app
