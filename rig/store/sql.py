"""One SQL layer for both index back-ends: the schema's migrations and every query, each
written once, spelled for a database by a small :class:`Dialect`.

:class:`SqlIndex` implements :class:`rig.store.backend.IndexBackend` on these texts; a
back-end adds what genuinely differs: how it connects (and reconnects), how it keeps the
schema version, and how it inserts in bulk (:mod:`rig.store.index` for SQLite,
:mod:`rig.store.index_pg` for PostgreSQL).
"""

from __future__ import annotations

import itertools
from abc import abstractmethod
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import Any, TypeVar

from rig.store.backend import (
    JSON_COLUMNS,
    RUN_INSERT_COLUMNS,
    SCHEMA_VERSION,
    IndexBackend,
    RunFilter,
    RunUpdate,
    where_clause,
)
from rig.store.ids import StoreError

T = TypeVar("T")

#: A database connection (sqlite3.Connection or psycopg.Connection): ``execute(sql, args)``
#: returns a cursor with ``fetchone``, ``fetchall`` and ``rowcount``.
Connection = Any


@dataclass(frozen=True)
class Dialect:
    """How one database spells what the shared schema and queries need. The words default
    to SQLite's (the embedded back-end); a database overrides those it spells otherwise."""

    #: The JSON adapter: a Python value (None stays None) as a query parameter.
    json_param: Callable[[Any], Any]
    #: A fetched row as a dict, JSON columns as Python objects.
    row: Callable[[Any], dict[str, Any]]
    #: The write transaction of a connection (a context manager; rolls back on error).
    transaction: Callable[[Connection], AbstractContextManager[Any]]
    #: The parameter marker.
    placeholder: str = "?"
    #: The column that keeps insertion order (SQLite's implicit rowid, or an identity column).
    order_column: str = "rowid"
    #: The type of a JSON column.
    json_type: str = "TEXT"
    #: The type of an automatically numbered primary key.
    serial_key: str = "INTEGER PRIMARY KEY AUTOINCREMENT"
    #: The declaration of the insertion-order column of runs and campaigns, after their
    #: key ("": the implicit rowid).
    order_declaration: str = ""
    #: The trailing columns of the history indexes: started_at, then insertion order where
    #: an index does not keep it implicitly (SQLite's indexes end in the rowid).
    history_order: str = "started_at"
    #: Appended to a read of the row a write transaction changes: the row lock ("": the
    #: transaction holds the whole database, SQLite's BEGIN IMMEDIATE).
    row_lock: str = ""
    #: Appended to an insert whose retry after a lost commit may find its own row; ``{key}``
    #: is the key column ("": a duplicate is an error, no retry can have written it).
    on_duplicate: str = ""

    def marks(self, n: int) -> str:
        """``n`` placeholders, comma-separated."""
        return ", ".join([self.placeholder] * n)

    def params(self, row: Mapping[str, Any], columns: Iterable[str]) -> list[Any]:
        """``row``'s values of ``columns``, the JSON columns through :attr:`json_param`."""
        return [self.json_param(row[c]) if c in JSON_COLUMNS else row[c] for c in columns]


