"""What the store needs from its index, whichever database keeps it: :class:`IndexBackend`,
the run filter, the columns and the schema version.

Two back-ends implement it, on one SQL layer (:mod:`rig.store.sql`):

- :class:`rig.store.index.SqliteIndex`: ``<root>/index.sqlite``, the embedded default;
- :class:`rig.store.index_pg.PostgresIndex`: a PostgreSQL database (``postgresql://...``).

Both keep the same tables and columns and the same versioned migrations
(:data:`SCHEMA_VERSION`); a store made by an older version is migrated when it is opened.
"""

from __future__ import annotations

import contextlib
import json
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

from rig.store.ids import StoreError

SCHEMA_VERSION = 2

# Columns of a new ``runs`` row (:meth:`IndexBackend.insert_run`); JSON ones as Python objects.
RUN_INSERT_COLUMNS = (
    "run_id", "campaign_id", "unit_serial", "operator", "rig_id", "calibration",
    "software_version", "plan_name", "plan_version", "status", "started_at", "path",
    "writer_pid", "writer_host", "meta", "design",
)
JSON_COLUMNS = frozenset({"calibration", "metrics", "meta", "summary", "diagnosis", "detail"})


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
        return where_clause(
            (("campaign_id", self.campaign_id, "="), ("status", self.status, "="),
             ("unit_serial", self.serial, "="), ("outcome", self.outcome, "="),
             ("design", self.design, "="), ("started_at", self.since, ">="),
             ("started_at", self.until, "<")),
            placeholder)


def where_clause(conditions: Iterable[tuple[str, Any, str]], placeholder: str
                 ) -> tuple[str, list[Any]]:
    """`` WHERE a = ? AND ...`` (or "") of the ``(column, value, operator)`` whose value is
    not None, and their arguments, ``placeholder`` per argument."""
    parts, args = [], []
    for column, value, op in conditions:
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
    #: Why this process may only read the store (a read-only file system, no permission);
    #: None when it may write.
    read_only: str | None = None

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
    def add_audit(self, audit: Mapping[str, Any]) -> None:
        """One audit record on its own (an operator's action: a fault reset, an override)."""

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


def check_version(version: int, where: str) -> None:
    """StoreError if an index at ``version`` is newer than this software reads."""
    if version > SCHEMA_VERSION:
        raise StoreError(
            f"{where}: index schema version {version} is newer than this software "
            f"reads ({SCHEMA_VERSION}); update backlash-rig"
        )


def to_json(value: Any) -> str | None:
    """Strict JSON text of ``value`` (None stays None); ValueError for NaN/inf/non-JSON."""
    if value is None:
        return None
    try:
        return json.dumps(value, ensure_ascii=False, allow_nan=False, sort_keys=False)
    except (TypeError, ValueError) as e:
        raise ValueError(f"not storable as JSON: {e}") from None


def from_json(value: Any) -> Any:
    """A JSON column's value as Python (SQLite gives text, PostgreSQL jsonb gives objects)."""
    return json.loads(value) if isinstance(value, str | bytes) else value


def json_text_params(row: Mapping[str, Any], columns: Iterable[str]) -> list[Any]:
    """``row``'s values of ``columns``, the JSON columns as JSON text."""
    return [to_json(row[c]) if c in JSON_COLUMNS else row[c] for c in columns]
