"""The live stream to browsers: the acquisition never waits for a slow page.

Path of a sample (docs/web.md, "Live data"):

1. the engine appends each merged row to the run in the store (full rate, on disk) through
   :class:`rig.web.live_tap.TapStore`, which also hands the row to :meth:`LiveHub.add_rows`:
   an O(1) append to a bounded buffer under a lock, nothing else on the engine's thread;
2. the hub's pump (an asyncio task of the app, ``tick_s`` = 50 ms) takes the new rows,
   decimates them for display (at most ``max_points_per_tick`` per tick, evenly spaced, the
   newest always kept), keeps them as the current run's display loop (bounded) and puts one
   batch into every client's queue;
3. each client (a server-sent-events response) has its own bounded queue: when a browser
   falls behind, its *oldest* batches are dropped, never the acquisition's samples.

Batches carry ``t_wall_s`` of their newest sample (host wall clock, s) so the page can
measure the latency from a sample measured to the sample drawn (bench/bench_web.py).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

CLIENT_QUEUE_BATCHES = 64
"""Batches a client may fall behind (~3 s at 20 Hz) before its oldest are dropped."""
PENDING_ROWS_MAX = 200_000
"""Rows waiting for the pump (minutes at 1 kHz); beyond, the oldest are dropped (display
only: the store has them all)."""


def decimate(rows: list[tuple[float, ...]], max_points: int) -> list[tuple[float, ...]]:
    """At most ``max_points`` rows, evenly spaced by index, the last row always kept."""
    n = len(rows)
    if n <= max_points:
        return rows
    if max_points <= 1:
        return rows[-1:]
    step = (n - 1) / (max_points - 1)
    return [rows[round(i * step)] for i in range(max_points)]


def _finite(value: float | None) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


@dataclass(eq=False)
class ClientQueue:
    """One browser's bounded queue of messages (oldest dropped when full)."""

    queue: asyncio.Queue[dict[str, Any]] = field(
        default_factory=lambda: asyncio.Queue(maxsize=CLIENT_QUEUE_BATCHES))
    dropped: int = 0

    def put(self, message: dict[str, Any]) -> None:
        while True:
            try:
                self.queue.put_nowait(message)
                return
            except asyncio.QueueFull:
                with contextlib.suppress(asyncio.QueueEmpty):
                    self.queue.get_nowait()
                    self.dropped += 1


class LiveHub:
    """Rows and events from the engine's threads to every connected page (see module doc).

    Rows are ``(t_s, torque_Nm, twist_arcmin, t_wall_s)``: run time (s), torque (N*m),
    output twist (arcmin, as the encoder reads it: the page centres the loop) and the host
    wall-clock time the sample was measured (s).
    """

    def __init__(self, *, tick_s: float = 0.05, max_points_per_tick: int = 50,
                 display_points: int = 20_000) -> None:
        self.tick_s = tick_s
        self.max_points_per_tick = max_points_per_tick
        self._lock = threading.Lock()
        self._pending: deque[tuple[float, ...]] = deque(maxlen=PENDING_ROWS_MAX)
        self._events: deque[dict[str, Any]] = deque(maxlen=1000)
        self._display: deque[tuple[float, ...]] = deque(maxlen=display_points)
        self._run_id: str | None = None
        self._clients: set[ClientQueue] = set()
        self._task: asyncio.Task | None = None
        self._closing = False
        self.rows_in = 0
        self.batches_out = 0

    # -- from any thread (the engine's) ------------------------------------------------------
    def begin_run(self, run_id: str, label: str | None = None, test: str | None = None) -> None:
        """A new run is being recorded: the display loop starts empty. ``label``: the plan's
        name of the run (``pos090-a100-r0``), which the page shows with the id. ``test``: the
        run's test kind when it is not a loop (``transmission_error``: the page shows its TE
        panel, never a loop, from the first event on)."""
        with self._lock:
            self._pending.clear()
            self._run_id = run_id
            self._events.append({"type": "run_begin", "run_id": run_id,
                                 **({"label": label} if label else {}),
                                 **({"test": test} if test else {})})

    def add_rows(self, rows: list[tuple[float, ...]]) -> None:
        """Queue rows for display (cheap; called on the acquisition thread)."""
        with self._lock:
            self._pending.extend(rows)
            self.rows_in += len(rows)

    def add_event(self, event: dict[str, Any]) -> None:
        """Queue an event (progress, state, fault) for every page."""
        with self._lock:
            self._events.append(event)

    # -- the pump (asyncio) -------------------------------------------------------------------
    def start(self) -> None:
        """Start the pump on the running event loop (the app's lifespan)."""
        self._task = asyncio.create_task(self._pump(), name="rig live pump")

    async def stop(self) -> None:
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        self.close_streams()

    def close_streams(self) -> None:
        """End every client's stream (a ``bye`` each; a client connecting later gets one at
        once): the server is stopping. Called on the event loop (rig/web/server.py) before the
        server waits for its connections, so that no stream holds the stop up."""
        self._closing = True
        for client in list(self._clients):
            client.put({"type": "bye"})

    async def _pump(self) -> None:
        while True:
            await asyncio.sleep(self.tick_s)
            self.pump_once()

    def pump_once(self) -> None:
        """Move what came since the last tick to every client (one batch, then events)."""
        with self._lock:
            rows = list(self._pending)
            self._pending.clear()
            events = list(self._events)
            self._events.clear()
            run_id = self._run_id
        for event in events:
            if event.get("type") == "run_begin":
                self._display.clear()
            self._broadcast(event)
        if rows:
            shown = decimate(rows, self.max_points_per_tick)
            self._display.extend(shown)
            self._broadcast(self._batch(run_id, shown, len(rows)))

    @staticmethod
    def _batch(run_id: str | None, rows: list[tuple[float, ...]], n_measured: int
               ) -> dict[str, Any]:
        return {
            "type": "rows", "run_id": run_id, "n_measured": n_measured,
            "t_s": [_finite(r[0]) for r in rows],
            "torque_Nm": [_finite(r[1]) for r in rows],
            "twist_arcmin": [_finite(r[2]) for r in rows],
            **({"output_deg": [_finite(r[4]) for r in rows],
                "te_arcsec": [_finite(r[5]) for r in rows],
                "direction": [_finite(r[6]) for r in rows]}
               if rows and len(rows[-1]) >= 7 else {}),
            "t_wall_s": rows[-1][3],
            "t_sent_s": time.time(),
        }

    def _broadcast(self, message: dict[str, Any]) -> None:
        for client in list(self._clients):
            client.put(message)
        if message.get("type") == "rows":
            self.batches_out += 1

    # -- clients --------------------------------------------------------------------------------
    def connect(self) -> ClientQueue:
        """A new client; its first message is the current run's display loop so far."""
        client = ClientQueue()
        rows = list(self._display)
        if rows:
            client.put(self._batch(self._run_id, rows, 0) | {"type": "rows_replay"})
        if self._closing:
            client.put({"type": "bye"})
        self._clients.add(client)
        return client

    def disconnect(self, client: ClientQueue) -> None:
        self._clients.discard(client)

    @property
    def n_clients(self) -> int:
        return len(self._clients)
