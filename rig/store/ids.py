"""Run and campaign ids of the measurement store: generation and strict validation.

An id is also a folder name inside the store, so it is held to the one rule of
:mod:`rig.core.ids`: ASCII letters, digits, ``_`` and ``-``, starting with a letter or digit, at
most 100 characters. No dots, slashes or backslashes can appear, so no id can climb out of
the store (``..``) or name a hidden file.
"""

from __future__ import annotations

import re
from datetime import UTC, datetime

from rig.core.errors import RigError
from rig.core.ids import ID_PATTERN, id_problem  # noqa: F401  (ID_PATTERN: re-exported)

_LABEL_MAX = 40


class StoreError(RigError):
    """The store cannot do what was asked (no store, unknown id, bad state)."""


class StoreUnavailable(StoreError):
    """The store's database cannot be reached within the retry window (a server restart, a
    network outage). The message is one line."""


class StoreDiskFull(StoreError):
    """The store's disk (or a file size limit, a quota) refused a write: one line saying
    what was kept."""


class StoreReadOnly(StoreError):
    """A write asked of a store this process may only read (a read-only file system, no
    write permission): one line naming the store."""


class InvalidIdError(StoreError, ValueError):
    """A run or campaign id given by a caller does not match :data:`ID_PATTERN`."""


class UnknownIdError(StoreError, LookupError):
    """A well-formed run or campaign id that the store does not hold."""


def validate_id(value: object, kind: str = "run") -> str:
    """Return ``value`` if it is a valid id, else raise :class:`InvalidIdError` naming it."""
    problem = id_problem(value, kind)  # the one rule of rig/core/ids.py
    if problem is not None:
        raise InvalidIdError(problem)
    return value  # type: ignore[return-value]


def safe_label(text: object, fallback: str) -> str:
    """A filesystem-safe label from free text (a unit serial, a campaign name).

    Characters outside ``[A-Za-z0-9_-]`` become ``_``; runs of ``_`` collapse; the result is
    cut to 40 characters. Empty or unusable text gives ``fallback``.
    """
    raw = str(text) if text is not None else ""
    label = re.sub(r"[^A-Za-z0-9_-]+", "_", raw).strip("_-")[:_LABEL_MAX].strip("_-")
    return label if label else fallback


def id_candidates(label: str, now: datetime | None = None):
    """Yield ``<label>-<UTC yyyymmddThhmmssZ>-<n>`` for n = 1, 2, ... (the caller claims one)."""
    stamp = (now or datetime.now(UTC)).astimezone(UTC).strftime("%Y%m%dT%H%M%SZ")
    n = 1
    while True:
        yield validate_id(f"{label}-{stamp}-{n}")
        n += 1


def utc_now_iso() -> str:
    """The current UTC time as ISO 8601 with seconds and ``Z`` (the rig-run/1 form)."""
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
