"""The production quality view on the control page: ``GET /spc`` (the charts of ``rig spc``
as a page) and ``GET /api/spc`` (every figure as JSON), for the store the page serves.

Lost motion, backlash and stiffness per unit over time as individuals/moving-range charts
with control limits, the out-of-control rules, Cp/Cpk against the campaign limits and the
seed 000 batch band of the design (rig/spc.py, docs/deployment.md). Computed in the page's
worker process (rig/web/workers.py): a large store never holds up the page.
"""

from __future__ import annotations

import datetime as dt
from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.responses import HTMLResponse, JSONResponse

from rig.errors import RigError
from rig.web.workers import run_in_worker

__all__ = ["router", "spc_document"]

router = APIRouter(tags=["quality"])

Design = Annotated[str | None, Query(max_length=200, description="Only this design "
                                     "(the unit's design name); default: every design.")]
Since = Annotated[dt.date | None, Query(description="Only tests started on or after this "
                                        "UTC date (ISO 8601).")]


def spc_document(store_root: str, samples: str | None, design: str | None,
                 since: str | None, html: bool) -> Any:
    """In the worker: the ``rig spc`` document (JSON) or its HTML page."""
    from rig.spc import spc_report
    from rig.spc_html import render_html
    from rig.store import Store

    store = Store(store_root, create=False, recover=False, samples=samples)
    try:
        doc = spc_report(store, design=design, since=since)
    finally:
        store.close()
    if not html:
        return doc
    page = render_html(doc)
    back = ('<p style="font:14px system-ui;margin:8px 0"><a href="/">&larr; control page</a>'
            ' &middot; the same figures: <a href="/api/spc">/api/spc</a></p>')
    return page.replace("<body>", "<body>" + back, 1)


def _compute(request: Request, design: str | None, since: dt.date | None, html: bool) -> Any:
    store = request.app.state.store
    where = store.url or str(store.root)
    samples = str(store.root) if store.url else None
    try:
        return run_in_worker(spc_document, where, samples, design,
                             None if since is None else since.isoformat(), html)
    except (RigError, ValueError) as exc:
        raise HTTPException(409, f"no quality view: {exc}") from exc


@router.get("/api/spc", summary="Production quality: I-MR charts, rules, Cp/Cpk, batch band "
            "(the JSON of `rig spc`)")
def spc_json(request: Request, design: Design = None, since: Since = None) -> JSONResponse:
    return JSONResponse(_compute(request, design, since, html=False))


@router.get("/spc", response_class=HTMLResponse, summary="Production quality charts (page)")
def spc_page(request: Request, design: Design = None, since: Since = None) -> HTMLResponse:
    return HTMLResponse(_compute(request, design, since, html=True))
