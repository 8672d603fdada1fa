"""The production quality view on the control page: ``GET /spc`` (the charts of ``rig spc``
as a page) and ``GET /api/spc`` (every figure as JSON), for the store the page serves.

Lost motion, backlash and stiffness per unit over time as individuals/moving-range charts
with control limits, the out-of-control rules, Cp/Cpk against each unit's own campaign
limits and the seed 000 batch band of the design (rig/reports/spc/__init__.py, docs/deployment.md).
Computed in the page's worker process (rig/web/workers.py): a large store never holds up the page.
"""

from __future__ import annotations

import datetime as dt
from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.responses import HTMLResponse, JSONResponse

from rig.core.errors import RigError
from rig.web.models import ErrorBody
from rig.web.routes.history import ERROR_JSON
from rig.web.workers import run_in_worker

__all__ = ["router", "spc_document"]

router = APIRouter(tags=["quality"])
ERRORS: dict[int | str, dict[str, Any]] = {
    400: {"model": ErrorBody, "content": ERROR_JSON,
          "description": "``since`` is not a calendar date."},
    409: {"model": ErrorBody, "content": ERROR_JSON,
          "description": "The store cannot give the view (the message says why)."}}

Design = Annotated[str | None, Query(max_length=200, description="Only this design "
                                     "(the unit's design name, or the label or design "
                                     "key of one build of it); default: every design.")]
Since = Annotated[str | None, Query(pattern=r"^\d{4}-\d{2}-\d{2}$", description="Only tests "
                                    "started on or after this UTC date (YYYY-MM-DD).")]


def spc_document(store_root: str, samples: str | None, design: str | None,
                 since: str | None, html: bool) -> Any:
    """In the worker: the ``rig spc`` document (JSON) or its HTML page."""
    from rig.reports.spc import spc_report
    from rig.reports.spc.html import render_html
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


def _compute(request: Request, design: str | None, since: str | None, html: bool) -> Any:
    if since is not None:
        try:
            dt.date.fromisoformat(since)
        except ValueError as exc:
            raise HTTPException(400, f"since: not a date: {since!r}") from exc
    store = request.app.state.store
    where = store.url or str(store.root)
    samples = str(store.root) if store.url else None
    try:
        return run_in_worker(spc_document, where, samples, design, since, html)
    except (RigError, ValueError) as exc:
        raise HTTPException(409, f"no quality view: {exc}") from exc


@router.get("/api/spc", responses=ERRORS,
            summary="Production quality: I-MR charts, rules, Cp/Cpk, batch band (the JSON of "
                    "`rig spc`)")
def spc_json(request: Request, design: Design = None, since: Since = None) -> JSONResponse:
    return JSONResponse(_compute(request, design, since, html=False))


@router.get("/spc", response_class=HTMLResponse, responses=ERRORS,
            summary="Production quality charts (page)")
def spc_page(request: Request, design: Design = None, since: Since = None) -> HTMLResponse:
    return HTMLResponse(_compute(request, design, since, html=True))