def migrations(d: Dialect) -> dict[int, tuple[str, ...]]:
    """The schema, one tuple of statements per version (applied in order, never edited)."""
    order = d.order_declaration
    return {
        1: (
            f"""CREATE TABLE IF NOT EXISTS campaigns (
            campaign_id TEXT PRIMARY KEY,{order}
            name TEXT NOT NULL,
            status TEXT NOT NULL CHECK (status IN ('running', 'completed', 'aborted')),
            started_at TEXT NOT NULL,
            finished_at TEXT,
            path TEXT NOT NULL,
            meta {d.json_type} NOT NULL,
            summary {d.json_type}
        )""",
            f"""CREATE TABLE IF NOT EXISTS runs (
            run_id TEXT PRIMARY KEY,{order}
            campaign_id TEXT REFERENCES campaigns (campaign_id),
            unit_serial TEXT,
            operator TEXT,
            rig_id TEXT,
            calibration {d.json_type} NOT NULL,
            software_version TEXT NOT NULL,
            plan_name TEXT,
            plan_version TEXT,
            status TEXT NOT NULL CHECK (status IN ('running', 'completed', 'aborted')),
            reason TEXT,
            started_at TEXT NOT NULL,
            finished_at TEXT,
            n_samples INTEGER,
            path TEXT NOT NULL,
            metrics {d.json_type},
            writer_pid INTEGER,
            writer_host TEXT
        )""",
            "CREATE INDEX IF NOT EXISTS runs_by_status ON runs (status)",
            "CREATE INDEX IF NOT EXISTS runs_by_campaign ON runs (campaign_id)",
        ),
        2: (
            "ALTER TABLE runs ADD COLUMN outcome TEXT",
            f"ALTER TABLE runs ADD COLUMN meta {d.json_type}",
            "ALTER TABLE runs ADD COLUMN design TEXT",
            f"CREATE INDEX runs_by_start ON runs ({d.history_order})",
            f"CREATE INDEX runs_by_serial ON runs (unit_serial, {d.history_order})",
            f"CREATE INDEX runs_by_outcome ON runs (outcome, {d.history_order})",
            f"CREATE INDEX runs_by_design ON runs (design, {d.history_order})",
            f"""CREATE TABLE results (
            result_id {d.serial_key},
            run_id TEXT REFERENCES runs (run_id),
            campaign_id TEXT REFERENCES campaigns (campaign_id),
            software_version TEXT NOT NULL,
            computed_at TEXT NOT NULL,
            metrics {d.json_type},
            diagnosis {d.json_type},
            error TEXT,
            CHECK ((run_id IS NULL) <> (campaign_id IS NULL))
        )""",
            "CREATE UNIQUE INDEX results_of_run ON results (run_id, software_version)"
            " WHERE run_id IS NOT NULL",
            "CREATE UNIQUE INDEX results_of_campaign ON results (campaign_id, software_version)"
            " WHERE campaign_id IS NOT NULL",
            f"""CREATE TABLE audit (
            audit_id {d.serial_key},
            at TEXT NOT NULL,
            action TEXT NOT NULL,
            target TEXT NOT NULL,
            pid INTEGER,
            host TEXT,
            detail {d.json_type}
        )""",
            "CREATE INDEX audit_by_target ON audit (target)",
        ),
    }


def migrate(conn: Connection, d: Dialect, version: int,
            mark: Callable[[int], object]) -> None:
    """Apply the migrations after ``version`` up to :data:`SCHEMA_VERSION` on ``conn``
    (inside the caller's transaction); ``mark(step)`` after each step's statements."""
    steps = migrations(d)
    for step in range(version + 1, SCHEMA_VERSION + 1):
        for statement in steps[step]:
            conn.execute(statement)
        mark(step)


def first_and_rest(rows: Iterable[Mapping[str, Any]]
                   ) -> tuple[Mapping[str, Any] | None, Iterator[Mapping[str, Any]]]:
    """The first row (None if there is none) and an iterator over all of them."""
    rest = iter(rows)
    first = next(rest, None)
    return first, itertools.chain(() if first is None else [first], rest)


