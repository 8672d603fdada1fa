"""The SQLite index of the store (``<root>/index.sqlite``): schema, connections, rows.

The index holds metadata and status only; the samples go to each run's ``samples.csv``.
The database runs in WAL mode so that readers (the web page, ``rig runs``) never block the
writer and the writer never blocks them. Every connection is short-lived and private to one
call, waits up to a busy timeout for a lock instead of failing with "database is locked",
and writes in short ``BEGIN IMMEDIATE`` transactions (taking the write lock up front, so a
transaction never has to upgrade a read lock, the case SQLite cannot wait for).
"""

from __future__ import annotations

import contextlib
import json
import sqlite3
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from rig.store_ids import StoreError
from rig.store_records import CampaignInfo, RunInfo

INDEX_NAME = "index.sqlite"
SCHEMA_VERSION = 1

_SCHEMA = (
    """CREATE TABLE IF NOT EXISTS campaigns (
        campaign_id TEXT PRIMARY KEY,
        name TEXT NOT NULL,
        status TEXT NOT NULL CHECK (status IN ('running', 'completed', 'aborted')),
        started_at TEXT NOT NULL,
        finished_at TEXT,
        path TEXT NOT NULL,
        meta TEXT NOT NULL,
        summary TEXT
    )""",
    """CREATE TABLE IF NOT EXISTS runs (
        run_id TEXT PRIMARY KEY,
        campaign_id TEXT REFERENCES campaigns (campaign_id),
        unit_serial TEXT,
        operator TEXT,
        rig_id TEXT,
        calibration TEXT NOT NULL,
        software_version TEXT NOT NULL,
        plan_name TEXT,
        plan_version TEXT,
        status TEXT NOT NULL CHECK (status IN ('running', 'completed', 'aborted')),
        reason TEXT,
        started_at TEXT NOT NULL,
        finished_at TEXT,
        n_samples INTEGER,
        path TEXT NOT NULL,
        metrics TEXT,
        writer_pid INTEGER,
        writer_host TEXT
    )""",
    "CREATE INDEX IF NOT EXISTS runs_by_status ON runs (status)",
    "CREATE INDEX IF NOT EXISTS runs_by_campaign ON runs (campaign_id)",
)


def connect(db_path: Path, busy_timeout_s: float) -> sqlite3.Connection:
    """A new connection in autocommit mode (explicit transactions), rows as sqlite3.Row."""
    conn = sqlite3.connect(db_path, timeout=busy_timeout_s, isolation_level=None)
    conn.row_factory = sqlite3.Row
    conn.execute("PRAGMA synchronous = FULL")
    conn.execute("PRAGMA foreign_keys = ON")
    return conn


@contextlib.contextmanager
def write_transaction(conn: sqlite3.Connection) -> Iterator[sqlite3.Connection]:
    """``BEGIN IMMEDIATE`` ... ``COMMIT`` (``ROLLBACK`` on any exception)."""
    conn.execute("BEGIN IMMEDIATE")
    try:
        yield conn
    except BaseException:
        conn.execute("ROLLBACK")
        raise
    conn.execute("COMMIT")


def create_index(db_path: Path, busy_timeout_s: float) -> None:
    """Create the index if needed, switch it to WAL mode and check its schema version."""
    with contextlib.closing(connect(db_path, busy_timeout_s)) as conn:
        _set_wal(conn, db_path, busy_timeout_s)
        with write_transaction(conn):
            version = conn.execute("PRAGMA user_version").fetchone()[0]
            if version > SCHEMA_VERSION:
                raise StoreError(
                    f"{db_path}: index schema version {version} is newer than this software "
                    f"reads ({SCHEMA_VERSION}); update backlash-rig"
                )
            for statement in _SCHEMA:
                conn.execute(statement)
            conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")


def _set_wal(conn: sqlite3.Connection, db_path: Path, busy_timeout_s: float) -> None:
    """Switch to WAL (persistent in the file). The switch needs a moment with no other
    connection inside a transaction and does not always wait on the busy handler: retry.
    """
    deadline = time.monotonic() + busy_timeout_s
    while True:
        try:
            mode = conn.execute("PRAGMA journal_mode = WAL").fetchone()[0]
        except sqlite3.OperationalError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)
            continue
        if str(mode).lower() != "wal":
            raise StoreError(f"{db_path}: SQLite refused WAL mode (journal mode is {mode!r})")
        return


def index_exists(root: Path) -> bool:
    return (root / INDEX_NAME).is_file()


def to_json(value: Any) -> str | None:
    """Strict JSON text of ``value`` (None stays None); ValueError for NaN/inf/non-JSON."""
    if value is None:
        return None
    try:
        return json.dumps(value, ensure_ascii=False, allow_nan=False, sort_keys=False)
    except (TypeError, ValueError) as e:
        raise ValueError(f"not storable as JSON: {e}") from None


def run_info(row: sqlite3.Row, root: Path) -> RunInfo:
    """A :class:`RunInfo` from a ``runs`` row; ``path`` made absolute under ``root``."""
    return RunInfo(
        run_id=row["run_id"],
        campaign_id=row["campaign_id"],
        unit_serial=row["unit_serial"],
        operator=row["operator"],
        rig_id=row["rig_id"],
        calibration=json.loads(row["calibration"]),
        software_version=row["software_version"],
        plan_name=row["plan_name"],
        plan_version=row["plan_version"],
        status=row["status"],
        reason=row["reason"],
        started_at=row["started_at"],
        finished_at=row["finished_at"],
        n_samples=row["n_samples"],
        path=root / row["path"],
        metrics=json.loads(row["metrics"]) if row["metrics"] is not None else None,
        writer_pid=row["writer_pid"],
        writer_host=row["writer_host"],
    )


def campaign_info(row: sqlite3.Row, root: Path) -> CampaignInfo:
    """A :class:`CampaignInfo` from a ``campaigns`` row."""
    return CampaignInfo(
        campaign_id=row["campaign_id"],
        name=row["name"],
        status=row["status"],
        started_at=row["started_at"],
        finished_at=row["finished_at"],
        path=root / row["path"],
        meta=json.loads(row["meta"]),
        summary=json.loads(row["summary"]) if row["summary"] is not None else None,
    )
