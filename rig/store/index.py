"""The store's SQLite index (``<root>/index.sqlite``), the embedded default.

The database runs in WAL mode so that readers (the web page, ``rig runs``) never block the
writer and the writer never blocks them. Every connection is short-lived and private to one
call, waits up to a busy timeout for a lock instead of failing with "database is locked",
and writes in short ``BEGIN IMMEDIATE`` transactions (taking the write lock up front, so a
transaction never has to upgrade a read lock, the case SQLite cannot wait for). The schema
version is SQLite's ``user_version``.

The interface is :class:`rig.store.backend.IndexBackend`; the schema and the queries are
the shared ones of :mod:`rig.store.sql`; the PostgreSQL index is
:class:`rig.store.index_pg.PostgresIndex`.
"""

from __future__ import annotations

import contextlib
import os
import sqlite3
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

from rig.store.backend import (
    JSON_COLUMNS,
    SCHEMA_VERSION,
    check_version,
    from_json,
    json_text_params,
    to_json,
)
from rig.store.ids import StoreError, StoreReadOnly
from rig.store.sql import Dialect, SqlIndex, T, first_and_rest, migrate

INDEX_NAME = "index.sqlite"


def connect(db_path: Path, busy_timeout_s: float) -> sqlite3.Connection:
    """A new connection in autocommit mode (explicit transactions), rows as sqlite3.Row."""
    conn = sqlite3.connect(db_path, timeout=busy_timeout_s, isolation_level=None)
    conn.row_factory = sqlite3.Row
    conn.execute("PRAGMA synchronous = FULL")
    conn.execute("PRAGMA foreign_keys = ON")
    return conn


def connect_read_only(db_path: Path, busy_timeout_s: float) -> sqlite3.Connection:
    """A read-only connection (``mode=ro``) to an index this process cannot write; when
    SQLite cannot open its WAL files read-only there (no ``-shm`` and no right to make one),
    the file is read as it is (``immutable=1``: nobody else is writing it then)."""
    uri = f"{db_path.absolute().as_uri()}?mode=ro"
    for suffix in ("", "&immutable=1"):
        conn = sqlite3.connect(uri + suffix, uri=True, timeout=busy_timeout_s,
                               isolation_level=None)
        try:
            conn.execute("PRAGMA user_version").fetchone()
        except sqlite3.OperationalError:
            conn.close()
            if suffix:
                raise
            continue
        conn.row_factory = sqlite3.Row
        return conn
    raise AssertionError("unreachable")


def read_only_reason(root: Path, db_path: Path) -> str | None:
    """Why this process cannot write the store at ``root`` (None: it can)."""
    if os.access(root, os.W_OK) and os.access(db_path, os.W_OK):
        return None
    try:
        if os.statvfs(root).f_flag & os.ST_RDONLY:
            return "a read-only file system"
    except OSError:
        pass
    return "no permission to write there"


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


def _row_dict(row: sqlite3.Row) -> dict[str, Any]:
    """A row as a dict, the JSON columns (text in SQLite) as Python objects."""
    return {k: (from_json(row[k]) if k in JSON_COLUMNS else row[k]) for k in row.keys()}  # noqa: SIM118


# SQLite's words are the dialect's defaults: "?", the rowid, JSON as TEXT, no row locks.
SQLITE = Dialect(json_param=to_json, row=_row_dict, transaction=write_transaction)


def create_index(db_path: Path, busy_timeout_s: float) -> None:
    """Create the index if needed, switch it to WAL mode and migrate it to the current
    schema version (StoreError if it is newer than this software reads)."""
    with contextlib.closing(connect(db_path, busy_timeout_s)) as conn:
        _set_wal(conn, db_path, busy_timeout_s)
        if _user_version(conn) == SCHEMA_VERSION:
            return
        with write_transaction(conn):
            version = _user_version(conn)
            check_version(version, str(db_path))
            migrate(conn, SQLITE, version, lambda step: None)
            conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")


def _user_version(conn: sqlite3.Connection) -> int:
    return int(conn.execute("PRAGMA user_version").fetchone()[0])


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


class SqliteIndex(SqlIndex):
    """The index in ``<root>/index.sqlite`` (see the module doc)."""

    dialect = SQLITE

    def __init__(self, root: Path, busy_timeout_s: float) -> None:
        self.db_path = root / INDEX_NAME
        self.busy_timeout_s = busy_timeout_s
        self.location = str(root)
        self.read_only: str | None = None
        """Why this process may only read the index (set by :meth:`ensure_schema`)."""

    def _call(self, fn: Callable[[sqlite3.Connection, int], T]) -> T:
        """``fn(connection, 0)`` on a new connection, closed afterwards."""
        opener = connect if self.read_only is None else connect_read_only
        with contextlib.closing(opener(self.db_path, self.busy_timeout_s)) as conn:
            return fn(conn, 0)

    def _write(self, fn: Callable[[sqlite3.Connection, int], T]) -> T:
        if self.read_only is not None:
            raise StoreReadOnly(f"the store {self.location} is read-only "
                                f"({self.read_only}): nothing can be written to it")
        return super()._write(fn)

    def exists(self) -> bool:
        return self.db_path.is_file()

    def ensure_schema(self) -> None:
        """Create or migrate the index; an index this process cannot write is opened
        read-only instead (its schema must then be the current one)."""
        if self.exists():
            self.read_only = read_only_reason(self.db_path.parent, self.db_path)
        if self.read_only is None:
            create_index(self.db_path, self.busy_timeout_s)
            return
        version = self.schema_version()
        check_version(version, str(self.db_path))
        if version != SCHEMA_VERSION:
            raise StoreError(f"{self.db_path}: schema version {version}, this software reads "
                             f"{SCHEMA_VERSION}; the store is read-only ({self.read_only}), "
                             "so it cannot be migrated: open it once with write access")

    def schema_version(self) -> int:
        if not self.exists():
            return 0
        return self._call(lambda conn, _: _user_version(conn))

    def bulk_insert_runs(self, rows: Iterable[Mapping[str, Any]]) -> int:
        first, rows = first_and_rest(rows)
        if first is None:
            return 0
        cols = list(first)
        sql = f"INSERT INTO runs ({', '.join(cols)}) VALUES ({SQLITE.marks(len(cols))})"
        count = 0

        def values() -> Iterator[list[Any]]:
            nonlocal count
            for row in rows:
                count += 1
                yield json_text_params(row, cols)

        self._write(lambda conn, _: conn.executemany(sql, values()))
        return count
