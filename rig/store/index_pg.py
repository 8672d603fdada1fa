"""The store's index in PostgreSQL (``--store postgresql://...``), through psycopg 3.

Same tables, columns and versioned migrations as the SQLite index (:mod:`rig.store.index`);
JSON columns are ``jsonb``, insertion order is a ``seq`` identity column. Migrations run
under a transaction-scoped advisory lock, so rigs starting at once never race on them; the
version is kept in the table ``rig_schema``.

Connections: one per thread and process, opened on first use, autocommit with explicit
transactions. Once a process has reached the database, a lost connection (the server
restarted, the network dropped) is retried with back-off for up to ``reconnect_s``
seconds, so a run in progress goes on recording its samples to its files and writes its
index rows when the server is back. The first connection of a process is not retried: a
wrong URL fails at once with a clear error.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import os
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from typing import Any, TypeVar

import psycopg
from psycopg.rows import dict_row
from psycopg.types.json import Jsonb

from rig.core.redact import redact
from rig.store.ids import StoreError, StoreUnavailable
from rig.store.index import (
    JSON_COLUMNS,
    RUN_INSERT_COLUMNS,
    SCHEMA_VERSION,
    IndexBackend,
    RunFilter,
    RunUpdate,
    check_version,
    to_json,
)

log = logging.getLogger("rig.store")

T = TypeVar("T")
_LOCK_KEY = 0x726967  # "rig": the advisory lock of schema migrations

_PG_MIGRATIONS: dict[int, tuple[str, ...]] = {
    1: (
        """CREATE TABLE IF NOT EXISTS campaigns (
            campaign_id TEXT PRIMARY KEY,
            seq BIGINT GENERATED ALWAYS AS IDENTITY UNIQUE,
            name TEXT NOT NULL,
            status TEXT NOT NULL CHECK (status IN ('running', 'completed', 'aborted')),
            started_at TEXT NOT NULL,
            finished_at TEXT,
            path TEXT NOT NULL,
            meta JSONB NOT NULL,
            summary JSONB
        )""",
        """CREATE TABLE IF NOT EXISTS runs (
            run_id TEXT PRIMARY KEY,
            seq BIGINT GENERATED ALWAYS AS IDENTITY UNIQUE,
            campaign_id TEXT REFERENCES campaigns (campaign_id),
            unit_serial TEXT,
            operator TEXT,
            rig_id TEXT,
            calibration JSONB NOT NULL,
            software_version TEXT NOT NULL,
            plan_name TEXT,
            plan_version TEXT,
            status TEXT NOT NULL CHECK (status IN ('running', 'completed', 'aborted')),
            reason TEXT,
            started_at TEXT NOT NULL,
            finished_at TEXT,
            n_samples INTEGER,
            path TEXT NOT NULL,
            metrics JSONB,
            writer_pid INTEGER,
            writer_host TEXT
        )""",
        "CREATE INDEX IF NOT EXISTS runs_by_status ON runs (status)",
        "CREATE INDEX IF NOT EXISTS runs_by_campaign ON runs (campaign_id)",
    ),
    2: (
        "ALTER TABLE runs ADD COLUMN outcome TEXT",
        "ALTER TABLE runs ADD COLUMN meta JSONB",
        "ALTER TABLE runs ADD COLUMN design TEXT",
        "CREATE INDEX runs_by_start ON runs (started_at, seq)",
        "CREATE INDEX runs_by_serial ON runs (unit_serial, started_at, seq)",
        "CREATE INDEX runs_by_outcome ON runs (outcome, started_at, seq)",
        "CREATE INDEX runs_by_design ON runs (design, started_at, seq)",
        """CREATE TABLE results (
            result_id BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
            run_id TEXT REFERENCES runs (run_id),
            campaign_id TEXT REFERENCES campaigns (campaign_id),
            software_version TEXT NOT NULL,
            computed_at TEXT NOT NULL,
            metrics JSONB,
            diagnosis JSONB,
            error TEXT,
            CHECK ((run_id IS NULL) <> (campaign_id IS NULL))
        )""",
        "CREATE UNIQUE INDEX results_of_run ON results (run_id, software_version)"
        " WHERE run_id IS NOT NULL",
        "CREATE UNIQUE INDEX results_of_campaign ON results (campaign_id, software_version)"
        " WHERE campaign_id IS NOT NULL",
        """CREATE TABLE audit (
            audit_id BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
            at TEXT NOT NULL,
            action TEXT NOT NULL,
            target TEXT NOT NULL,
            pid INTEGER,
            host TEXT,
            detail JSONB
        )""",
        "CREATE INDEX audit_by_target ON audit (target)",
    ),
}


def first_line(error: BaseException) -> str:
    """The first line of a driver's message (psycopg's run over several lines)."""
    text = str(error).strip()
    return text.splitlines()[0].strip() if text else type(error).__name__


def _json(value: Any) -> Any:
    return None if value is None else Jsonb(value)


def _params(row: Mapping[str, Any], cols: Iterable[str]) -> list[Any]:
    return [_json(row[c]) if c in JSON_COLUMNS else row[c] for c in cols]


class PostgresIndex(IndexBackend):
    """The index in the PostgreSQL database named by ``url`` (see the module doc)."""

    def __init__(self, url: str, *, reconnect_s: float = 60.0, connect_timeout_s: int = 5
                 ) -> None:
        self.url = url
        self.location = redact(url)
        self.reconnect_s = float(reconnect_s)
        self.connect_timeout_s = int(connect_timeout_s)
        self._local = threading.local()
        self._ever_connected = False
        self._outage = False

    # ------------------------------------------------------------------ connections

    def _conn(self) -> psycopg.Connection:
        conn = getattr(self._local, "conn", None)
        if conn is not None and (conn.closed or self._local.pid != os.getpid()):
            conn = None
        if conn is None:
            conn = psycopg.connect(self.url, autocommit=True, row_factory=dict_row,
                                   connect_timeout=self.connect_timeout_s,
                                   application_name="backlash-rig")
            self._local.conn, self._local.pid = conn, os.getpid()
            self._ever_connected = True
        return conn

    def close(self) -> None:
        conn = getattr(self._local, "conn", None)
        self._local.conn = None
        if conn is not None and self._local.pid == os.getpid():
            conn.close()

    @contextlib.contextmanager
    def retry_window(self, seconds: float) -> Iterator[None]:
        """Within the block this thread's calls retry a lost connection for ``seconds`` (0:
        one attempt) instead of ``reconnect_s``; then :class:`StoreUnavailable`."""
        before = getattr(self._local, "window_s", None)
        self._local.window_s = float(seconds)
        try:
            yield
        finally:
            self._local.window_s = before

    def _call(self, fn: Callable[[psycopg.Connection, int], T]) -> T:
        """``fn(connection, attempt)``, retried on a lost connection (see the module doc);
        :class:`StoreUnavailable` (one line) when the retry window has passed."""
        deadline: float | None = None
        pause = 0.1
        attempt = 0
        window = getattr(self._local, "window_s", None)
        window = self.reconnect_s if window is None else min(window, self.reconnect_s)
        while True:
            had = getattr(self._local, "conn", None) is not None
            try:
                value = fn(self._conn(), attempt)
                self._outage = False
                return value
            except psycopg.OperationalError as e:
                self._local.conn = None
                if had and attempt == 0:  # a connection an outage broke: a new one at once
                    attempt += 1
                    continue
                if not self._ever_connected:
                    raise StoreError(
                        f"cannot open the store database {self.location}: "
                        f"{str(e).strip().splitlines()[-1] if str(e).strip() else e}") from e
                now = time.monotonic()
                deadline = deadline if deadline is not None else now + window
                if now >= deadline:
                    raise StoreUnavailable(
                        f"store database {self.location} unreachable for {window:g} s: "
                        f"{first_line(e)}") from e
                if not self._outage:  # once per outage, one line (the file log has more)
                    self._outage = True
                    log.warning("store database %s: %s; reconnecting", self.location,
                                first_line(e))
                time.sleep(min(pause, max(0.0, deadline - now)))
                pause = min(2.0, pause * 2)
                attempt += 1

    # ------------------------------------------------------------------ schema

    def exists(self) -> bool:
        return self.schema_version() > 0

    def schema_version(self) -> int:
        def q(conn: psycopg.Connection, _: int) -> int:
            if conn.execute("SELECT to_regclass('rig_schema') AS t").fetchone()["t"] is None:
                return 0
            row = conn.execute("SELECT max(version) AS v FROM rig_schema").fetchone()
            return int(row["v"] or 0)
        return self._call(q)

    def ensure_schema(self) -> None:
        if self.schema_version() == SCHEMA_VERSION:
            return

        def migrate(conn: psycopg.Connection, _: int) -> None:
            with conn.transaction():
                conn.execute("SELECT pg_advisory_xact_lock(%s)", (_LOCK_KEY,))
                conn.execute("CREATE TABLE IF NOT EXISTS rig_schema (version INTEGER NOT NULL)")
                row = conn.execute("SELECT max(version) AS v FROM rig_schema").fetchone()
                version = int(row["v"] or 0)
                check_version(version, self.location)
                for step in range(version + 1, SCHEMA_VERSION + 1):
                    for statement in _PG_MIGRATIONS[step]:
                        conn.execute(statement)
                    conn.execute("INSERT INTO rig_schema (version) VALUES (%s)", (step,))
        self._call(migrate)

    # ------------------------------------------------------------------ runs

    @staticmethod
    def _audit(conn: psycopg.Connection, audit: Mapping[str, Any]) -> None:
        conn.execute(
            "INSERT INTO audit (at, action, target, pid, host, detail) "
            "VALUES (%s, %s, %s, %s, %s, %s)",
            (audit["at"], audit["action"], audit["target"], audit.get("pid"),
             audit.get("host"), _json(audit.get("detail"))),
        )

    def run_exists(self, run_id: str) -> bool:
        return self._call(lambda c, _: c.execute(
            "SELECT 1 FROM runs WHERE run_id = %s", (run_id,)).fetchone() is not None)

    def add_audit(self, audit: Mapping[str, Any]) -> None:
        """One audit record on its own (an operator's action: a fault reset, an override)."""

        def add(conn: psycopg.Connection, attempt: int) -> None:
            with conn.transaction():
                self._audit(conn, audit)
        self._call(add)

    def insert_run(self, row: Mapping[str, Any]) -> None:
        cols = ", ".join(RUN_INSERT_COLUMNS)
        marks = ", ".join(["%s"] * len(RUN_INSERT_COLUMNS))

        def ins(conn: psycopg.Connection, attempt: int) -> None:
            with conn.transaction():
                # a retry after a lost commit finds its own row: the id was claimed by mkdir
                cur = conn.execute(f"INSERT INTO runs ({cols}) VALUES ({marks}) "
                                   "ON CONFLICT (run_id) DO NOTHING",
                                   _params(row, RUN_INSERT_COLUMNS))
                if cur.rowcount == 1:
                    self._audit(conn, {"at": row["started_at"], "action": "run started",
                                       "target": row["run_id"], "pid": row["writer_pid"],
                                       "host": row["writer_host"]})
                elif attempt == 0:
                    raise StoreError(f"run id {row['run_id']} is in the index already")
        self._call(ins)

    def finalize_run(self, run_id: str, update: Callable[[str | None], RunUpdate | None],
                     audit: Mapping[str, Any]) -> bool:
        def fin(conn: psycopg.Connection, _: int) -> bool:
            with conn.transaction():
                row = conn.execute(
                    "SELECT status, campaign_id FROM runs WHERE run_id = %s FOR UPDATE",
                    (run_id,)).fetchone()
                if row is None or row["status"] != "running":
                    return False
                if row["campaign_id"] is not None:  # campaign.json: one writer at a time
                    conn.execute("SELECT 1 FROM campaigns WHERE campaign_id = %s FOR UPDATE",
                                 (row["campaign_id"],))
                values = update(row["campaign_id"])
                if values is None:
                    return False
                cols = list(values)
                conn.execute(
                    f"UPDATE runs SET {', '.join(f'{c} = %s' for c in cols)} "
                    "WHERE run_id = %s AND status = 'running'",
                    [*_params(values, cols), run_id])
                self._audit(conn, audit)
                return True
        return self._call(fin)

    def running_runs(self) -> list[tuple[str, str]]:
        rows = self._call(lambda c, _: c.execute(
            "SELECT run_id, path FROM runs WHERE status = 'running' ORDER BY seq").fetchall())
        return [(r["run_id"], r["path"]) for r in rows]

    def query_runs(self, flt: RunFilter) -> list[Mapping[str, Any]]:
        where, args = flt.where("%s")
        sql = f"SELECT * FROM runs{where} ORDER BY started_at DESC, seq DESC"
        if flt.limit is not None:
            sql += f" LIMIT {int(flt.limit)}"
        return self._call(lambda c, _: c.execute(sql, args).fetchall())

    def get_run(self, run_id: str) -> Mapping[str, Any] | None:
        return self._call(lambda c, _: c.execute(
            "SELECT * FROM runs WHERE run_id = %s", (run_id,)).fetchone())

    # ------------------------------------------------------------------ campaigns

    def insert_campaign(self, row: Mapping[str, Any]) -> None:
        def ins(conn: psycopg.Connection, attempt: int) -> None:
            with conn.transaction():
                cur = conn.execute(
                    "INSERT INTO campaigns (campaign_id, name, status, started_at, path, meta) "
                    "VALUES (%s, %s, 'running', %s, %s, %s) ON CONFLICT DO NOTHING",
                    (row["campaign_id"], row["name"], row["started_at"], row["path"],
                     Jsonb(row["meta"])))
                if cur.rowcount == 1:
                    self._audit(conn, {"at": row["started_at"], "action": "campaign started",
                                       "target": row["campaign_id"], "pid": row.get("pid"),
                                       "host": row.get("host")})
                elif attempt == 0:
                    raise StoreError(f"campaign id {row['campaign_id']} is in the index already")
        self._call(ins)

    def finish_campaign(self, campaign_id: str,
                        update: Callable[[Mapping[str, Any]], RunUpdate]) -> None:
        def fin(conn: psycopg.Connection, _: int) -> None:
            with conn.transaction():
                row = conn.execute("SELECT * FROM campaigns WHERE campaign_id = %s FOR UPDATE",
                                   (campaign_id,)).fetchone()
                if row is None:
                    raise StoreError(f"no campaign {campaign_id!r} in the store {self.location}")
                if row["status"] != "running":
                    raise StoreError(f"campaign {campaign_id} is already {row['status']}")
                values = update(row)
                audit = values.pop("audit")
                conn.execute(
                    "UPDATE campaigns SET status = %s, finished_at = %s, summary = %s "
                    "WHERE campaign_id = %s",
                    (values["status"], values["finished_at"], _json(values["summary"]),
                     campaign_id))
                self._audit(conn, audit)
        self._call(fin)

    def get_campaign(self, campaign_id: str) -> Mapping[str, Any] | None:
        return self._call(lambda c, _: c.execute(
            "SELECT * FROM campaigns WHERE campaign_id = %s", (campaign_id,)).fetchone())

    def list_campaigns(self) -> list[Mapping[str, Any]]:
        return self._call(lambda c, _: c.execute(
            "SELECT * FROM campaigns ORDER BY seq DESC").fetchall())

    # ------------------------------------------------------------------ results, audit

    def add_result(self, row: Mapping[str, Any]) -> bool:
        def ins(conn: psycopg.Connection, attempt: int) -> bool:
            cur = conn.execute(
                """INSERT INTO results (run_id, campaign_id, software_version, computed_at,
                metrics, diagnosis, error) VALUES (%s, %s, %s, %s, %s, %s, %s)
                ON CONFLICT DO NOTHING""",
                (row.get("run_id"), row.get("campaign_id"), row["software_version"],
                 row["computed_at"], _json(row.get("metrics")), _json(row.get("diagnosis")),
                 row.get("error")))
            return cur.rowcount == 1 or attempt > 0
        return self._call(ins)

    def results(self, *, run_id: str | None = None, campaign_id: str | None = None,
                software_version: str | None = None) -> list[Mapping[str, Any]]:
        parts, args = [], []
        for column, value in (("run_id", run_id), ("campaign_id", campaign_id),
                              ("software_version", software_version)):
            if value is not None:
                parts.append(f"{column} = %s")
                args.append(value)
        where = " WHERE " + " AND ".join(parts) if parts else ""
        return self._call(lambda c, _: c.execute(
            f"SELECT * FROM results{where} ORDER BY result_id", args).fetchall())

    def audit_records(self, target: str | None = None) -> list[Mapping[str, Any]]:
        sql, args = "SELECT * FROM audit", []
        if target is not None:
            sql, args = sql + " WHERE target = %s", [target]
        return self._call(lambda c, _: c.execute(sql + " ORDER BY audit_id", args).fetchall())

    def bulk_insert_runs(self, rows: Iterable[Mapping[str, Any]]) -> int:
        """COPY in one transaction (JSON columns as JSON text)."""
        rows = iter(rows)
        first = next(rows, None)
        if first is None:
            return 0
        cols = list(first)

        def copy_all(conn: psycopg.Connection, attempt: int) -> int:
            if attempt:
                raise StoreError("bulk insert interrupted by a lost connection: not retried")
            n = 0
            with conn.transaction(), conn.cursor() as cur, cur.copy(
                    f"COPY runs ({', '.join(cols)}) FROM STDIN") as copy:
                for r in itertools.chain([first], rows):
                    copy.write_row([to_json(r[c]) if c in JSON_COLUMNS else r[c] for c in cols])
                    n += 1
            return n
        return self._call(copy_all)