class SqlIndex(IndexBackend):
    """:class:`IndexBackend` on the shared query texts; a back-end gives :attr:`dialect`
    and :meth:`_call` (and the schema, bulk insert and connection methods)."""

    dialect: Dialect

    @abstractmethod
    def _call(self, fn: Callable[[Connection, int], T]) -> T:
        """``fn(connection, attempt)`` on a connection of this back-end (``attempt`` > 0:
        a retry after a lost connection, whose earlier attempt may have committed)."""

    def _write(self, fn: Callable[[Connection, int], T]) -> T:
        """:meth:`_call` inside one write transaction."""
        def in_transaction(conn: Connection, attempt: int) -> T:
            with self.dialect.transaction(conn):
                return fn(conn, attempt)
        return self._call(in_transaction)

    def _all(self, sql: str, args: Iterable[Any] = ()) -> list[dict[str, Any]]:
        """Every row ``sql`` selects, as dicts (:attr:`Dialect.row`)."""
        args, row = list(args), self.dialect.row
        return self._call(lambda c, _: [row(r) for r in c.execute(sql, args).fetchall()])

    def _one(self, sql: str, args: Iterable[Any] = ()) -> dict[str, Any] | None:
        """The first row ``sql`` selects as a dict, or None."""
        args, row = list(args), self.dialect.row

        def one(conn: Connection, _: int) -> dict[str, Any] | None:
            r = conn.execute(sql, args).fetchone()
            return None if r is None else row(r)
        return self._call(one)

    def _audit(self, conn: Connection, audit: Mapping[str, Any]) -> None:
        conn.execute(
            "INSERT INTO audit (at, action, target, pid, host, detail) "
            f"VALUES ({self.dialect.marks(6)})",
            (audit["at"], audit["action"], audit["target"], audit.get("pid"),
             audit.get("host"), self.dialect.json_param(audit.get("detail"))),
        )

    def _insert_new(self, conn: Connection, attempt: int, sql: str, args: list[Any],
                    key: str, what: str) -> bool:
        """Insert one row keyed ``key`` (a run or campaign id); True if it is new. A retry
        after a lost commit finds its own row (False); a first attempt that finds one is
        a StoreError."""
        cur = conn.execute(sql + self.dialect.on_duplicate.format(key=key), args)
        if cur.rowcount == 1:
            return True
        if attempt == 0:
            raise StoreError(f"{what} is in the index already")
        return False

    # ------------------------------------------------------------------ runs

    def run_exists(self, run_id: str) -> bool:
        p = self.dialect.placeholder
        return self._one(f"SELECT 1 FROM runs WHERE run_id = {p}", [run_id]) is not None

    def add_audit(self, audit: Mapping[str, Any]) -> None:
        self._write(lambda conn, _: self._audit(conn, audit))

    def insert_run(self, row: Mapping[str, Any]) -> None:
        sql = (f"INSERT INTO runs ({', '.join(RUN_INSERT_COLUMNS)}) "
               f"VALUES ({self.dialect.marks(len(RUN_INSERT_COLUMNS))})")
        args = self.dialect.params(row, RUN_INSERT_COLUMNS)

        def ins(conn: Connection, attempt: int) -> None:
            # a retry after a lost commit finds its own row: the id was claimed by mkdir
            if self._insert_new(conn, attempt, sql, args, "run_id",
                                f"run id {row['run_id']}"):
                self._audit(conn, {"at": row["started_at"], "action": "run started",
                                   "target": row["run_id"], "pid": row["writer_pid"],
                                   "host": row["writer_host"]})
        self._write(ins)

    def finalize_run(self, run_id: str, update: Callable[[str | None], RunUpdate | None],
                     audit: Mapping[str, Any]) -> bool:
        d = self.dialect
        p = d.placeholder

        def fin(conn: Connection, _: int) -> bool:
            row = conn.execute(f"SELECT status, campaign_id FROM runs WHERE run_id = {p}"
                               f"{d.row_lock}", (run_id,)).fetchone()
            if row is None or row["status"] != "running":
                return False
            if d.row_lock and row["campaign_id"] is not None:  # campaign.json: one writer
                conn.execute(f"SELECT 1 FROM campaigns WHERE campaign_id = {p}{d.row_lock}",
                             (row["campaign_id"],))
            values = update(row["campaign_id"])
            if values is None:
                return False
            cols = list(values)
            conn.execute(
                f"UPDATE runs SET {', '.join(f'{c} = {p}' for c in cols)} "
                f"WHERE run_id = {p} AND status = 'running'",
                [*d.params(values, cols), run_id])
            self._audit(conn, audit)
            return True
        return self._write(fin)

    def refresh_run(self, run_id: str, values: Mapping[str, Any]) -> None:
        """Set the columns ``values`` of a finished run as its run.json now says them (the
        record; the index is its copy)."""
        p = self.dialect.placeholder
        cols = list(values)
        self._write(lambda conn, _: conn.execute(
            f"UPDATE runs SET {', '.join(f'{c} = {p}' for c in cols)} "
            f"WHERE run_id = {p} AND status <> 'running'",
            [*self.dialect.params(values, cols), run_id]))

    def running_runs(self) -> list[tuple[str, str]]:
        rows = self._all("SELECT run_id, path FROM runs WHERE status = 'running' "
                         f"ORDER BY {self.dialect.order_column}")
        return [(r["run_id"], r["path"]) for r in rows]

    def query_runs(self, flt: RunFilter) -> list[Mapping[str, Any]]:
        where, args = flt.where(self.dialect.placeholder)
        sql = (f"SELECT * FROM runs{where} "
               f"ORDER BY started_at DESC, {self.dialect.order_column} DESC")
        if flt.limit is not None:
            sql += f" LIMIT {int(flt.limit)}"
        return self._all(sql, args)

    def get_run(self, run_id: str) -> Mapping[str, Any] | None:
        return self._one(f"SELECT * FROM runs WHERE run_id = {self.dialect.placeholder}",
                         [run_id])

    # ------------------------------------------------------------------ campaigns

    def insert_campaign(self, row: Mapping[str, Any]) -> None:
        sql = ("INSERT INTO campaigns (campaign_id, name, status, started_at, path, meta) "
               f"VALUES ({self.dialect.marks(2)}, 'running', {self.dialect.marks(3)})")
        args = [row["campaign_id"], row["name"], row["started_at"], row["path"],
                self.dialect.json_param(row["meta"])]

        def ins(conn: Connection, attempt: int) -> None:
            if self._insert_new(conn, attempt, sql, args, "campaign_id",
                                f"campaign id {row['campaign_id']}"):
                self._audit(conn, {"at": row["started_at"], "action": "campaign started",
                                   "target": row["campaign_id"], "pid": row.get("pid"),
                                   "host": row.get("host")})
        self._write(ins)

    def finish_campaign(self, campaign_id: str,
                        update: Callable[[Mapping[str, Any]], RunUpdate]) -> None:
        d = self.dialect
        p = d.placeholder

        def fin(conn: Connection, _: int) -> None:
            row = conn.execute(f"SELECT * FROM campaigns WHERE campaign_id = {p}{d.row_lock}",
                               (campaign_id,)).fetchone()
            if row is None:
                raise StoreError(f"no campaign {campaign_id!r} in the store {self.location}")
            if row["status"] != "running":
                raise StoreError(f"campaign {campaign_id} is already {row['status']}")
            values = update(d.row(row))
            audit = values.pop("audit")
            conn.execute(
                f"UPDATE campaigns SET status = {p}, finished_at = {p}, summary = {p} "
                f"WHERE campaign_id = {p}",
                (values["status"], values["finished_at"], d.json_param(values["summary"]),
                 campaign_id))
            self._audit(conn, audit)
        self._write(fin)

    def get_campaign(self, campaign_id: str) -> Mapping[str, Any] | None:
        return self._one(
            f"SELECT * FROM campaigns WHERE campaign_id = {self.dialect.placeholder}",
            [campaign_id])

    def list_campaigns(self) -> list[Mapping[str, Any]]:
        return self._all(f"SELECT * FROM campaigns ORDER BY {self.dialect.order_column} DESC")

    # ------------------------------------------------------------------ results, audit

    def add_result(self, row: Mapping[str, Any]) -> bool:
        d = self.dialect
        args = (row.get("run_id"), row.get("campaign_id"), row["software_version"],
                row["computed_at"], d.json_param(row.get("metrics")),
                d.json_param(row.get("diagnosis")), row.get("error"))

        def ins(conn: Connection, attempt: int) -> bool:
            cur = conn.execute(
                "INSERT INTO results (run_id, campaign_id, software_version, computed_at, "
                f"metrics, diagnosis, error) VALUES ({d.marks(7)}) ON CONFLICT DO NOTHING",
                args)
            return cur.rowcount == 1 or attempt > 0
        return self._write(ins)

    def results(self, *, run_id: str | None = None, campaign_id: str | None = None,
                software_version: str | None = None) -> list[Mapping[str, Any]]:
        where, args = where_clause(
            (("run_id", run_id, "="), ("campaign_id", campaign_id, "="),
             ("software_version", software_version, "=")), self.dialect.placeholder)
        return self._all(f"SELECT * FROM results{where} ORDER BY result_id", args)

    def audit_records(self, target: str | None = None) -> list[Mapping[str, Any]]:
        where, args = where_clause((("target", target, "="),), self.dialect.placeholder)
        return self._all(f"SELECT * FROM audit{where} ORDER BY audit_id", args)
