"""Durable writes: fsync of a file or a folder by its path (a rename or a new entry in a
folder survives a power loss only once the folder is synced)."""

from __future__ import annotations

import os
from pathlib import Path


def fsync_path(path: Path) -> None:
    """fsync the file or folder at ``path`` (opened read-only, closed again)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
