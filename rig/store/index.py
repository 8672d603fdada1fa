"""The store's index: the back-end interface and its SQLite implementation (``index.sqlite``).

The index holds metadata, status, results, outcomes, calibration and audit records; the
samples stay in each run's folder. Two back-ends implement :class:`IndexBackend`:

- :class:`SqliteIndex` (this module): ``<root>/index.sqlite``, the embedded default. The
  database runs in WAL mode so that readers (the web page, ``rig runs``) never block the
  writer and the writer never blocks them. Every connection is short-lived and private to
  one call, waits up to a busy timeout for a lock instead of failing with "database is
  locked", and writes in short ``BEGIN IMMEDIATE`` transactions (taking the write lock up
  front, so a transaction never has to upgrade a read lock, the case SQLite cannot wait for).
- :class:`rig.store.index_pg.PostgresIndex`: a PostgreSQL database (``postgresql://...``).

Both keep the same tables and columns and the same versioned migrations
(:data:`SCHEMA_VERSION`); a store made by an older version is migrated when it is opened.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import sqlite3
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rig.store.ids import StoreError
from rig.store.records import CampaignInfo, RunInfo

INDEX_NAME = "index.sqlite"
SCHEMA_VERSION = 2

# Columns of a new ``runs`` row (:meth:`IndexBackend.insert_run`); JSON ones as Python objects.
RUN_INSERT_COLUMNS = (
    "run_id", "campaign_id", "unit_serial", "operator", "rig_id", "calibration",
    "software_version", "plan_name", "plan_version", "status", "started_at", "path",
    "writer_pid", "writer_host", "meta", "design",
)
JSON_COLUMNS = frozenset({"calibration", "metrics", "meta", "summary", "diagnosis", "detail"})

# The SQLite schema, one list of statements per version (applied in order, never edited).
_SQLITE_MIGRATIONS: dict[int, tuple[str, ...]] = {
    1: (
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
    ),
    2: (
        "ALTER TABLE runs ADD COLUMN outcome TEXT",
        "ALTER TABLE runs ADD COLUMN meta TEXT",
        "ALTER TABLE runs ADD COLUMN design TEXT",
        "CREATE INDEX runs_by_start ON runs (started_at)",
        "CREATE INDEX runs_by_serial ON runs (unit_serial, started_at)",
        "CREATE INDEX runs_by_outcome ON runs (outcome, started_at)",
        "CREATE INDEX runs_by_design ON runs (design, started_at)",
        """CREATE TABLE results (
            result_id INTEGER PRIMARY KEY AUTOINCREMENT,
            run_id TEXT REFERENCES runs (run_id),
            campaign_id TEXT REFERENCES campaigns (campaign_id),
            software_version TEXT NOT NULL,
            computed_at TEXT NOT NULL,
            metrics TEXT,
            diagnosis TEXT,
            error TEXT,
            CHECK ((run_id IS NULL) <> (campaign_id IS NULL))
        )""",
        "CREATE UNIQUE INDEX results_of_run ON results (run_id, software_version)"
        " WHERE run_id IS NOT NULL",
        "CREATE UNIQUE INDEX results_of_campaign ON results (campaign_id, software_version)"
        " WHERE campaign_id IS NOT NULL",
        """CREATE TABLE audit (
            audit_id INTEGER PRIMARY KEY AUTOINCREMENT,
            at TEXT NOT NULL,
            action TEXT NOT NULL,
            target TEXT NOT NULL,
            pid INTEGER,
            host TEXT,
            detail TEXT
        )""",
        "CREATE INDEX audit_by_target ON audit (target)",
    ),
}


@dataclass(frozen=True)
class RunFilter:
    """Which runs :meth:`IndexBackend.query_runs` returns (None: any). ``since``/``until``
    bound ``started_at`` (ISO 8601 UTC text, ``since`` inclusive, ``until`` exclusive)."""

    campaign_id: str | None = None
    status: str | None = None
    serial: str | None = None
    outcome: str | None = None
    design: str | None = None
    since: str | None = None
    until: str | None = None
    limit: int | None = None

    def where(self, placeholder: str) -> tuple[str, list[Any]]:
        """The SQL ``WHERE`` clause (or "") and its arguments, ``placeholder`` per argument."""
        parts, args = [], []
        for column, value, op in (
            ("campaign_id", self.campaign_id, "="), ("status", self.status, "="),
            ("unit_serial", self.serial, "="), ("outcome", self.outcome, "="),
            ("design", self.design, "="), ("started_at", self.since, ">="),
            ("started_at", self.until, "<"),
        ):
            if value is not None:
                parts.append(f"{column} {op} {placeholder}")
                args.append(value)
        return (" WHERE " + " AND ".join(parts) if parts else ""), args


# What a finalize callback returns: the columns to set on the run (status, reason,
# finished_at, n_samples, metrics, outcome). It is called inside the transaction that holds
# the run's row, so two processes can never both close the same run.
RunUpdate = dict[str, Any]


class IndexBackend(ABC):
    """What the store needs from its index; rows are mappings of column name to value
    (JSON columns as Python objects). Every method is safe to call from many threads and
    processes at once."""

    #: How the store is named in messages (a path, or a URL without its password).
    location: str

    @contextlib.contextmanager
    def retry_window(self, seconds: float) -> Iterator[None]:
        """Within the block, this thread's calls give up on a lost database after
        ``seconds`` (a database back-end; the embedded index has nothing to wait for)."""
        yield

    @abstractmethod
    def exists(self) -> bool:
        """Does the index exist already (the store was created)?"""

    @abstractmethod
    def ensure_schema(self) -> None:
        """Create the index if absent and migrate it to :data:`SCHEMA_VERSION`; StoreError if
        it was written by a newer version."""

    @abstractmethod
    def schema_version(self) -> int:
        """The schema version the index is at (0: no index)."""

    @abstractmethod
    def run_exists(self, run_id: str) -> bool: ...

    @abstractmethod
    def insert_run(self, row: Mapping[str, Any]) -> None:
        """Insert a running run (keys :data:`RUN_INSERT_COLUMNS`) and its audit record."""

    @abstractmethod
    def finalize_run(self, run_id: str, update: Callable[[str | None], RunUpdate | None],
                     audit: Mapping[str, Any]) -> bool:
        """Close a running run: in one transaction holding its row, call ``update(campaign_id)``
        (which writes the run's files and returns the new column values, or None to leave it
        alone) and apply it. False if the run is not "running" (or ``update`` returned None).
        """

    @abstractmethod
    def running_runs(self) -> list[tuple[str, str]]:
        """``(run_id, path)`` of every run marked "running", oldest first."""

    @abstractmethod
    def query_runs(self, flt: RunFilter) -> list[Mapping[str, Any]]:
        """Rows of ``runs`` matching ``flt``, newest first (started_at, then insertion)."""

    @abstractmethod
    def get_run(self, run_id: str) -> Mapping[str, Any] | None: ...

    @abstractmethod
    def insert_campaign(self, row: Mapping[str, Any]) -> None:
        """Insert a running campaign (campaign_id, name, started_at, path, meta)."""

    @abstractmethod
    def finish_campaign(self, campaign_id: str,
                        update: Callable[[Mapping[str, Any]], RunUpdate]) -> None:
        """In one transaction holding the campaign's row: StoreError unless it is running,
        else ``update(row)`` (writes campaign.json, returns status/finished_at/summary)."""

    @abstractmethod
    def get_campaign(self, campaign_id: str) -> Mapping[str, Any] | None: ...

    @abstractmethod
    def list_campaigns(self) -> list[Mapping[str, Any]]:
        """Every campaign row, newest first."""

    @abstractmethod
    def add_result(self, row: Mapping[str, Any]) -> bool:
        """Keep one re-computed result (run_id or campaign_id, software_version,
        computed_at, metrics, diagnosis, error). Earlier results stay. False if this
        software version's result of that run/campaign is there already."""

    @abstractmethod
    def results(self, *, run_id: str | None = None, campaign_id: str | None = None,
                software_version: str | None = None) -> list[Mapping[str, Any]]:
        """Stored results, oldest first, optionally of one run/campaign/version."""

    @abstractmethod
    def audit_records(self, target: str | None = None) -> list[Mapping[str, Any]]:
        """The audit trail (oldest first), optionally of one run or campaign id."""

    @abstractmethod
    def bulk_insert_runs(self, rows: Iterable[Mapping[str, Any]]) -> int:
        """Insert finished runs in bulk (imports, benchmarks): every column given per row;
        returns the count. No audit records, no files."""

    def close(self) -> None:  # noqa: B027 (a back-end without connections has nothing to do)
        """Drop any connection held (the next call reconnects)."""


