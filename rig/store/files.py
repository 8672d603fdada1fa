"""File-level helpers of the store: atomic JSON files, the writer lock, cut-off CSV tails,
the finalisation of a run's samples (the CSV stream written during the run becomes Parquet).

The writer lock is an ``fcntl.flock`` on ``<run>/.writer.lock``, held by the process that
records the run for as long as the run is open. The kernel drops it when that process ends,
however it ends (SIGKILL included), so "lock can be taken" means "no live writer": unlike a
recorded pid, it cannot be fooled by pid reuse, and a second open of the file in the same
process conflicts too (flock locks belong to the open file, not to the process).
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq

from rig.core.durable import fsync_path
from rig.runformat import atomic_write_text
from rig.runformat.base import SAMPLES_CSV, SAMPLES_PARQUET
from rig.runformat.csvread import read_samples_csv
from rig.runformat.parquet import write_samples_parquet

LOCK_NAME = ".writer.lock"


def write_json_atomic(path: Path, obj: Any) -> None:
    """Write ``obj`` as indented UTF-8 JSON to ``path``: temp file, fsync, rename, fsync dir.

    Raises ValueError (before touching the file) if ``obj`` is not strict JSON (NaN, inf,
    objects that are not dicts/lists/str/numbers/bools/None).
    """
    atomic_write_text(path, json.dumps(obj, indent=2, ensure_ascii=False, allow_nan=False)
                      + "\n")
    sync_dir(path.parent)


def sync_dir(folder: Path) -> None:
    """fsync a folder so that a rename or a new entry in it survives a power loss."""
    fsync_path(folder)


class WriterLock:
    """An exclusive ``flock`` on a run's lock file, held while the run is being recorded."""

    def __init__(self, fd: int, path: Path) -> None:
        self._fd: int | None = fd
        self.path = path

    @classmethod
    def acquire(cls, folder: Path, *, create: bool) -> WriterLock | None:
        """Take the lock of ``folder`` without waiting; None if a live holder has it.

        ``create`` makes the file (a writer starting a run). Without it (recovery), a missing
        lock file means no writer holds it: the result then holds nothing and releasing it
        only does what ``remove`` asks.
        """
        path = folder / LOCK_NAME
        flags = os.O_RDWR | (os.O_CREAT if create else 0)
        try:
            fd = os.open(path, flags, 0o644)
        except FileNotFoundError:
            if create:
                raise
            return cls(-1, path)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            return None
        if create:
            os.write(fd, f"{os.getpid()}\n".encode())
        return cls(fd, path)

    def release(self, *, remove: bool) -> None:
        """Drop the lock; with ``remove`` delete the lock file first (while still holding it)."""
        if self._fd is None:
            return
        if remove:
            with contextlib.suppress(FileNotFoundError):
                self.path.unlink()
        if self._fd >= 0:
            os.close(self._fd)
        self._fd = None


def cut_incomplete_tail(csv_path: Path) -> str | None:
    """Cut a last line without newline (written in part when the writer was killed).

    Every row the store writes ends in a newline, so such a line is an unfinished row.
    Returns the text cut off (for the record), or None if the file ended cleanly or is absent.
    """
    try:
        raw = csv_path.read_bytes()
    except FileNotFoundError:
        return None
    if not raw or raw.endswith(b"\n"):
        return None
    cut = raw.rfind(b"\n") + 1
    if cut == 0:
        return None
    with open(csv_path, "r+b") as f:
        f.truncate(cut)
        f.flush()
        os.fsync(f.fileno())
    return raw[cut:].decode("utf-8", "replace")


def finalise_samples(folder: Path) -> int:
    """Turn a run's ``samples.csv`` (appended during the run) into ``samples.parquet``.

    Crash-safe at every step: the Parquet file is written under a temporary name, synced and
    renamed into place before the CSV is removed, so the folder always holds the samples
    whole in one of the two files; a folder that already has ``samples.parquet`` (a crash
    after the rename) only loses its leftover CSV. Returns the number of samples. A CSV that
    cannot be read raises :class:`rig.core.errors.RunFormatError` and is left as it is.
    """
    csv_path = folder / SAMPLES_CSV
    parquet_path = folder / SAMPLES_PARQUET
    with contextlib.suppress(FileNotFoundError):
        (folder / f".{SAMPLES_PARQUET}.tmp").unlink()
    if not parquet_path.is_file():
        columns, data, _notes = read_samples_csv(csv_path, allow_truncated_tail=False)
        write_samples_parquet(parquet_path, columns, data)
        sync_dir(folder)
    if csv_path.exists():
        csv_path.unlink()
        sync_dir(folder)
    return int(pq.ParquetFile(parquet_path).metadata.num_rows)
