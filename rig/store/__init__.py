"""The measurement store: run folders in rig-run/1 plus an index (docs/store.md).

The index is ``index.sqlite`` in the store folder (the embedded default) or a PostgreSQL
database (``Store("postgresql://...", samples=DIR)``; docs/deployment.md), whose run
folders go to the samples folder ``DIR`` that every rig reaches. Layout of a store root
(the samples folder of a database store)::

    index.sqlite              runs and campaigns: metadata and status (WAL mode)
    runs/<run_id>/            a run outside any campaign: run.json + samples.parquet
    campaigns/<campaign_id>/  a rig-campaign/1 folder: campaign.json + one folder per run

Samples go to ``samples.csv`` as they are measured (flushed at least every 0.5 s), never
into SQLite; when the run ends they are turned into ``samples.parquet`` (the CSV removed
once the Parquet file is in place). A process killed during a run keeps its samples in the
CSV; the next :class:`Store` opened on the root marks the run "aborted" and finalises its
samples to Parquet (:meth:`Store.recover`). Live writers hold a ``flock``
on their run folder, so a reader opening the store never aborts a run still being measured.

The default root is ``$RIG_STORE`` if set, else ``./rig-store`` (:func:`default_store_root`);
the samples folder of a database store is ``samples=`` or ``$RIG_SAMPLES_DIR``.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import socket
from collections.abc import Callable, Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from rig import __version__
from rig.core.durable import is_disk_full
from rig.core.errors import RigError
from rig.runformat import (
    CAMPAIGN_FORMAT,
    CAMPAIGN_JSON,
    REQUIRED_COLUMNS,
    RUN_FORMAT,
    RUN_JSON,
    SAMPLES_CSV,
    SAMPLES_PARQUET,
    Run,
    SamplesAppender,
    read_run,
)
from rig.store.backend import IndexBackend, RunFilter, to_json
from rig.store.files import (
    WriterLock,
    cut_incomplete_tail,
    finalise_samples,
    sync_dir,
    write_json_atomic,
)
from rig.store.ids import (
    ID_PATTERN,
    InvalidIdError,
    StoreDiskFull,
    StoreError,
    StoreReadOnly,
    StoreUnavailable,
    UnknownIdError,
    id_candidates,
    safe_label,
    utc_now_iso,
    validate_id,
)
from rig.store.index import INDEX_NAME, SqliteIndex
from rig.store.recorder import RunRecorder
from rig.store.records import (
    FINAL_STATUSES,
    RUN_STATUSES,
    CampaignInfo,
    RunInfo,
    campaign_info,
    check_calibration,
    past_due,
    run_info,
)

__all__ = [
    "RECOVERED_REASON",
    "CampaignInfo",
    "InvalidIdError",
    "RunInfo",
    "RunRecorder",
    "Store",
    "StoreDiskFull",
    "StoreError",
    "StoreReadOnly",
    "StoreUnavailable",
    "UnknownIdError",
    "default_store_root",
]

log = logging.getLogger(__name__)

STORE_ENV = "RIG_STORE"
SAMPLES_ENV = "RIG_SAMPLES_DIR"
DATABASE_SCHEMES = ("postgresql://", "postgres://")
DEFAULT_STORE_DIR = "rig-store"
PENDING_DIR = "pending-index"
"""Runs finalised while the database was unreachable: one JSON file per run, removed once
the run is indexed (docs/store.md, "A database outage")."""
DISK_RESERVE = ".disk-reserve"
"""A file of :data:`DISK_RESERVE_BYTES` kept in the store folder while runs begin: when the
disk fills during a run it is removed, so that the run's abort record (run.json,
campaign.json, the index) still finds room (docs/store.md, "A full disk")."""
DISK_RESERVE_BYTES = 1 << 20
RECORD_SLACK_S = 2.0
"""A run.json modified later than this after its run's end (s) was changed after it was
indexed: the store reads it again (:meth:`Store._as_recorded`)."""
RUN_RETRY_ENV = "RIG_STORE_RUN_RETRY_S"
DEFAULT_RUN_RETRY_S = 5.0
"""How long a run's start or end waits for a lost database before the run is kept locally
(s): the drive is at zero torque and enabled meanwhile, so it is short."""
RECOVERED_REASON = "process ended during the run (found at next start)"
RUN_RESERVED_KEYS = (
    "format", "run_id", "started_at", "finished_at", "status", "reason", "result",
    "n_samples", "software_version", "campaign_id", "recovery",
)
CAMPAIGN_RESERVED_KEYS = (
    "format", "name", "campaign_id", "status", "started_at", "finished_at", "summary", "runs",
)


def default_store_root() -> Path | str:
    """``$RIG_STORE`` if set and not empty, else ``./rig-store`` (relative to the cwd).
    A database URL in ``$RIG_STORE`` is returned as it is (a str)."""
    value = os.environ.get(STORE_ENV) or DEFAULT_STORE_DIR
    return value if is_database_url(value) else Path(value)


def is_database_url(value: object) -> bool:
    """Does ``value`` name a database store (``postgresql://...`` or ``postgres://...``)?"""
    return isinstance(value, str) and value.startswith(DATABASE_SCHEMES)


def outcome_word(value: Any) -> str | None:
    """run.json's ``outcome`` as the index keeps it: a string as it is; a bool or a dict
    with ``passed`` as "pass"/"fail"; a dict's ``verdict``/``status``/``result`` string."""
    if isinstance(value, bool):
        return "pass" if value else "fail"
    if isinstance(value, str):
        return value or None
    if isinstance(value, dict):
        for key in ("verdict", "status", "result", "outcome"):
            if isinstance(value.get(key), str) and value[key]:
                return value[key]
        if isinstance(value.get("passed"), bool):
            return "pass" if value["passed"] else "fail"
    return None


class Store:
    """A store: run folders plus an index. Safe to open from many processes.

    ``root``: the store folder (index in ``index.sqlite`` there), or a database URL
    ``postgresql://...`` (the index in PostgreSQL; the run folders then go to ``samples``,
    else ``$RIG_SAMPLES_DIR``). ``create``: make the folder and the index if absent (else a
    missing index raises :class:`StoreError`). An index made by an older version is
    migrated. ``recover``: run :meth:`recover` now (its result is kept in ``recovered``).
    ``busy_timeout_s``: how long a call waits for another process's SQLite write
    transaction before failing (writes last milliseconds; the default is generous).
    ``reconnect_s``: how long a call to a database store retries a lost connection (a
    server restart) before failing; samples keep going to their files meanwhile.
    ``run_retry_s`` (default ``$RIG_STORE_RUN_RETRY_S``, else 5 s): how long a run's start
    and end wait for a lost database; past it a finishing run is finalised locally (its
    run.json with status, metrics and outcome, its samples in Parquet) and indexed when the
    database returns (:meth:`index_pending`: at every store opening, listing and run start,
    or when called), and a starting run raises :class:`StoreUnavailable`.
    """

    def __init__(
        self,
        root: str | Path,
        *,
        create: bool = True,
        recover: bool = True,
        busy_timeout_s: float = 30.0,
        samples: str | Path | None = None,
        reconnect_s: float = 60.0,
        run_retry_s: float | None = None,
    ) -> None:
        self.busy_timeout_s = float(busy_timeout_s)
        if run_retry_s is None:
            run_retry_s = _env_seconds(RUN_RETRY_ENV, DEFAULT_RUN_RETRY_S)
        self.run_retry_s = float(run_retry_s)
        self.url: str | None = None
        self._index: IndexBackend
        if is_database_url(root):
            from rig.core.redact import redact
            from rig.store.index_pg import PostgresIndex

            folder = samples if samples not in (None, "") else os.environ.get(SAMPLES_ENV)
            if not folder:
                raise StoreError(
                    f"the store {redact(root)} is a database: give the folder for the "
                    f"run files (shared by every rig) with --samples DIR or {SAMPLES_ENV}"
                )
            self.url = str(root)
            self.root = Path(folder).absolute()
            self._index = PostgresIndex(self.url, reconnect_s=reconnect_s)
        else:
            self.root = Path(root).absolute()
            self._index = SqliteIndex(self.root, self.busy_timeout_s)
        if not create and not self._index.exists():
            what = f"no {INDEX_NAME}" if self.url is None else "no rig tables in the database"
            raise StoreError(
                f"no store at {self.location} ({what}); a store is created by the first "
                "measurement run into it"
            )
        try:
            (self.root / "runs").mkdir(parents=True, exist_ok=True)
            (self.root / "campaigns").mkdir(exist_ok=True)
        except OSError as e:
            raise StoreError(f"cannot create the store at {self.root}: {e.strerror or e}") from e
        self._index.ensure_schema()
        recover = recover and self.read_only is None  # nothing can be closed in a read-only one
        self.indexed_at_open: list[str] = self.index_pending() if recover else []
        self.recovered: list[str] = self.recover() if recover else []

    @property
    def read_only(self) -> str | None:
        """Why this process may only read the store (a read-only file system, no write
        permission); None when it may write. Reading works either way."""
        return self._index.read_only

    def check_writable(self, what: str) -> None:
        """:class:`StoreReadOnly` (one line) when the store is read-only; ``what`` says what
        needed to write ("a measurement", "the import")."""
        if self.read_only is not None:
            raise StoreReadOnly(f"the store {self.location} is read-only ({self.read_only}): "
                                f"{what} cannot be stored there")

    @property
    def location(self) -> str:
        """The store as users name it: its folder, or its database URL without password."""
        return self._index.location

    @property
    def backend(self) -> str:
        """"sqlite" or "postgresql"."""
        return "sqlite" if self.url is None else "postgresql"

    def close(self) -> None:
        """Drop the database connections this object holds (they reopen when used)."""
        self._index.close()

    def __repr__(self) -> str:
        return f"Store({self.location!r})"

    # ----------------------------------------------------------------------- runs

    def begin_run(
        self,
        meta: dict[str, Any],
        columns: list[str],
        *,
        campaign_id: str | None = None,
        flush_interval_s: float = 0.5,
    ) -> RunRecorder:
        """Start a run: create its folder, write run.json and the CSV header, index it.

        ``meta`` is the rig-run/1 metadata known at the start ("unit", "test", "sensors", ...)
        plus the keys the index reads: ``unit.serial``, ``operator``, ``rig_id``,
        ``plan`` (``{"name": ..., "version": ...}``) and ``calibration`` (a list of
        ``{"sensor": id, "due": "YYYY-MM-DD"}``). The store adds "format", "run_id",
        "started_at", "status", "software_version" and "campaign_id"; a caller may not set
        those (ValueError). ``columns``: the samples.csv header (t_s, torque_Nm,
        output_angle_deg required). Calibrations past due are logged and listed in
        ``RunRecorder.warnings``. The run id is ``<unit serial or 'unit'>-<UTC time>-<n>``.
        """
        fields = _index_fields(meta)
        columns = _check_columns(columns)
        self.check_writable("a run")
        self.index_pending()
        self._keep_disk_reserve()
        try:
            with self._index.retry_window(self.run_retry_s):
                return self._begin_run(meta, fields, columns, campaign_id, flush_interval_s)
        except OSError as e:
            if is_disk_full(e):
                raise StoreDiskFull(f"the store's disk is full ({self.location}): the run "
                                    f"was not begun ({e.strerror or e})") from None
            raise

    def _keep_disk_reserve(self) -> None:
        """Make the disk reserve (:data:`DISK_RESERVE`) if it is absent; best effort (a disk
        too full for it is told when the run's own files are written)."""
        path = self.root / DISK_RESERVE
        try:
            if path.stat().st_size >= DISK_RESERVE_BYTES:
                return
        except FileNotFoundError:
            pass
        except OSError:
            return
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT, 0o644)
        except OSError:
            return
        try:
            os.posix_fallocate(fd, 0, DISK_RESERVE_BYTES)
        except OSError as e:
            log.info("store: no disk reserve at %s (%s)", path, e.strerror or e)
            os.close(fd)
            path.unlink(missing_ok=True)
            return
        os.close(fd)

    def release_disk_reserve(self) -> None:
        """Remove the disk reserve: room for the records of a run stopped by a full disk."""
        (self.root / DISK_RESERVE).unlink(missing_ok=True)

    def _begin_run(self, meta: dict[str, Any], fields: dict[str, Any], columns: list[str],
                   campaign_id: str | None, flush_interval_s: float) -> RunRecorder:
        folder_parent = self.root / "runs"
        if campaign_id is not None:
            camp = self.get_campaign(campaign_id)
            if camp.status != "running":
                raise StoreError(
                    f"campaign {campaign_id} is {camp.status}: runs can only be added to a "
                    "running campaign"
                )
            folder_parent = camp.path
        started_at = utc_now_iso()
        label = safe_label(fields["unit_serial"], "unit")
        folder, run_id = self._claim_folder(folder_parent, label, self._index.run_exists)
        unit = meta.get("unit") or {}
        design = unit.get("design") if unit.get("design") is not None else unit.get("model")
        full_meta: dict[str, Any] = {
            "format": RUN_FORMAT,
            "run_id": run_id,
            "started_at": started_at,
            **meta,
            "status": "running",
            "software_version": __version__,
        }
        if campaign_id is not None:
            full_meta["campaign_id"] = campaign_id
        lock: WriterLock | None = None
        appender: SamplesAppender | None = None
        try:
            lock = WriterLock.acquire(folder, create=True)
            if lock is None:
                raise StoreError(f"{folder}: a new run folder is locked by another process")
            write_json_atomic(folder / RUN_JSON, full_meta)
            appender = SamplesAppender(
                folder / SAMPLES_CSV, columns, flush_interval_s=flush_interval_s
            )
            sync_dir(folder)
            sync_dir(folder.parent)
            self._index.insert_run({
                "run_id": run_id, "campaign_id": campaign_id,
                "unit_serial": fields["unit_serial"], "operator": fields["operator"],
                "rig_id": fields["rig_id"], "calibration": fields["calibration"],
                "software_version": __version__, "plan_name": fields["plan_name"],
                "plan_version": fields["plan_version"], "status": "running",
                "started_at": started_at, "path": folder.relative_to(self.root).as_posix(),
                "writer_pid": os.getpid(), "writer_host": socket.gethostname(),
                "meta": full_meta, "design": None if design is None else str(design),
            })
        except BaseException:
            if appender is not None:
                appender.close()
            if lock is not None:
                lock.release(remove=True)
            shutil.rmtree(folder, ignore_errors=True)
            raise
        warnings = past_due(fields["calibration"], started_at)
        for message in warnings:
            log.warning("run %s: %s", run_id, message)
        return RunRecorder(self, run_id, folder, full_meta, appender, lock, warnings)

    @staticmethod
    def _claim_folder(parent: Path, label: str,
                      indexed: Callable[[str], bool] = lambda _id: False) -> tuple[Path, str]:
        """Create ``parent/<new id>`` atomically (mkdir is the claim), skipping the ids
        ``indexed`` says are taken; return it and the id."""
        for new_id in id_candidates(label):
            if indexed(new_id):
                continue
            folder = parent / new_id
            try:
                folder.mkdir()
            except FileExistsError:
                continue
            return folder, new_id
        raise AssertionError("unreachable: id_candidates is endless")

    def _finalize_run(
        self,
        run_id: str,
        folder: Path,
        status: str,
        reason: str | None,
        result: dict[str, Any] | None,
        n_samples: int | None,
        extra_meta: dict[str, Any],
    ) -> bool:
        """Move a run from "running" to ``status``: rewrite run.json, update the index and,
        for a completed campaign run, list it in campaign.json; all inside one write
        transaction, so two processes can never both close the same run. False if the run
        was not "running".
        """
        finished_at = utc_now_iso()

        def update(campaign_id: str | None) -> dict[str, Any]:
            meta = _read_json_or(folder / RUN_JSON, {"format": RUN_FORMAT, "run_id": run_id})
            meta.update(
                status=status, reason=reason, result=result, finished_at=finished_at,
                n_samples=n_samples, **extra_meta,
            )
            if folder.is_dir():
                write_json_atomic(folder / RUN_JSON, meta)
            if status == "completed" and campaign_id is not None:
                campaign_json = folder.parent / CAMPAIGN_JSON
                cmeta = _read_json_or(campaign_json, None)
                if cmeta is not None and folder.name not in cmeta.get("runs", []):
                    cmeta["runs"] = [*cmeta.get("runs", []), folder.name]
                    write_json_atomic(campaign_json, cmeta)
            return {"status": status, "reason": reason, "finished_at": finished_at,
                    "n_samples": n_samples, "metrics": result, "meta": meta,
                    "outcome": outcome_word(meta.get("outcome"))}

        audit = {"at": finished_at, "action": f"run {status}", "target": run_id,
                 "pid": os.getpid(), "host": socket.gethostname(),
                 "detail": {"reason": reason} if reason else None}
        try:
            with self._index.retry_window(self.run_retry_s):
                return self._index.finalize_run(run_id, update, audit)
        except StoreUnavailable as e:
            self._keep_locally(run_id, folder, update, audit, e)
            return True

    # ----------------------------------------------------------------------- outages

    def _pending_path(self, run_id: str) -> Path:
        return self.root / PENDING_DIR / f"{run_id}.json"

    def _keep_locally(self, run_id: str, folder: Path,
                      update: Any, audit: dict[str, Any], error: StoreUnavailable) -> None:
        """The database is gone while a run ends: finalise the run in its files (run.json
        with status, result and outcome; campaign.json lists a completed campaign run) and
        queue its index row in ``pending-index/<run_id>.json`` for :meth:`index_pending`."""
        meta = _read_json_or(folder / RUN_JSON, {})
        values = update(meta.get("campaign_id"))
        record = {"run_id": run_id, "path": folder.relative_to(self.root).as_posix(),
                  "values": values, "audit": audit, "kept_at": utc_now_iso(),
                  "error": str(error)}
        (self.root / PENDING_DIR).mkdir(exist_ok=True)
        write_json_atomic(self._pending_path(run_id), record)
        cause = str(error).split(": ", 1)[-1]
        log.warning("store: PostgreSQL unreachable (%s); run %s kept locally, will be indexed "
                    "when it returns", cause, run_id)

    def reachable(self) -> bool:
        """Does the index answer now (one attempt; always True for the embedded index)?"""
        try:
            with self._index.retry_window(0.0):
                self._index.schema_version()
        except StoreUnavailable:
            return False
        return True

    def pending_runs(self) -> list[str]:
        """Ids of the runs finalised locally and not yet indexed (a database outage)."""
        folder = self.root / PENDING_DIR
        if not folder.is_dir():
            return []
        return sorted(p.stem for p in folder.glob("*.json") if ID_PATTERN.fullmatch(p.stem))

    def index_pending(self) -> list[str]:
        """Index the runs finalised locally during a database outage (one attempt each, no
        waiting); returns the ids indexed now. Their audit records keep the time the run
        ended. A database still unreachable leaves them queued (no error)."""
        done: list[str] = []
        if self.read_only is not None:  # queued runs wait for a process that may write
            return done
        for run_id in self.pending_runs():
            path = self._pending_path(run_id)
            record = _read_json_or(path, None)
            if record is None or not isinstance(record.get("values"), dict):
                continue
            values = record["values"]
            try:
                with self._index.retry_window(0.0):
                    changed = self._index.finalize_run(run_id, lambda _cid, v=values: v,
                                                       record["audit"])
            except StoreUnavailable:
                break
            path.unlink(missing_ok=True)
            if changed:
                done.append(run_id)
                log.warning("store: run %s indexed (kept locally during a database outage)",
                            run_id)
            elif (row := self._index.get_run(run_id)) is None or \
                    row["finished_at"] != values["finished_at"]:  # not another indexer's
                log.warning("run %s: kept locally, but the index no longer holds it as "
                            "running; its files are kept as they are", run_id)
        return done

    def local_run_info(self, run_id: str) -> RunInfo:
        """A run's row as its files say (the run was kept locally: the index is behind)."""
        record = _read_json_or(self._pending_path(run_id), None)
        if record is None:
            return self.get_run(run_id)
        values, meta = record["values"], record["values"].get("meta") or {}
        fields = _index_fields({k: v for k, v in meta.items() if k not in RUN_RESERVED_KEYS})
        unit = meta.get("unit") or {}
        return RunInfo(
            run_id=run_id, campaign_id=meta.get("campaign_id"),
            unit_serial=fields["unit_serial"], operator=fields["operator"],
            rig_id=fields["rig_id"], calibration=fields["calibration"],
            software_version=str(meta.get("software_version", __version__)),
            plan_name=fields["plan_name"], plan_version=fields["plan_version"],
            status=values["status"], reason=values["reason"],
            started_at=str(meta.get("started_at", "")), finished_at=values["finished_at"],
            n_samples=values["n_samples"], path=self.root / record["path"],
            metrics=values["metrics"], outcome=values.get("outcome"),
            design=unit.get("design") if unit.get("design") is not None else unit.get("model"),
            label=meta.get("label") if isinstance(meta.get("label"), str) else None,
        )

    def recover(self) -> list[str]:
        """Mark runs left "running" by a process that has ended as "aborted".

        The reason is :data:`RECOVERED_REASON`. A run whose writer still holds its lock
        (a live process, this one included) is left alone. Samples are kept; an unfinished
        last CSV line (cut by the kill) is cut off and recorded in run.json under
        ``"recovery"``, and the CSV stream is finalised to ``samples.parquet`` (a run killed
        after its Parquet file was in place keeps that). Returns the ids of the runs marked
        aborted.
        """
        recovered = []
        pending = set(self.pending_runs())
        for run_id, path in self._index.running_runs():
            if run_id in pending:  # finalised locally; the database was away at its end
                continue
            folder = self.root / path
            lock = WriterLock.acquire(folder, create=False)
            if lock is None:
                continue
            try:
                record: dict[str, Any] = {"found_at": utc_now_iso(), "by_pid": os.getpid()}
                if not (folder / SAMPLES_PARQUET).is_file():
                    dropped = cut_incomplete_tail(folder / SAMPLES_CSV)
                    if dropped is not None:
                        record["dropped_incomplete_line"] = dropped
                try:
                    n_samples: int | None = finalise_samples(folder)
                except (RigError, OSError, ValueError) as e:
                    n_samples = None
                    record["read_error"] = str(e)
                if self._finalize_run(
                    run_id, folder, "aborted", RECOVERED_REASON, None, n_samples,
                    {"recovery": record, "outcome": "incomplete"},
                ):
                    recovered.append(run_id)
                    log.warning("run %s: marked aborted: %s", run_id, RECOVERED_REASON)
            finally:
                lock.release(remove=True)
        return recovered

    def list_runs(
        self,
        *,
        campaign_id: str | None = None,
        status: str | None = None,
        limit: int | None = None,
        serial: str | None = None,
        outcome: str | None = None,
        design: str | None = None,
        since: str | None = None,
        until: str | None = None,
    ) -> list[RunInfo]:
        """Runs in the index, newest first (by start time), at most ``limit``, optionally
        of one campaign / status / unit serial / outcome / design, started at or after
        ``since`` and before ``until`` (ISO 8601 UTC dates or times, e.g. "2026-11-01")."""
        if campaign_id is not None:
            validate_id(campaign_id, "campaign")
        if status is not None and status not in RUN_STATUSES:
            raise ValueError(f"status must be one of {RUN_STATUSES}, got {status!r}")
        if limit is not None and (isinstance(limit, bool) or not isinstance(limit, int)
                                  or limit < 1):
            raise ValueError(f"limit must be a positive int, got {limit!r}")
        self.index_pending()
        rows = self._index.query_runs(RunFilter(
            campaign_id=campaign_id, status=status, serial=serial, outcome=outcome,
            design=design, since=_iso_bound(since, "since"), until=_iso_bound(until, "until"),
            limit=limit))
        infos = [run_info(self._as_recorded(r), self.root) for r in rows]
        return [i for i in infos if status is None or i.status == status]

    def _as_recorded(self, row: Mapping[str, Any]) -> Mapping[str, Any]:
        """A finished run's index row as its run.json says it: run.json is the record, the
        index a copy made when the run ended. A run.json changed after that (modified more
        than :data:`RECORD_SLACK_S` after the run's end, e.g. by hand) is read again; its
        status, reason, result, outcome and sample count replace the copy's (NaN and inf as
        missing values), in the index too when the store may be written."""
        if row.get("status") == "running" or not row.get("finished_at"):
            return row
        path = self.root / row["path"] / RUN_JSON
        try:
            changed_at = path.stat().st_mtime
            ended_at = datetime.fromisoformat(str(row["finished_at"]).replace("Z", "+00:00"))
        except (OSError, ValueError):
            return row
        if changed_at <= ended_at.timestamp() + RECORD_SLACK_S:
            return row
        meta = _read_json_or(path, None)  # Python's reader takes a NaN typed by hand
        if meta is None:
            return row
        from rig.core.json_files import json_safe

        meta = json_safe(meta)
        values: dict[str, Any] = {
            "reason": meta.get("reason") if isinstance(meta.get("reason"), str) else None,
            "metrics": meta.get("result") if isinstance(meta.get("result"), dict) else None,
            "outcome": outcome_word(meta.get("outcome")),
            "n_samples": meta.get("n_samples") if isinstance(meta.get("n_samples"), int)
            else row.get("n_samples")}
        if meta.get("status") in FINAL_STATUSES:
            values["status"] = meta["status"]
        if all(row.get(k) == v for k, v in values.items()):  # the copy holds: as it is
            return row
        values["meta"] = meta
        if self.read_only is None:
            try:
                self._index.refresh_run(str(row["run_id"]), values)
            except StoreError as e:
                log.warning("run %s: the index keeps its old copy of run.json: %s",
                            row["run_id"], e)
        return {**row, **values}

    def runs(self, *, serial: str | None = None, since: str | None = None,
             outcome: str | None = None, **filters: Any) -> Any:
        """:meth:`list_runs` as a pandas DataFrame, one row per run (rig/store/frame.py)."""
        from rig.store.frame import runs_frame
        return runs_frame(self, serial=serial, since=since, outcome=outcome, **filters)

    def get_run(self, run_id: str) -> RunInfo:
        """The index row of one run, as its run.json says it (:meth:`_as_recorded`)
        (InvalidIdError / UnknownIdError)."""
        return run_info(self._as_recorded(self._indexed("run", run_id, self._index.get_run)),
                        self.root)

    def run_path(self, run_id: str) -> Path:
        """The folder of a run (validated id, known to the index)."""
        return self.get_run(run_id).path

    def load_run(self, run_id: str) -> Run:
        """Read a run (a running one too: a row cut off mid-write at the end is dropped).

        A run folder or samples file that is missing or unreadable raises
        :class:`StoreError` naming the run id (never an empty run)."""
        path = self.run_path(run_id)
        try:
            return read_run(path, allow_truncated_tail=True)
        except (RigError, OSError, ValueError) as e:  # ValueError: a corrupt Parquet file
            raise StoreError(f"run {run_id}: its files cannot be read: {e}") from e

    # ----------------------------------------------------------------------- campaigns

    def create_campaign(self, name: str, meta: dict[str, Any] | None = None) -> str:
        """Create a running campaign: its folder and campaign.json (rig-campaign/1).

        ``meta`` keys are kept in campaign.json (not the reserved ones, ValueError).
        campaign.json "runs" lists the campaign's *completed* runs, so that a diagnosis
        reading the folder sees those only. Returns the campaign id
        ``<name>-<UTC time>-<n>``.
        """
        if not isinstance(name, str) or not name.strip():
            raise ValueError(f"campaign name must be a non-empty string, got {name!r}")
        meta = dict(meta or {})
        self.check_writable("a campaign")
        _reject_reserved(meta, CAMPAIGN_RESERVED_KEYS, "campaign meta")
        to_json(meta)
        started_at = utc_now_iso()
        folder, campaign_id = self._claim_folder(self.root / "campaigns",
                                                 safe_label(name, "campaign"))
        cmeta = {
            "format": CAMPAIGN_FORMAT, "name": name, "campaign_id": campaign_id,
            "status": "running", "started_at": started_at, **meta, "runs": [],
        }
        try:
            write_json_atomic(folder / CAMPAIGN_JSON, cmeta)
            self._index.insert_campaign({
                "campaign_id": campaign_id, "name": name, "started_at": started_at,
                "path": folder.relative_to(self.root).as_posix(), "meta": meta,
                "pid": os.getpid(), "host": socket.gethostname()})
        except BaseException:
            shutil.rmtree(folder, ignore_errors=True)
            raise
        return campaign_id

    def finish_campaign(
        self, campaign_id: str, status: str, summary: dict[str, Any] | None = None,
        extra: dict[str, Any] | None = None,
    ) -> None:
        """Close a running campaign as "completed" or "aborted" with a JSON-able summary;
        ``extra``: more top-level keys of campaign.json (``outcome``)."""
        if status not in FINAL_STATUSES:
            raise ValueError(f"status must be one of {FINAL_STATUSES}, got {status!r}")
        to_json(summary)
        camp = self.get_campaign(campaign_id)
        finished_at = utc_now_iso()

        def update(_row: Any) -> dict[str, Any]:
            cjson = camp.path / CAMPAIGN_JSON
            cmeta = _read_json_or(cjson, {"format": CAMPAIGN_FORMAT, "name": camp.name})
            cmeta.update(status=status, finished_at=finished_at, summary=summary,
                         **(extra or {}))
            write_json_atomic(cjson, cmeta)
            return {"status": status, "finished_at": finished_at, "summary": summary,
                    "audit": {"at": finished_at, "action": f"campaign {status}",
                              "target": campaign_id, "pid": os.getpid(),
                              "host": socket.gethostname()}}

        self._index.finish_campaign(campaign_id, update)

    def get_campaign(self, campaign_id: str) -> CampaignInfo:
        """The index row of one campaign (InvalidIdError / UnknownIdError)."""
        return campaign_info(
            self._indexed("campaign", campaign_id, self._index.get_campaign), self.root)

    def _indexed(self, kind: str, id_: str,
                 get: Callable[[str], Mapping[str, Any] | None]) -> Mapping[str, Any]:
        """The index row of a run or campaign (``kind``) by ``get`` (InvalidIdError /
        UnknownIdError)."""
        validate_id(id_, kind)
        row = get(id_)
        if row is None:
            raise UnknownIdError(f"no {kind} {id_!r} in the store {self.location}")
        return row

    def list_campaigns(self) -> list[CampaignInfo]:
        """All campaigns, newest first."""
        return [campaign_info(r, self.root) for r in self._index.list_campaigns()]

    # ----------------------------------------------------------------------- results, audit

    def add_result(
        self,
        *,
        software_version: str,
        run_id: str | None = None,
        campaign_id: str | None = None,
        metrics: dict[str, Any] | None = None,
        diagnosis: dict[str, Any] | None = None,
        error: str | None = None,
    ) -> bool:
        """Keep a re-computed result of one run or one campaign (``rig reanalyse``), made by
        ``software_version``; earlier results stay. False if that version's result of that
        run/campaign is stored already (nothing changed)."""
        if (run_id is None) == (campaign_id is None):
            raise ValueError("give exactly one of run_id and campaign_id")
        self.check_writable("a re-computed result")
        if run_id is not None:
            validate_id(run_id, "run")
        if campaign_id is not None:
            validate_id(campaign_id, "campaign")
        to_json(metrics)
        to_json(diagnosis)
        return self._index.add_result({
            "run_id": run_id, "campaign_id": campaign_id,
            "software_version": software_version, "computed_at": utc_now_iso(),
            "metrics": metrics, "diagnosis": diagnosis, "error": error})

    def results(self, *, run_id: str | None = None, campaign_id: str | None = None,
                software_version: str | None = None) -> list[dict[str, Any]]:
        """Stored re-computed results (oldest first): dicts with result_id, run_id,
        campaign_id, software_version, computed_at, metrics, diagnosis, error."""
        return [dict(r) for r in self._index.results(
            run_id=run_id, campaign_id=campaign_id, software_version=software_version)]

    def record_action(self, action: str, target: str | None = None,
                      detail: dict[str, Any] | None = None) -> None:
        """Add an operator's action to the audit trail (who is in ``detail``: operator), with
        the time, this process and host."""
        to_json(detail)
        self.check_writable("an audit record")
        self._index.add_audit({"at": utc_now_iso(), "action": action, "target": target or "",
                               "pid": os.getpid(), "host": socket.gethostname(),
                               "detail": detail})

    def audit(self, target: str | None = None) -> list[dict[str, Any]]:
        """The audit trail (oldest first): run/campaign started, completed, aborted, with
        time, process id and host; optionally of one run or campaign id."""
        return [dict(r) for r in self._index.audit_records(target)]


