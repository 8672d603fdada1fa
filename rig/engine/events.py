"""Progress events of the engine and a thread-safe way to subscribe to them.

The CLI's progress bar and the web page subscribe; callbacks run on the engine's thread and
must be quick (a queue subscriber never blocks the engine: when its queue is full the oldest
event is dropped).
"""

from __future__ import annotations

import contextlib
import logging
import queue
import threading
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

log = logging.getLogger(__name__)

STATES = ("idle", "running", "paused", "completed", "aborted")


@dataclass(frozen=True)
class ProgressEvent:
    """What the engine is doing: ``kind`` one of "start", "step", "run_started",
    "run_finished", "paused", "resumed", "fault", "finished"; ``step`` (1-based) of
    ``n_steps``; times in s; ``run_label``/``run_id`` of the run being recorded (if any);
    ``message`` a readable line; ``data`` extra values (metrics of a finished run ...)."""

    kind: str
    state: str
    step: int
    n_steps: int
    elapsed_s: float
    remaining_s: float
    description: str = ""
    run_label: str | None = None
    run_id: str | None = None
    message: str = ""
    data: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


class EventHub:
    """Fan-out of events to callbacks and bounded queues; safe from any thread."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._callbacks: list[Callable[[ProgressEvent], None]] = []
        self._queues: list[queue.Queue[ProgressEvent]] = []

    def subscribe(self, callback: Callable[[ProgressEvent], None]) -> Callable[[], None]:
        """Call ``callback(event)`` for every event; returns a function that unsubscribes."""
        with self._lock:
            self._callbacks.append(callback)

        def unsubscribe() -> None:
            with self._lock, contextlib.suppress(ValueError):
                self._callbacks.remove(callback)

        return unsubscribe

    def queue(self, maxsize: int = 1000) -> queue.Queue[ProgressEvent]:
        """A new bounded queue receiving every event (oldest dropped when full)."""
        q: queue.Queue[ProgressEvent] = queue.Queue(maxsize=maxsize)
        with self._lock:
            self._queues.append(q)
        return q

    def publish(self, event: ProgressEvent) -> None:
        with self._lock:
            callbacks = list(self._callbacks)
            queues = list(self._queues)
        for cb in callbacks:
            try:
                cb(event)
            except Exception:  # a broken subscriber must not stop a measurement
                log.exception("progress subscriber %r failed", cb)
        for q in queues:
            while True:
                try:
                    q.put_nowait(event)
                    break
                except queue.Full:
                    with contextlib.suppress(queue.Empty):
                        q.get_nowait()
