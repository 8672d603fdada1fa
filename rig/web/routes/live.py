"""The live stream: server-sent events, one bounded queue per page (rig.web.live)."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator

from fastapi import APIRouter, Request
from fastapi.sse import EventSourceResponse, ServerSentEvent

router = APIRouter(prefix="/api", tags=["live"])

KEEPALIVE_S = 5.0


@router.get("/live", response_class=EventSourceResponse,
            summary="Live data (server-sent events): decimated rows, progress, state",
            description="Events: `rows` (t_s, torque_Nm, twist_arcmin arrays, t_wall_s of the "
                        "newest sample), `rows_replay` (the current run so far, first), "
                        "`progress` (engine events), `state`, `status` (devices changed), "
                        "`run_begin`. Each page has its own bounded queue: a slow page loses "
                        "its oldest batches, never the acquisition's samples.")
async def live(request: Request) -> AsyncIterator[ServerSentEvent]:
    hub = request.app.state.hub
    client = hub.connect()
    try:
        yield ServerSentEvent(event="hello", data={"clients": hub.n_clients}, retry=1000)
        while True:
            try:
                message = await asyncio.wait_for(client.queue.get(), KEEPALIVE_S)
            except TimeoutError:
                if await request.is_disconnected():
                    return
                yield ServerSentEvent(comment="keepalive")
                continue
            if message.get("type") == "bye":
                return
            if client.dropped:
                message = {**message, "dropped": client.dropped}
            yield ServerSentEvent(event=message.get("type", "message"), data=message)
    finally:
        hub.disconnect(client)