# --------------------------------------------------------------------------- helpers


def _env_seconds(name: str, default: float) -> float:
    """A non-negative number of seconds from the environment variable ``name``."""
    text = os.environ.get(name, "").strip()
    if not text:
        return default
    try:
        value = float(text)
    except ValueError:
        raise StoreError(f"{name}={text!r}: expected a number of seconds") from None
    if not value >= 0 or value == float("inf"):
        raise StoreError(f"{name}={text!r}: expected a number of seconds >= 0")
    return value


def _iso_bound(value: Any, name: str) -> str | None:
    """A ``since``/``until`` bound as the index's ISO text ("2026-11-01" or a full time)."""
    if value is None:
        return None
    text = value.isoformat() if hasattr(value, "isoformat") else value
    if not isinstance(text, str):
        raise ValueError(f"{name} must be an ISO 8601 date or time, got {value!r}")
    try:
        parsed = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise ValueError(f"{name}: {text!r} is not an ISO 8601 date or time") from None
    if parsed.tzinfo is not None:
        parsed = parsed.astimezone(UTC).replace(tzinfo=None)
    return parsed.strftime("%Y-%m-%dT%H:%M:%SZ")


def _reject_reserved(meta: dict[str, Any], reserved: tuple[str, ...], what: str) -> None:
    taken = [k for k in meta if k in reserved]
    if taken:
        raise ValueError(f"{what} may not set {taken}: the store writes those keys")


