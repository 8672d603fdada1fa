"""The store's index in PostgreSQL (``--store postgresql://...``), through psycopg 3.

The schema and the queries are the shared ones of :mod:`rig.store.sql` in the PostgreSQL
dialect (:data:`POSTGRES`): JSON columns are ``jsonb``, insertion order is a ``seq``
identity column, a write reads the rows it changes ``FOR UPDATE``. Migrations run under a
transaction-scoped advisory lock, so rigs starting at once never race on them; the version
is kept in the table ``rig_schema``.

Connections: one per thread and process, opened on first use, autocommit with explicit
transactions. Once a process has reached the database, a lost connection (the server
restarted, the network dropped) is retried with back-off for up to ``reconnect_s``
seconds, so a run in progress goes on recording its samples to its files and writes its
index rows when the server is back. The first connection of a process is not retried: a
wrong URL fails at once with a clear error.
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from typing import Any

import psycopg
import psycopg.conninfo
from psycopg.rows import dict_row
from psycopg.types.json import Jsonb

from rig.core.redact import redact, redact_text
from rig.store.backend import SCHEMA_VERSION, check_version, json_text_params
from rig.store.ids import StoreError, StoreUnavailable
from rig.store.sql import Dialect, SqlIndex, T, first_and_rest, migrate, migrations

log = logging.getLogger("rig.store")

_LOCK_KEY = 0x726967  # "rig": the advisory lock of schema migrations


def first_line(error: BaseException) -> str:
    """The first line of a driver's message (psycopg's run over several lines)."""
    text = str(error).strip()
    return text.splitlines()[0].strip() if text else type(error).__name__


def _jsonb(value: Any) -> Any:
    return None if value is None else Jsonb(value)


def _row(row: dict[str, Any]) -> dict[str, Any]:
    """A fetched row as it is: dict rows, jsonb already decoded by psycopg."""
    return row


POSTGRES = Dialect(
    json_param=_jsonb,
    row=_row,
    transaction=psycopg.Connection.transaction,
    placeholder="%s",
    order_column="seq",
    json_type="JSONB",
    serial_key="BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY",
    order_declaration=" seq BIGINT GENERATED ALWAYS AS IDENTITY UNIQUE,",
    history_order="started_at, seq",
    row_lock=" FOR UPDATE",
    on_duplicate=" ON CONFLICT ({key}) DO NOTHING",
)
_PG_MIGRATIONS = migrations(POSTGRES)  # (the tests build a version-1 schema from it)


class PostgresIndex(SqlIndex):
    """The index in the PostgreSQL database named by ``url`` (see the module doc)."""

    dialect = POSTGRES

    def __init__(self, url: str, *, reconnect_s: float = 60.0, connect_timeout_s: int = 5
                 ) -> None:
        self.url = url
        self.location = redact(url)
        try:  # parsed once where the URL enters: a malformed one is the user's, not a bug
            psycopg.conninfo.conninfo_to_dict(url)
        except psycopg.ProgrammingError as e:
            raise StoreError(f"the store URL {self.location} is malformed: "
                             f"{redact_text(first_line(e)).split(' in URI: ')[0]}") from e
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
            return _recorded_version(conn)
        return self._call(q)

    def ensure_schema(self) -> None:
        if self.schema_version() == SCHEMA_VERSION:
            return

        def migrate_locked(conn: psycopg.Connection, _: int) -> None:
            with conn.transaction():
                conn.execute("SELECT pg_advisory_xact_lock(%s)", (_LOCK_KEY,))
                conn.execute("CREATE TABLE IF NOT EXISTS rig_schema (version INTEGER NOT NULL)")
                version = _recorded_version(conn)
                check_version(version, self.location)
                migrate(conn, POSTGRES, version, lambda step: conn.execute(
                    "INSERT INTO rig_schema (version) VALUES (%s)", (step,)))
        self._call(migrate_locked)

    # ------------------------------------------------------------------ bulk

    def bulk_insert_runs(self, rows: Iterable[Mapping[str, Any]]) -> int:
        """COPY in one transaction (JSON columns as JSON text)."""
        first, rows = first_and_rest(rows)
        if first is None:
            return 0
        cols = list(first)

        def copy_all(conn: psycopg.Connection, attempt: int) -> int:
            if attempt:
                raise StoreError("bulk insert interrupted by a lost connection: not retried")
            n = 0
            with conn.transaction(), conn.cursor() as cur, cur.copy(
                    f"COPY runs ({', '.join(cols)}) FROM STDIN") as copy:
                for r in rows:
                    copy.write_row(json_text_params(r, cols))
                    n += 1
            return n
        return self._call(copy_all)


def _recorded_version(conn: psycopg.Connection) -> int:
    """The newest version in ``rig_schema`` (0: none)."""
    row = conn.execute("SELECT max(version) AS v FROM rig_schema").fetchone()
    return int(row["v"] or 0)
