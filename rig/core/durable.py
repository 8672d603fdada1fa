"""Durable writes: fsync of a file or a folder by its path (a rename or a new entry in a
folder survives a power loss only once the folder is synced); which write errors mean "no
space left"."""

from __future__ import annotations

import errno
import os
from pathlib import Path

DISK_FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EFBIG, errno.EDQUOT})
"""A full disk, a file size limit, a full quota: no more bytes can be written there."""


def is_disk_full(exc: BaseException) -> bool:
    """Is ``exc`` a write refused for want of space (:data:`DISK_FULL_ERRNOS`)?"""
    return isinstance(exc, OSError) and exc.errno in DISK_FULL_ERRNOS


def fsync_path(path: Path) -> None:
    """fsync the file or folder at ``path`` (opened read-only, closed again)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