# --------------------------------------------------------------------------- SQLite


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
    """Create the index if needed, switch it to WAL mode and migrate it to the current
    schema version (StoreError if it is newer than this software reads)."""
    with contextlib.closing(connect(db_path, busy_timeout_s)) as conn:
        _set_wal(conn, db_path, busy_timeout_s)
        if conn.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION:
            return
        with write_transaction(conn):
            version = conn.execute("PRAGMA user_version").fetchone()[0]
            check_version(version, str(db_path))
            for step in range(version + 1, SCHEMA_VERSION + 1):
                for statement in _SQLITE_MIGRATIONS[step]:
                    conn.execute(statement)
            conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")


def check_version(version: int, where: str) -> None:
    """StoreError if an index at ``version`` is newer than this software reads."""
    if version > SCHEMA_VERSION:
        raise StoreError(
            f"{where}: index schema version {version} is newer than this software "
            f"reads ({SCHEMA_VERSION}); update backlash-rig"
        )


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


def _from_json(value: Any) -> Any:
    """A JSON column's value as Python (SQLite gives text, PostgreSQL jsonb gives objects)."""
    return json.loads(value) if isinstance(value, str | bytes) else value


def _row_dict(row: sqlite3.Row) -> dict[str, Any]:
    return {k: (_from_json(row[k]) if k in JSON_COLUMNS else row[k]) for k in row.keys()}  # noqa: SIM118


