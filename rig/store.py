"""The measurement store: run folders in rig-run/1 plus an SQLite index (docs/store.md).

Layout of a store root::

    index.sqlite              runs and campaigns: metadata and status (WAL mode)
    runs/<run_id>/            a run outside any campaign: run.json + samples.csv
    campaigns/<campaign_id>/  a rig-campaign/1 folder: campaign.json + one folder per run

Samples go to ``samples.csv`` as they are measured (flushed at least every 0.5 s), never
into SQLite. A process killed during a run keeps its samples; the next :class:`Store` opened
on the root marks the run "aborted" (:meth:`Store.recover`). Live writers hold a ``flock``
on their run folder, so a reader opening the store never aborts a run still being measured.

The default root is ``$RIG_STORE`` if set, else ``./rig-store`` (:func:`default_store_root`).
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import shutil
import socket
import sqlite3
from pathlib import Path
from typing import Any

from rig import __version__
from rig.errors import RigError
from rig.runformat import (
    CAMPAIGN_FORMAT,
    CAMPAIGN_JSON,
    REQUIRED_COLUMNS,
    RUN_FORMAT,
    RUN_JSON,
    SAMPLES_CSV,
    Run,
    SamplesAppender,
    read_run,
)
from rig.store_files import WriterLock, cut_incomplete_tail, sync_dir, write_json_atomic
from rig.store_ids import (
    InvalidIdError,
    StoreError,
    UnknownIdError,
    id_candidates,
    safe_label,
    utc_now_iso,
    validate_id,
)
from rig.store_index import (
    INDEX_NAME,
    campaign_info,
    connect,
    create_index,
    index_exists,
    run_info,
    to_json,
    write_transaction,
)
from rig.store_recorder import RunRecorder
from rig.store_records import (
    FINAL_STATUSES,
    RUN_STATUSES,
    CampaignInfo,
    RunInfo,
    check_calibration,
    past_due,
)

__all__ = [
    "RECOVERED_REASON",
    "CampaignInfo",
    "InvalidIdError",
    "RunInfo",
    "RunRecorder",
    "Store",
    "StoreError",
    "UnknownIdError",
    "default_store_root",
]

log = logging.getLogger(__name__)

STORE_ENV = "RIG_STORE"
DEFAULT_STORE_DIR = "rig-store"
RECOVERED_REASON = "process ended during the run (found at next start)"
RUN_RESERVED_KEYS = (
    "format", "run_id", "started_at", "finished_at", "status", "reason", "result",
    "n_samples", "software_version", "campaign_id", "recovery",
)
CAMPAIGN_RESERVED_KEYS = (
    "format", "name", "campaign_id", "status", "started_at", "finished_at", "summary", "runs",
)


def default_store_root() -> Path:
    """``$RIG_STORE`` if set and not empty, else ``./rig-store`` (relative to the cwd)."""
    return Path(os.environ.get(STORE_ENV) or DEFAULT_STORE_DIR)


class Store:
    """A store root: run folders plus ``index.sqlite``. Safe to open from many processes.

    ``create``: make the root and the index if absent (else a missing index raises
    :class:`StoreError`). ``recover``: run :meth:`recover` now (its result is kept in
    ``recovered``). ``busy_timeout_s``: how long a call waits for another process's write
    transaction before failing (writes last milliseconds; the default is generous).
    """

    def __init__(
        self,
        root: str | Path,
        *,
        create: bool = True,
        recover: bool = True,
        busy_timeout_s: float = 30.0,
    ) -> None:
        self.root = Path(root).absolute()
        self.busy_timeout_s = float(busy_timeout_s)
        if not create and not index_exists(self.root):
            raise StoreError(
                f"no store at {self.root} (no {INDEX_NAME}); a store is created by the first "
                "measurement run into it"
            )
        try:
            (self.root / "runs").mkdir(parents=True, exist_ok=True)
            (self.root / "campaigns").mkdir(exist_ok=True)
        except OSError as e:
            raise StoreError(f"cannot create the store at {self.root}: {e.strerror or e}") from e
        create_index(self.root / INDEX_NAME, self.busy_timeout_s)
        self.recovered: list[str] = self.recover() if recover else []

    def __repr__(self) -> str:
        return f"Store({str(self.root)!r})"

    # ----------------------------------------------------------------------- connections

    def _connect(self) -> contextlib.closing[sqlite3.Connection]:
        return contextlib.closing(connect(self.root / INDEX_NAME, self.busy_timeout_s))

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
        folder, run_id = self._claim_folder(folder_parent, label)
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
            with self._connect() as conn, write_transaction(conn):
                conn.execute(
                    """INSERT INTO runs (run_id, campaign_id, unit_serial, operator, rig_id,
                    calibration, software_version, plan_name, plan_version, status,
                    started_at, path, writer_pid, writer_host)
                    VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, 'running', ?, ?, ?, ?)""",
                    (
                        run_id, campaign_id, fields["unit_serial"], fields["operator"],
                        fields["rig_id"], to_json(fields["calibration"]), __version__,
                        fields["plan_name"], fields["plan_version"], started_at,
                        folder.relative_to(self.root).as_posix(), os.getpid(),
                        socket.gethostname(),
                    ),
                )
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

    def _claim_folder(self, parent: Path, label: str) -> tuple[Path, str]:
        """Create ``parent/<new id>`` atomically (mkdir is the claim); return it and the id."""
        with self._connect() as conn:
            for run_id in id_candidates(label):
                if conn.execute("SELECT 1 FROM runs WHERE run_id = ?", (run_id,)).fetchone():
                    continue
                folder = parent / run_id
                try:
                    folder.mkdir()
                except FileExistsError:
                    continue
                return folder, run_id
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
        with self._connect() as conn, write_transaction(conn):
            row = conn.execute(
                "SELECT status, campaign_id FROM runs WHERE run_id = ?", (run_id,)
            ).fetchone()
            if row is None or row["status"] != "running":
                return False
            meta = _read_json_or(folder / RUN_JSON, {"format": RUN_FORMAT, "run_id": run_id})
            meta.update(
                status=status, reason=reason, result=result, finished_at=finished_at,
                n_samples=n_samples, **extra_meta,
            )
            if folder.is_dir():
                write_json_atomic(folder / RUN_JSON, meta)
            conn.execute(
                """UPDATE runs SET status = ?, reason = ?, finished_at = ?, n_samples = ?,
                metrics = ? WHERE run_id = ? AND status = 'running'""",
                (status, reason, finished_at, n_samples, to_json(result), run_id),
            )
            if status == "completed" and row["campaign_id"] is not None:
                campaign_json = folder.parent / CAMPAIGN_JSON
                cmeta = _read_json_or(campaign_json, None)
                if cmeta is not None:
                    cmeta["runs"] = [*cmeta.get("runs", []), folder.name]
                    write_json_atomic(campaign_json, cmeta)
        return True

    def recover(self) -> list[str]:
        """Mark runs left "running" by a process that has ended as "aborted".

        The reason is :data:`RECOVERED_REASON`. A run whose writer still holds its lock
        (a live process, this one included) is left alone. Samples are kept; an unfinished
        last CSV line (cut by the kill) is cut off and recorded in run.json under
        ``"recovery"``. Returns the ids of the runs marked aborted.
        """
        with self._connect() as conn:
            rows = conn.execute(
                "SELECT run_id, path FROM runs WHERE status = 'running' ORDER BY rowid"
            ).fetchall()
        recovered = []
        for row in rows:
            folder = self.root / row["path"]
            lock = WriterLock.acquire(folder, create=False)
            if lock is None:
                continue
            try:
                record: dict[str, Any] = {"found_at": utc_now_iso(), "by_pid": os.getpid()}
                dropped = cut_incomplete_tail(folder / SAMPLES_CSV)
                if dropped is not None:
                    record["dropped_incomplete_line"] = dropped
                try:
                    n_samples: int | None = read_run(folder, allow_truncated_tail=True).n_samples
                except RigError as e:
                    n_samples = None
                    record["read_error"] = str(e)
                if self._finalize_run(
                    row["run_id"], folder, "aborted", RECOVERED_REASON, None, n_samples,
                    {"recovery": record},
                ):
                    recovered.append(row["run_id"])
                    log.warning("run %s: marked aborted: %s", row["run_id"], RECOVERED_REASON)
            finally:
                lock.release(remove=True)
        return recovered

    def list_runs(
        self,
        *,
        campaign_id: str | None = None,
        status: str | None = None,
        limit: int | None = None,
    ) -> list[RunInfo]:
        """Runs in the index, newest first, optionally of one campaign / status, at most
        ``limit``."""
        where, args = [], []
        if campaign_id is not None:
            where.append("campaign_id = ?")
            args.append(validate_id(campaign_id, "campaign"))
        if status is not None:
            if status not in RUN_STATUSES:
                raise ValueError(f"status must be one of {RUN_STATUSES}, got {status!r}")
            where.append("status = ?")
            args.append(status)
        sql = "SELECT * FROM runs"
        if where:
            sql += " WHERE " + " AND ".join(where)
        sql += " ORDER BY rowid DESC"
        if limit is not None:
            if isinstance(limit, bool) or not isinstance(limit, int) or limit < 1:
                raise ValueError(f"limit must be a positive int, got {limit!r}")
            sql += f" LIMIT {limit}"
        with self._connect() as conn:
            rows = conn.execute(sql, args).fetchall()
        return [run_info(r, self.root) for r in rows]

    def get_run(self, run_id: str) -> RunInfo:
        """The index row of one run (InvalidIdError / UnknownIdError)."""
        validate_id(run_id, "run")
        with self._connect() as conn:
            row = conn.execute("SELECT * FROM runs WHERE run_id = ?", (run_id,)).fetchone()
        if row is None:
            raise UnknownIdError(f"no run {run_id!r} in the store {self.root}")
        return run_info(row, self.root)

    def run_path(self, run_id: str) -> Path:
        """The folder of a run (validated id, known to the index)."""
        return self.get_run(run_id).path

    def load_run(self, run_id: str) -> Run:
        """Read a run (a running one too: a row cut off mid-write at the end is dropped)."""
        return read_run(self.run_path(run_id), allow_truncated_tail=True)

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
        _reject_reserved(meta, CAMPAIGN_RESERVED_KEYS, "campaign meta")
        to_json(meta)
        started_at = utc_now_iso()
        for campaign_id in id_candidates(safe_label(name, "campaign")):
            folder = self.root / "campaigns" / campaign_id
            try:
                folder.mkdir()
            except FileExistsError:
                continue
            break
        cmeta = {
            "format": CAMPAIGN_FORMAT, "name": name, "campaign_id": campaign_id,
            "status": "running", "started_at": started_at, **meta, "runs": [],
        }
        try:
            write_json_atomic(folder / CAMPAIGN_JSON, cmeta)
            with self._connect() as conn, write_transaction(conn):
                conn.execute(
                    """INSERT INTO campaigns (campaign_id, name, status, started_at, path, meta)
                    VALUES (?, ?, 'running', ?, ?, ?)""",
                    (campaign_id, name, started_at,
                     folder.relative_to(self.root).as_posix(), to_json(meta)),
                )
        except BaseException:
            shutil.rmtree(folder, ignore_errors=True)
            raise
        return campaign_id

    def finish_campaign(
        self, campaign_id: str, status: str, summary: dict[str, Any] | None = None
    ) -> None:
        """Close a running campaign as "completed" or "aborted" with a JSON-able summary."""
        if status not in FINAL_STATUSES:
            raise ValueError(f"status must be one of {FINAL_STATUSES}, got {status!r}")
        summary_json = to_json(summary)
        camp = self.get_campaign(campaign_id)
        finished_at = utc_now_iso()
        with self._connect() as conn, write_transaction(conn):
            row = conn.execute(
                "SELECT status FROM campaigns WHERE campaign_id = ?", (campaign_id,)
            ).fetchone()
            if row["status"] != "running":
                raise StoreError(f"campaign {campaign_id} is already {row['status']}")
            cjson = camp.path / CAMPAIGN_JSON
            cmeta = _read_json_or(cjson, {"format": CAMPAIGN_FORMAT, "name": camp.name})
            cmeta.update(status=status, finished_at=finished_at, summary=summary)
            write_json_atomic(cjson, cmeta)
            conn.execute(
                """UPDATE campaigns SET status = ?, finished_at = ?, summary = ?
                WHERE campaign_id = ?""",
                (status, finished_at, summary_json, campaign_id),
            )

    def get_campaign(self, campaign_id: str) -> CampaignInfo:
        """The index row of one campaign (InvalidIdError / UnknownIdError)."""
        validate_id(campaign_id, "campaign")
        with self._connect() as conn:
            row = conn.execute(
                "SELECT * FROM campaigns WHERE campaign_id = ?", (campaign_id,)
            ).fetchone()
        if row is None:
            raise UnknownIdError(f"no campaign {campaign_id!r} in the store {self.root}")
        return campaign_info(row, self.root)

    def list_campaigns(self) -> list[CampaignInfo]:
        """All campaigns, newest first."""
        with self._connect() as conn:
            rows = conn.execute("SELECT * FROM campaigns ORDER BY rowid DESC").fetchall()
        return [campaign_info(r, self.root) for r in rows]


# --------------------------------------------------------------------------- helpers


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