def _optional_str(value: Any, where: str) -> str | None:
    if value is None or isinstance(value, str):
        return value
    if isinstance(value, int | float) and not isinstance(value, bool):
        return str(value)
    raise ValueError(f"{where} must be a string, got {value!r}")


def _index_fields(meta: Any) -> dict[str, Any]:
    """Check a run's start meta and pick the indexed fields out of it (ValueError)."""
    if not isinstance(meta, dict):
        raise ValueError(f"run meta must be a dict, got {type(meta).__name__}")
    _reject_reserved(meta, RUN_RESERVED_KEYS, "run meta")
    to_json(meta)
    for key in ("unit", "test", "sensors", "plan"):
        if key in meta and not isinstance(meta[key], dict):
            raise ValueError(f"meta[{key!r}] must be a dict, got {type(meta[key]).__name__}")
    unit = meta.get("unit") or {}
    plan = meta.get("plan") or {}
    return {
        "unit_serial": _optional_str(unit.get("serial"), "meta['unit']['serial']"),
        "operator": _optional_str(meta.get("operator"), "meta['operator']"),
        "rig_id": _optional_str(meta.get("rig_id"), "meta['rig_id']"),
        "plan_name": _optional_str(plan.get("name"), "meta['plan']['name']"),
        "plan_version": _optional_str(plan.get("version"), "meta['plan']['version']"),
        "calibration": check_calibration(meta.get("calibration", [])),
    }


def _check_columns(columns: Any) -> list[str]:
    if not isinstance(columns, list | tuple) or not all(isinstance(c, str) for c in columns):
        raise ValueError(f"columns must be a list of column names, got {columns!r}")
    missing = [c for c in REQUIRED_COLUMNS if c not in columns]
    if missing:
        raise ValueError(f"columns {list(columns)} lack the required {missing}")
    return list(columns)


def _read_json_or(path: Path, default: Any) -> Any:
    """A JSON object from one of the store's own files, or ``default`` if absent/unreadable."""
    try:
        value = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return default
    return value if isinstance(value, dict) else default