class SqliteIndex(IndexBackend):
    """The index in ``<root>/index.sqlite`` (see the module doc)."""

    def __init__(self, root: Path, busy_timeout_s: float) -> None:
        self.db_path = root / INDEX_NAME
        self.busy_timeout_s = busy_timeout_s
        self.location = str(root)

    def _connect(self) -> contextlib.closing[sqlite3.Connection]:
        return contextlib.closing(connect(self.db_path, self.busy_timeout_s))

    def exists(self) -> bool:
        return self.db_path.is_file()

    def ensure_schema(self) -> None:
        create_index(self.db_path, self.busy_timeout_s)

    def schema_version(self) -> int:
        if not self.exists():
            return 0
        with self._connect() as conn:
            return int(conn.execute("PRAGMA user_version").fetchone()[0])

    def run_exists(self, run_id: str) -> bool:
        with self._connect() as conn:
            return conn.execute("SELECT 1 FROM runs WHERE run_id = ?", (run_id,)
                                ).fetchone() is not None

    def _audit(self, conn: sqlite3.Connection, audit: Mapping[str, Any]) -> None:
        conn.execute(
            "INSERT INTO audit (at, action, target, pid, host, detail) VALUES (?, ?, ?, ?, ?, ?)",
            (audit["at"], audit["action"], audit["target"], audit.get("pid"),
             audit.get("host"), to_json(audit.get("detail"))),
        )

    def insert_run(self, row: Mapping[str, Any]) -> None:
        values = [to_json(row[c]) if c in JSON_COLUMNS else row[c] for c in RUN_INSERT_COLUMNS]
        with self._connect() as conn, write_transaction(conn):
            conn.execute(
                f"INSERT INTO runs ({', '.join(RUN_INSERT_COLUMNS)}) "
                f"VALUES ({', '.join('?' * len(RUN_INSERT_COLUMNS))})", values)
            self._audit(conn, {"at": row["started_at"], "action": "run started",
                               "target": row["run_id"], "pid": row["writer_pid"],
                               "host": row["writer_host"]})

    def add_audit(self, audit: Mapping[str, Any]) -> None:
        """One audit record on its own (an operator's action: a fault reset, an override)."""
        with self._connect() as conn, write_transaction(conn):
            self._audit(conn, audit)

    def finalize_run(self, run_id: str, update: Callable[[str | None], RunUpdate | None],
                     audit: Mapping[str, Any]) -> bool:
        with self._connect() as conn, write_transaction(conn):
            row = conn.execute(
                "SELECT status, campaign_id FROM runs WHERE run_id = ?", (run_id,)
            ).fetchone()
            if row is None or row["status"] != "running":
                return False
            values = update(row["campaign_id"])
            if values is None:
                return False
            cols = list(values)
            conn.execute(
                f"UPDATE runs SET {', '.join(f'{c} = ?' for c in cols)} "
                "WHERE run_id = ? AND status = 'running'",
                [to_json(values[c]) if c in JSON_COLUMNS else values[c] for c in cols]
                + [run_id],
            )
            self._audit(conn, audit)
        return True

    def running_runs(self) -> list[tuple[str, str]]:
        with self._connect() as conn:
            rows = conn.execute(
                "SELECT run_id, path FROM runs WHERE status = 'running' ORDER BY rowid"
            ).fetchall()
        return [(r["run_id"], r["path"]) for r in rows]

    def query_runs(self, flt: RunFilter) -> list[Mapping[str, Any]]:
        where, args = flt.where("?")
        sql = f"SELECT * FROM runs{where} ORDER BY started_at DESC, rowid DESC"
        if flt.limit is not None:
            sql += f" LIMIT {int(flt.limit)}"
        with self._connect() as conn:
            return [_row_dict(r) for r in conn.execute(sql, args).fetchall()]

    def get_run(self, run_id: str) -> Mapping[str, Any] | None:
        with self._connect() as conn:
            row = conn.execute("SELECT * FROM runs WHERE run_id = ?", (run_id,)).fetchone()
        return None if row is None else _row_dict(row)

    def insert_campaign(self, row: Mapping[str, Any]) -> None:
        with self._connect() as conn, write_transaction(conn):
            conn.execute(
                """INSERT INTO campaigns (campaign_id, name, status, started_at, path, meta)
                VALUES (?, ?, 'running', ?, ?, ?)""",
                (row["campaign_id"], row["name"], row["started_at"], row["path"],
                 to_json(row["meta"])),
            )
            self._audit(conn, {"at": row["started_at"], "action": "campaign started",
                               "target": row["campaign_id"], "pid": row.get("pid"),
                               "host": row.get("host")})

    def finish_campaign(self, campaign_id: str,
                        update: Callable[[Mapping[str, Any]], RunUpdate]) -> None:
        with self._connect() as conn, write_transaction(conn):
            row = conn.execute(
                "SELECT * FROM campaigns WHERE campaign_id = ?", (campaign_id,)
            ).fetchone()
            if row is None:
                raise StoreError(f"no campaign {campaign_id!r} in the store {self.location}")
            if row["status"] != "running":
                raise StoreError(f"campaign {campaign_id} is already {row['status']}")
            values = update(_row_dict(row))
            audit = values.pop("audit")
            conn.execute(
                "UPDATE campaigns SET status = ?, finished_at = ?, summary = ? "
                "WHERE campaign_id = ?",
                (values["status"], values["finished_at"], to_json(values["summary"]),
                 campaign_id),
            )
            self._audit(conn, audit)

    def get_campaign(self, campaign_id: str) -> Mapping[str, Any] | None:
        with self._connect() as conn:
            row = conn.execute(
                "SELECT * FROM campaigns WHERE campaign_id = ?", (campaign_id,)
            ).fetchone()
        return None if row is None else _row_dict(row)

    def list_campaigns(self) -> list[Mapping[str, Any]]:
        with self._connect() as conn:
            rows = conn.execute("SELECT * FROM campaigns ORDER BY rowid DESC").fetchall()
        return [_row_dict(r) for r in rows]

    def add_result(self, row: Mapping[str, Any]) -> bool:
        with self._connect() as conn, write_transaction(conn):
            cur = conn.execute(
                """INSERT INTO results (run_id, campaign_id, software_version, computed_at,
                metrics, diagnosis, error) VALUES (?, ?, ?, ?, ?, ?, ?)
                ON CONFLICT DO NOTHING""",
                (row.get("run_id"), row.get("campaign_id"), row["software_version"],
                 row["computed_at"], to_json(row.get("metrics")),
                 to_json(row.get("diagnosis")), row.get("error")),
            )
            return cur.rowcount == 1

    def results(self, *, run_id: str | None = None, campaign_id: str | None = None,
                software_version: str | None = None) -> list[Mapping[str, Any]]:
        parts, args = [], []
        for column, value in (("run_id", run_id), ("campaign_id", campaign_id),
                              ("software_version", software_version)):
            if value is not None:
                parts.append(f"{column} = ?")
                args.append(value)
        where = " WHERE " + " AND ".join(parts) if parts else ""
        with self._connect() as conn:
            rows = conn.execute(f"SELECT * FROM results{where} ORDER BY result_id", args)
            return [_row_dict(r) for r in rows.fetchall()]

    def audit_records(self, target: str | None = None) -> list[Mapping[str, Any]]:
        sql, args = "SELECT * FROM audit", []
        if target is not None:
            sql, args = sql + " WHERE target = ?", [target]
        with self._connect() as conn:
            return [_row_dict(r) for r in conn.execute(sql + " ORDER BY audit_id", args)]

    def bulk_insert_runs(self, rows: Iterable[Mapping[str, Any]]) -> int:
        rows = iter(rows)
        first = next(rows, None)
        if first is None:
            return 0
        cols = list(first)
        sql = f"INSERT INTO runs ({', '.join(cols)}) VALUES ({', '.join('?' * len(cols))})"
        count = 0

        def values() -> Iterator[list[Any]]:
            nonlocal count
            for row in itertools.chain([first], rows):
                count += 1
                yield [to_json(row[c]) if c in JSON_COLUMNS else row[c] for c in cols]

        with self._connect() as conn, write_transaction(conn):
            conn.executemany(sql, values())
        return count


