"""The handle of one run being recorded into the store (see :meth:`rig.store.Store.begin_run`)."""

from __future__ import annotations

import logging
import threading
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

from rig.core.durable import is_disk_full
from rig.core.errors import RigError
from rig.runformat import SamplesAppender
from rig.store.backend import to_json
from rig.store.files import WriterLock, finalise_samples
from rig.store.ids import StoreDiskFull, StoreError
from rig.store.records import FINAL_STATUSES, RunInfo


class RunCloser(Protocol):
    """What a recorder needs of its store (:class:`rig.store.Store`): close the run in the
    index and read it back. A protocol, so that the recorder does not import the store
    that imports it."""

    def _finalize_run(self, run_id: str, folder: Path, status: str, reason: str | None,
                      result: dict[str, Any] | None, n_samples: int | None,
                      extra_meta: dict[str, Any]) -> bool: ...

    def get_run(self, run_id: str) -> RunInfo: ...

    def pending_runs(self) -> list[str]: ...

    def local_run_info(self, run_id: str) -> RunInfo: ...

    def release_disk_reserve(self) -> None: ...

    @property
    def location(self) -> str: ...

log = logging.getLogger("rig.store")


class RunRecorder:
    """Appends a run's samples to its ``samples.csv`` and closes the run in the store.

    At the end (:meth:`finish`) the CSV stream is turned into ``samples.parquet``
    (:func:`rig.store.files.finalise_samples`); a run whose process dies before that keeps
    its CSV, which the next store opening finalises (:meth:`rig.store.Store.recover`).

    Use as a context manager: leaving the block normally finishes the run as "completed"
    (unless :meth:`finish` was called); leaving it with an exception finishes it as
    "aborted" with the exception's type and text as the reason, keeping every sample
    appended so far, and lets the exception go on.

    Attributes: ``run_id``; ``path`` (the run folder); ``columns``; ``meta`` (the run.json
    written at the start); ``warnings`` (calibrations past due at the start);
    ``samples`` (the underlying :class:`rig.runformat.SamplesAppender`); ``n_samples``.
    """

    def __init__(
        self,
        store: RunCloser,
        run_id: str,
        path: Path,
        meta: dict[str, Any],
        appender: SamplesAppender,
        lock: WriterLock,
        warnings: list[str],
    ) -> None:
        self._store = store
        self.run_id = run_id
        self.path = path
        self.meta = meta
        self.samples = appender
        self.columns = list(appender.columns)
        self.warnings = list(warnings)
        self.n_samples = 0
        self._lock = lock
        self._count_lock = threading.Lock()
        self._finished = False
        self.indexed = True
        """False when the run was finalised locally only (the database was unreachable at
        its end); the store indexes it when the database returns."""

    @property
    def finished(self) -> bool:
        return self._finished

    def append(self, row: Sequence[float | str | None] | Mapping[str, float | str | None]) -> None:
        """Append one sample row: values in ``columns`` order, or a mapping by column name
        (absent columns are missing values). Units as the column names say (s, N·m, deg, °C).
        Rows reach the disk within the appender's flush interval (0.5 s by default).
        """
        if isinstance(row, Mapping):
            unknown = [k for k in row if k not in self.columns]
            if unknown:
                raise ValueError(
                    f"run {self.run_id}: unknown column(s) {unknown}; columns are {self.columns}"
                )
            row = [row.get(c) for c in self.columns]
        try:
            self.samples.append(row)
        except OSError as e:
            if is_disk_full(e):
                raise self.disk_full() from None
            raise
        with self._count_lock:
            self.n_samples += 1

    def disk_full(self) -> StoreDiskFull:
        """The one line of a run stopped by a full disk: how many samples it keeps."""
        return StoreDiskFull(f"the store's disk is full ({self._store.location}): "
                             f"{self.samples.rows_written} samples kept, run aborted")

    def finish(
        self,
        status: str = "completed",
        reason: str | None = None,
        result: dict[str, Any] | None = None,
        extra: dict[str, Any] | None = None,
    ) -> RunInfo:
        """Close the samples file, turn it into Parquet, record the end of the run; return
        its index row.

        ``status``: "completed" or "aborted" (an aborted run needs a ``reason``). A run whose
        samples could not all be written (a full disk) is closed as aborted with that reason,
        its samples kept whole in samples.csv, and (when it was to be "completed") raises
        :class:`StoreDiskFull` once recorded.
        ``result``: the run's metrics (a JSON-able dict, e.g. ``{"lost_motion_arcmin": 1.2}``),
        stored in run.json under "result" and in the index as ``metrics``.
        run.json is rewritten atomically with "status", "reason", "result", "finished_at"
        and "n_samples" (and the top-level keys of ``extra``, e.g. ``outcome``). A bad argument
        raises ValueError and leaves the run open.
        """
        if self._finished:
            raise StoreError(f"run {self.run_id} is already finished")
        if status not in FINAL_STATUSES:
            raise ValueError(f"status must be one of {FINAL_STATUSES}, got {status!r}")
        if status == "aborted" and (not isinstance(reason, str) or not reason.strip()):
            raise ValueError("an aborted run needs a reason (a non-empty string)")
        if reason is not None and not isinstance(reason, str):
            raise ValueError(f"reason must be a string, got {reason!r}")
        if result is not None and not isinstance(result, dict):
            raise ValueError(f"result must be a dict of metrics, got {type(result).__name__}")
        to_json(result)
        to_json(extra)
        self.samples.close()
        full = self.samples.error is not None and is_disk_full(self.samples.error)
        n_samples = self.samples.rows_written if self.samples.error else self.n_samples
        cut_short = full and status == "completed"
        if full:  # the samples stay whole in samples.csv; the reserve makes room for the record
            if cut_short:
                status, reason = "aborted", str(self.disk_full())
                extra = {**(extra or {}), "outcome": "incomplete"}
            self._store.release_disk_reserve()
        else:
            try:
                finalise_samples(self.path)
            except (RigError, OSError, ValueError) as e:  # the samples stay in samples.csv
                log.warning("run %s: samples kept in CSV, not turned into Parquet: %s",
                            self.run_id, e)
        try:
            changed = self._store._finalize_run(
                self.run_id, self.path, status, reason, result, n_samples,
                dict(extra or {}),
            )
        finally:
            self._finished = True
            self._lock.release(remove=True)
        if not changed:
            raise StoreError(
                f"run {self.run_id} was no longer 'running' in the index when it was finished"
            )
        if cut_short:  # recorded as aborted; the caller that thought it completed is told
            raise self.disk_full()
        if self.run_id in self._store.pending_runs():
            self.indexed = False
            return self._store.local_run_info(self.run_id)
        return self._store.get_run(self.run_id)

    def __enter__(self) -> RunRecorder:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: object) -> None:
        if self._finished:
            return
        if exc is None:
            self.finish("completed")
        else:
            text = str(exc).strip()
            self.finish("aborted", reason=f"{exc_type.__name__}: {text}" if text
                        else exc_type.__name__)  # type: ignore[union-attr]