# --------------------------------------------------------------------------- rows


def run_info(row: Mapping[str, Any], root: Path) -> RunInfo:
    """A :class:`RunInfo` from a ``runs`` row; ``path`` made absolute under ``root``."""
    return RunInfo(
        run_id=row["run_id"],
        campaign_id=row["campaign_id"],
        unit_serial=row["unit_serial"],
        operator=row["operator"],
        rig_id=row["rig_id"],
        calibration=_from_json(row["calibration"]),
        software_version=row["software_version"],
        plan_name=row["plan_name"],
        plan_version=row["plan_version"],
        status=row["status"],
        reason=row["reason"],
        started_at=row["started_at"],
        finished_at=row["finished_at"],
        n_samples=row["n_samples"],
        path=root / row["path"],
        metrics=_from_json(row["metrics"]) if row["metrics"] is not None else None,
        writer_pid=row["writer_pid"],
        writer_host=row["writer_host"],
        outcome=_indexed_outcome(row),
        design=row.get("design"),
    )


def _indexed_outcome(row: Mapping[str, Any]) -> str | None:
    """The run's outcome as every view shows it (rig/results/outcome.py ``recorded_outcome``) when
    the row keeps the run's record (``meta``); else the indexed word as it is."""
    from rig.results.outcome import recorded_outcome

    meta = _from_json(row["meta"]) if row.get("meta") is not None else None
    if not isinstance(meta, dict):
        return row.get("outcome")
    metrics = _from_json(row["metrics"]) if row.get("metrics") is not None else None
    return recorded_outcome({**meta, "status": row["status"], "outcome": row.get("outcome"),
                             "result": metrics if metrics is not None else meta.get("result")})


def campaign_info(row: Mapping[str, Any], root: Path) -> CampaignInfo:
    """A :class:`CampaignInfo` from a ``campaigns`` row."""
    return CampaignInfo(
        campaign_id=row["campaign_id"],
        name=row["name"],
        status=row["status"],
        started_at=row["started_at"],
        finished_at=row["finished_at"],
        path=root / row["path"],
        meta=_from_json(row["meta"]),
        summary=_from_json(row["summary"]) if row["summary"] is not None else None,
    )
