"""Reader and writer of the run exchange format ``rig-run/1`` and of campaigns.

The format is specified in ``docs/run-format.md`` ("A run", "A campaign"): a run is a folder
holding ``run.json`` (metadata) and ``samples.csv`` (the time series); a campaign is a folder
of run sub-folders plus an optional ``campaign.json``. A run of the store keeps its samples in
``samples.parquet`` instead (rig/runformat/parquet.py); :func:`read_run` reads either.

Samples are read and written through pyarrow (rig/runformat/csvread.py) and orjson
(rig/runformat/csvwrite.py).

Guarantees:

- Lossless round-trip: unknown CSV columns (numeric or text) and unknown JSON keys at every
  level are kept, in their order. Floats are written as their shortest round-trip decimal
  (Python ``repr``), which reads back bit-exact and so carries at least the 10 significant
  digits the spec asks for whenever a value needs them; in columns the format does not
  define, whole numbers are written as integers (``8``). A missing value (NaN) is an empty
  field.
- Bad input raises :class:`rig.core.errors.RunFormatError` naming the file, the 1-based line and
  the 1-based column. In ``samples.csv`` the column is the 1-based CSV *field index* and the
  message names the column header; in JSON files it is the 1-based *character* column.
  Nothing is silently dropped.

Units follow the column names: ``t_s`` in s, ``torque_Nm`` in N·m, angles in deg, ``_C`` in °C.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import os
import threading
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq

from rig.core.errors import RunFormatError
from rig.core.ids import id_from_text, id_problem
from rig.core.json_files import DuplicateKey, no_duplicate_keys
from rig.runformat.base import (
    CAMPAIGN_FORMAT,
    CAMPAIGN_JSON,
    KNOWN_NUMERIC_COLUMNS,
    OPTIONAL_NUMERIC_COLUMNS,
    REQUIRED_COLUMNS,
    RUN_FORMAT,
    RUN_JSON,
    SAMPLES_CSV,
    SAMPLES_PARQUET,
    Column,
    Samples,
    as_float_column,
    check_column_names,
    decode,
    numeric_bits_equal,
    read_bytes,
)
from rig.runformat.csvread import read_samples_csv
from rig.runformat.csvwrite import csv_line, format_cell, samples_text, writes_integers
from rig.runformat.parquet import read_samples_parquet, write_samples_parquet

__all__ = [
    "CAMPAIGN_FORMAT", "CAMPAIGN_JSON", "KNOWN_NUMERIC_COLUMNS", "OPTIONAL_NUMERIC_COLUMNS",
    "REQUIRED_COLUMNS", "RUN_FORMAT", "RUN_JSON", "SAMPLES_CSV", "SAMPLES_PARQUET", "Campaign",
    "Column", "Run", "SamplesAppender", "is_campaign", "read_campaign", "read_run",
    "read_run_or_campaign", "runs_equal", "sample_columns", "samples_csv_bytes",
    "write_campaign", "write_run", "write_samples_parquet",
]


# --------------------------------------------------------------------------- data classes


@dataclass(eq=False)
class Run:
    """One hysteresis run: metadata, CSV column order and the columns themselves.

    ``data`` maps each column name to a float64 array (NaN = missing value) or, for extra
    columns that are not all numbers, to the list of their texts exactly as read.
    Use :func:`runs_equal` to compare two runs bit-exactly.
    """

    meta: dict[str, Any]
    columns: list[str]
    data: dict[str, Column]
    path: Path | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def run_id(self) -> str:
        return str(self.meta["run_id"])

    @property
    def unit(self) -> dict[str, Any]:
        """Design and inspection data of the unit under test (``{}`` if absent)."""
        return self.meta.get("unit") or {}

    @property
    def test(self) -> dict[str, Any]:
        """Test conditions (rated torque in N·m, locking angle in deg, ...; ``{}`` if absent)."""
        return self.meta.get("test") or {}

    @property
    def sensors(self) -> dict[str, Any]:
        """Sensor data (encoder counts per rev, torque full scale in N·m; ``{}`` if absent)."""
        return self.meta.get("sensors") or {}

    @property
    def t_s(self) -> np.ndarray:
        """Time since the run started, s."""
        return self._numeric("t_s")

    @property
    def torque_Nm(self) -> np.ndarray:
        """Output torque from the torque sensor, N·m, signed."""
        return self._numeric("torque_Nm")

    @property
    def output_angle_deg(self) -> np.ndarray:
        """Output encoder reading (absolute, unwrapped), deg."""
        return self._numeric("output_angle_deg")

    @property
    def input_angle_deg(self) -> np.ndarray | None:
        """Input encoder reading (absolute, unwrapped), deg, or None if not recorded."""
        return self._numeric("input_angle_deg") if "input_angle_deg" in self.data else None

    @property
    def temperature_C(self) -> np.ndarray | None:
        """Housing temperature, °C, or None if not recorded."""
        return self._numeric("temperature_C") if "temperature_C" in self.data else None

    @property
    def n_samples(self) -> int:
        return len(self.data["t_s"])

    def _numeric(self, name: str) -> np.ndarray:
        values = self.data[name]
        if not isinstance(values, np.ndarray):
            raise TypeError(f"run {self.meta.get('run_id')!r}: column {name!r} is not numeric")
        return values

    @classmethod
    def from_arrays(
        cls,
        run_id: str,
        t_s: Any,
        torque_Nm: Any,
        output_angle_deg: Any,
        *,
        input_angle_deg: Any = None,
        temperature_C: Any = None,
        unit: dict[str, Any] | None = None,
        test: dict[str, Any] | None = None,
        sensors: dict[str, Any] | None = None,
        extra_meta: dict[str, Any] | None = None,
        extra_columns: dict[str, Any] | None = None,
    ) -> Run:
        """Build a run from arrays (s, N·m, deg, deg, °C), with meta format/run_id/started_at.

        ``extra_meta`` keys are added after (and may replace) ``started_at``; ``extra_columns``
        maps names to numeric arrays or to lists of str (text columns). Raises ValueError if
        the result would not be a valid run (lengths differ, NaN in a required column,
        time not strictly ascending).
        """
        if not isinstance(run_id, str) or not run_id:
            raise ValueError(f"run_id must be a non-empty str, got {run_id!r}")
        meta: dict[str, Any] = {
            "format": RUN_FORMAT,
            "run_id": run_id,
            "started_at": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        }
        for key, value in (("unit", unit), ("test", test), ("sensors", sensors)):
            if value is not None:
                meta[key] = value
        for key, value in (extra_meta or {}).items():
            if key in ("format", "run_id") and value != meta[key]:
                raise ValueError(f"extra_meta may not change {key!r} (got {value!r})")
            meta[key] = value
        data: dict[str, Column] = {
            "t_s": as_float_column("t_s", t_s),
            "torque_Nm": as_float_column("torque_Nm", torque_Nm),
            "output_angle_deg": as_float_column("output_angle_deg", output_angle_deg),
        }
        if input_angle_deg is not None:
            data["input_angle_deg"] = as_float_column("input_angle_deg", input_angle_deg)
        if temperature_C is not None:
            data["temperature_C"] = as_float_column("temperature_C", temperature_C)
        for name, values in (extra_columns or {}).items():
            if name in data:
                raise ValueError(f"extra column {name!r} duplicates a standard column")
            data[name] = _as_column(name, values)
        run = cls(meta=meta, columns=list(data), data=data)
        _check_run(run)
        return run


@dataclass(eq=False)
class Campaign:
    """Runs of one unit (positions, temperatures, cycles) with the campaign metadata."""

    meta: dict[str, Any]
    runs: list[Run]
    path: Path | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def name(self) -> str:
        return str(self.meta.get("name", ""))


def runs_equal(a: Run, b: Run) -> bool:
    """True if two runs have equal meta, column order and bit-identical columns.

    Any NaN equals any NaN (the format has one missing value, not NaN payloads); -0.0 != 0.0.
    """
    if a.meta != b.meta or a.columns != b.columns or list(a.data) != list(b.data):
        return False
    for name, x in a.data.items():
        y = b.data[name]
        if isinstance(x, np.ndarray) != isinstance(y, np.ndarray):
            return False
        if isinstance(x, np.ndarray):
            if not numeric_bits_equal(x, y):
                return False
        elif list(x) != list(y):
            return False
    return True


# --------------------------------------------------------------------------- public reading


def read_run(path: str | Path, *, allow_truncated_tail: bool = False) -> Run:
    """Read a run from its folder, its ``run.json``, or a bare CSV of samples.

    A run folder holding ``samples.parquet`` (a stored run) is read from it, else from
    ``samples.csv``. A bare CSV (another lab's export, samples only) or Parquet file gets
    the minimal meta ``{"format": "rig-run/1", "run_id": <file stem>}`` (characters an id
    may not hold, :mod:`rig.core.ids`, become ``_``) and a note saying
    so. A ``samples.csv`` or ``samples.parquet`` next to a ``run.json`` is read as that run
    folder.

    ``allow_truncated_tail``: a last line without its newline was cut off mid-write (every row
    this module writes ends in a newline); it is dropped and recorded in ``Run.notes``.
    By default an incomplete last line is an error naming that line.
    """
    p = Path(path)
    if p.is_dir():
        folder = p
        if not (folder / RUN_JSON).exists():
            raise RunFormatError(folder, f"not a run folder: no {RUN_JSON}")
    elif p.name == RUN_JSON or (
        p.name in (SAMPLES_CSV, SAMPLES_PARQUET) and (p.parent / RUN_JSON).is_file()
    ):
        folder = p.parent
    elif p.is_file() and p.suffix == ".parquet":
        return _read_bare_parquet(p)
    elif p.is_file():
        return _read_bare_csv(p, allow_truncated_tail)
    else:
        raise RunFormatError(p, "no such file or folder")
    meta = _read_run_json(folder / RUN_JSON)
    columns, data, notes = _read_samples(folder, allow_truncated_tail)
    return Run(meta=meta, columns=columns, data=data, path=folder, notes=notes)


def is_campaign(path: str | Path) -> bool:
    """True for a ``campaign.json`` or a folder holding one, or whose sub-folders hold a
    ``run.json``. A folder that is itself a run (has ``run.json``, no ``campaign.json``) is not.
    """
    p = Path(path)
    if p.is_file():
        return p.name == CAMPAIGN_JSON
    if not p.is_dir():
        return False
    if (p / CAMPAIGN_JSON).is_file():
        return True
    if (p / RUN_JSON).exists():
        return False
    return any(_is_run_folder(c) for c in _subfolders(p))


def read_campaign(path: str | Path, *, allow_truncated_tail: bool = False) -> Campaign:
    """Read a campaign folder (or its ``campaign.json``).

    Runs come in the order of ``campaign.json`` ``"runs"`` (sub-folder names); without it, in
    sorted sub-folder name order. Run sub-folders not listed are not read but named in
    ``Campaign.notes``; a listed run that does not exist is an error. Without
    ``campaign.json`` the meta is ``{"format": "rig-campaign/1", "name": <folder name>,
    "runs": [...]}``. Two runs with the same ``run_id`` are an error.
    """
    p = Path(path)
    folder = p.parent if p.name == CAMPAIGN_JSON and p.is_file() else p
    if not folder.is_dir():
        raise RunFormatError(folder, "no such campaign folder")
    notes: list[str] = []
    json_path = folder / CAMPAIGN_JSON
    run_folders = sorted(c.name for c in _subfolders(folder) if _is_run_folder(c))
    if json_path.exists():
        text = _read_text(json_path)
        meta = _parse_json_object(json_path, text)
        _check_format_key(json_path, text, meta, CAMPAIGN_FORMAT)
        _check_ids(json_path, text, {"campaign_id": meta.get("campaign_id")})
        if "runs" in meta:
            names = _campaign_run_names(json_path, text, meta["runs"])
        else:
            names = run_folders
            meta["runs"] = list(names)
            notes.append(f"{json_path} has no 'runs': read all run sub-folders, sorted")
        for name in names:
            if not _is_run_folder(folder / name):
                raise RunFormatError(
                    json_path,
                    f"run {name!r} listed in 'runs' is not a run folder in {folder}"
                    f" (no {name}/{RUN_JSON})",
                    *_locate_string_after(text, name, "runs"),
                )
        unlisted = [n for n in run_folders if n not in names]
        if unlisted:
            notes.append(f"run folders not listed in {json_path} were not read: {unlisted}")
    else:
        names = run_folders
        meta = {"format": CAMPAIGN_FORMAT, "name": folder.name, "runs": list(names)}
        notes.append(f"no {CAMPAIGN_JSON} in {folder}: runs are its sub-folders, sorted")
    if not names:
        raise RunFormatError(folder, "campaign holds no runs (no sub-folder with run.json)")
    runs = [read_run(folder / n, allow_truncated_tail=allow_truncated_tail) for n in names]
    seen: dict[str, str] = {}
    for name, run in zip(names, runs, strict=True):
        if run.run_id in seen:
            raise RunFormatError(
                folder / name / RUN_JSON,
                f"run_id {run.run_id!r} is also the run_id of {seen[run.run_id]!r}",
            )
        seen[run.run_id] = name
    return Campaign(meta=meta, runs=runs, path=folder, notes=notes)


def read_run_or_campaign(path: str | Path, *, allow_truncated_tail: bool = False) -> Campaign:
    """Read a campaign, or a single run (folder, run.json or bare CSV) as a one-run campaign."""
    if is_campaign(path):
        return read_campaign(path, allow_truncated_tail=allow_truncated_tail)
    run = read_run(path, allow_truncated_tail=allow_truncated_tail)
    name = run.path.name if run.path is not None and run.path.is_dir() else run.run_id
    meta = {"format": CAMPAIGN_FORMAT, "name": run.run_id, "runs": [name]}
    return Campaign(meta=meta, runs=[run], path=run.path, notes=[f"single run {path}"])


# --------------------------------------------------------------------------- public writing


def write_run(run: Run, folder: str | Path) -> Path:
    """Write ``run`` as ``folder/run.json`` + ``folder/samples.csv`` (folder created).

    Existing files of those names are replaced; each is written to a temporary name, synced
    and renamed into place. Raises ValueError if the run is not valid (it would not read
    back). Returns the folder.
    """
    _check_run(run)
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / SAMPLES_CSV, samples_text(run.columns, run.data))
    atomic_write_text(out / RUN_JSON, json.dumps(run.meta, indent=2, ensure_ascii=False) + "\n")
    return out


def write_campaign(campaign: Campaign, folder: str | Path) -> Path:
    """Write each run into a sub-folder of ``folder`` and ``campaign.json`` listing them.

    Sub-folder names are ``meta["runs"]`` when it lists one name per run (as
    :func:`read_campaign` leaves it), otherwise the run ids. Other meta keys are kept;
    ``name`` defaults to the folder name. Returns the folder.
    """
    meta = dict(campaign.meta)
    if meta.setdefault("format", CAMPAIGN_FORMAT) != CAMPAIGN_FORMAT:
        raise ValueError(f"campaign format must be {CAMPAIGN_FORMAT!r}, got {meta['format']!r}")
    listed = meta.get("runs")
    if (
        isinstance(listed, list)
        and len(listed) == len(campaign.runs)
        and all(isinstance(n, str) for n in listed)
    ):
        names = list(listed)
    else:
        names = [r.run_id for r in campaign.runs]
    for name in names:
        _check_folder_name(name)
    if len(set(names)) != len(names):
        raise ValueError(f"run sub-folder names are not unique: {names}")
    out = Path(folder)
    meta.setdefault("name", out.name)
    meta["runs"] = names
    out.mkdir(parents=True, exist_ok=True)
    for name, run in zip(names, campaign.runs, strict=True):
        write_run(run, out / name)
    atomic_write_text(out / CAMPAIGN_JSON, json.dumps(meta, indent=2, ensure_ascii=False) + "\n")
    return out


def samples_csv_bytes(run: Run) -> bytes:
    """The run's samples as the rig-run/1 ``samples.csv`` :func:`write_run` writes (UTF-8)."""
    _check_run(run)
    return samples_text(run.columns, run.data).encode("utf-8")


def sample_columns(folder: str | Path) -> list[str]:
    """The sample column names of a run folder: the Parquet schema of ``samples.parquet``
    (a stored run), else the header of ``samples.csv``; [] if neither can be read."""
    p = Path(folder)
    if (p / SAMPLES_PARQUET).is_file():
        try:
            return list(pq.read_schema(p / SAMPLES_PARQUET).names)
        except (OSError, ValueError):
            return []
    try:
        with open(p / SAMPLES_CSV, encoding="utf-8-sig", newline="") as f:
            return [c.strip() for c in next(csv.reader(f), [])]
    except (OSError, ValueError):
        return []


_WRITE_CHUNK = 8192
"""Buffered rows are written once they reach this many bytes (and at every flush)."""


class SamplesAppender:
    """Append sample rows to a ``samples.csv`` as they are measured.

    Writes the header to a new (or empty) file; an existing file must carry exactly
    ``columns`` as header. Rows are flushed to disk (``flush`` + ``os.fsync``) at least every
    ``flush_interval_s`` seconds by a background thread, so a SIGKILL loses at most that much.
    Numbers are written as :func:`write_run` writes them (shortest round-trip, None/NaN empty,
    whole numbers as integers in the columns the format does not define).
    ``t_s`` must be strictly ascending and the required columns finite numbers (ValueError).

    A file whose last line was cut off by a kill raises RunFormatError unless
    ``repair_truncated_tail`` is true, which cuts that incomplete line off before appending.
    """

    def __init__(
        self,
        csv_path: str | Path,
        columns: list[str],
        *,
        flush_interval_s: float = 0.5,
        repair_truncated_tail: bool = False,
    ) -> None:
        self.path = Path(csv_path)
        self.columns = list(columns)
        if not flush_interval_s > 0:
            raise ValueError(f"flush_interval_s must be > 0 s, got {flush_interval_s!r}")
        _check_header(self.path, self.columns)
        self._required = [self.columns.index(c) for c in REQUIRED_COLUMNS]
        self._t_index = self.columns.index("t_s")
        self._integers = [writes_integers(c) for c in self.columns]
        self._last_t = -math.inf
        self._lock = threading.Lock()
        self._dirty = False
        self._closed = False
        header = csv_line(self.columns)
        existing = self.path.exists() and self.path.stat().st_size > 0
        self._lines = 0
        if existing:
            self._last_t = self._check_existing(header, repair_truncated_tail)
        try:
            self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
        except OSError as e:
            raise RunFormatError(self.path, f"cannot open to append: {e.strerror or e}") from None
        self._size = os.fstat(self._fd).st_size
        self._pending: list[bytes] = []
        self._pending_bytes = 0
        self.error: OSError | None = None
        """The write that failed (a full disk, a file size limit); the file then ends with
        the last whole line written, and every later append raises it again."""
        if not existing:
            self._pending.append(header.encode())
            try:
                self._sync()
            except OSError:
                os.close(self._fd)
                raise
        self._interval = float(flush_interval_s)
        self._stop = threading.Event()
        self._thread = threading.Thread(
            target=self._flush_loop, name=f"flush {self.path.name}", daemon=True
        )
        self._thread.start()

    @property
    def rows_written(self) -> int:
        """Rows whole on disk (or handed to it, before the next fsync), header not counted."""
        return max(0, self._lines - 1)

    def _check_existing(self, header: str, repair: bool) -> float:
        """Check an existing file's header and tail; return its last t_s (-inf if no rows)."""
        raw = read_bytes(self.path)
        if not raw.endswith(b"\n"):
            cut = raw.rfind(b"\n") + 1
            if cut == 0:
                raise RunFormatError(self.path, "the header line is incomplete (no newline)", 1)
            if not repair:
                raise RunFormatError(
                    self.path,
                    "last line has no newline (cut off mid-write?); "
                    "open with repair_truncated_tail=True to cut it off before appending",
                    line=raw.count(b"\n") + 1,
                )
            with open(self.path, "r+b") as f:
                f.truncate(cut)
            raw = raw[:cut]
        first = raw.split(b"\n", 1)[0].decode("utf-8", "replace").removeprefix("\ufeff")
        if first.rstrip("\r") + "\n" != header:
            found = next(csv.reader([first.rstrip("\r")]), [])
            col = next(
                (i for i, (a, b) in enumerate(zip(found, self.columns, strict=False), 1) if a != b),
                min(len(found), len(self.columns)) + 1,
            )
            raise RunFormatError(
                self.path,
                f"existing header {found} does not match the columns to append {self.columns}",
                line=1,
                column=col,
            )
        self._lines = raw.count(b"\n")
        lines = raw.rstrip(b"\r\n").split(b"\n")
        if len(lines) < 2:
            return -math.inf
        last = next(csv.reader([lines[-1].decode("utf-8", "replace").rstrip("\r")]))
        try:
            return float(last[self._t_index])
        except (ValueError, IndexError):
            raise RunFormatError(
                self.path, "last row has no readable t_s", line=len(lines),
                column=self._t_index + 1,
            ) from None

    def append(self, row: Sequence[float | str | None]) -> None:
        """Append one row (values in ``columns`` order; None or NaN = missing value)."""
        if self._closed:
            raise ValueError(f"{self.path}: appender is closed")
        if len(row) != len(self.columns):
            raise ValueError(
                f"{self.path}: row has {len(row)} values, expected {len(self.columns)} "
                f"({self.columns})"
            )
        for i in self._required:
            v = row[i]
            if isinstance(v, str | bool) or v is None or not math.isfinite(v):
                raise ValueError(
                    f"{self.path}: {self.columns[i]} must be a finite number, got {v!r}"
                )
        t = float(row[self._t_index])  # type: ignore[arg-type]
        if not t > self._last_t:
            raise ValueError(
                f"{self.path}: t_s must be strictly ascending, got {t!r} after {self._last_t!r}"
            )
        line = (",".join(map(format_cell, row, self._integers)) + "\n").encode()
        with self._lock:
            if self._closed:
                raise ValueError(f"{self.path}: appender is closed")
            if self.error is not None:
                raise self.error
            self._pending.append(line)
            self._pending_bytes += len(line)
            self._last_t = t
            self._dirty = True
            if self._pending_bytes >= _WRITE_CHUNK:
                self._write_pending()

    def flush(self) -> None:
        """Push buffered rows to the disk (write + ``os.fsync``); a failed write raises
        its OSError (:attr:`error`)."""
        with self._lock:
            if not self._closed:
                self._sync()

    def close(self) -> None:
        """Flush and close; idempotent. A write that fails here is kept in :attr:`error`
        (not raised): the rows written before it stay whole."""
        if self._closed:
            return
        self._stop.set()
        self._thread.join()
        with self._lock:
            with contextlib.suppress(OSError):
                self._sync()
            os.close(self._fd)
            self._closed = True

    def __enter__(self) -> SamplesAppender:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _write_pending(self) -> None:
        """Write the buffered lines. A write that fails (ENOSPC, EFBIG, ...) cuts the file
        back to its last whole line, keeps the error in :attr:`error` and raises it."""
        if self.error is not None:
            raise self.error
        data = b"".join(self._pending)
        self._pending.clear()
        self._pending_bytes = 0
        done = 0
        try:
            while done < len(data):
                done += os.write(self._fd, data[done:])
        except OSError as e:
            keep = data.rfind(b"\n", 0, done) + 1
            with contextlib.suppress(OSError):
                os.ftruncate(self._fd, self._size + keep)
                os.fsync(self._fd)
            self._size += keep
            self._lines += data.count(b"\n", 0, keep)
            self.error = e
            raise
        self._size += len(data)
        self._lines += data.count(b"\n")

    def _sync(self) -> None:
        self._write_pending()
        os.fsync(self._fd)
        self._dirty = False

    def _flush_loop(self) -> None:
        while not self._stop.wait(self._interval):
            with self._lock:
                if self._dirty and not self._closed and self.error is None:
                    with contextlib.suppress(OSError):  # kept in self.error: append raises it
                        self._sync()


# --------------------------------------------------------------------------- validation


def _as_column(name: str, values: Any) -> Column:
    if isinstance(values, list | tuple) and values and all(isinstance(v, str) for v in values):
        return list(values)
    return as_float_column(name, values)


def _check_run(run: Run) -> None:
    """Raise ValueError unless ``run`` would be written and read back as it is."""
    rid = run.meta.get("run_id") if isinstance(run.meta, dict) else None
    who = f"run {rid!r}"
    if not isinstance(run.meta, dict) or run.meta.get("format") != RUN_FORMAT:
        raise ValueError(f"{who}: meta['format'] must be {RUN_FORMAT!r}")
    if not isinstance(rid, str) or not rid:
        raise ValueError(f"{who}: meta['run_id'] must be a non-empty str")
    if list(run.columns) != list(run.data):
        raise ValueError(f"{who}: columns {run.columns} differ from data keys {list(run.data)}")
    check_column_names(run.columns, lambda msg, col: ValueError(f"{who}: {msg}"))
    n = None
    for name, values in run.data.items():
        if isinstance(values, np.ndarray):
            if values.ndim != 1 or values.dtype != np.float64:
                raise ValueError(f"{who}: column {name!r} must be 1-D float64")
        elif not all(isinstance(v, str) for v in values):
            raise ValueError(f"{who}: text column {name!r} must hold only str")
        elif name in KNOWN_NUMERIC_COLUMNS:
            raise ValueError(f"{who}: column {name!r} must be numeric")
        if n is not None and len(values) != n:
            raise ValueError(f"{who}: column {name!r} has {len(values)} values, expected {n}")
        n = len(values)
    for name in REQUIRED_COLUMNS:
        bad = np.flatnonzero(~np.isfinite(run.data[name]))
        if bad.size:
            raise ValueError(f"{who}: {name}[{bad[0]}] is {float(run.data[name][bad[0]])!r}")
    t = run.data["t_s"]
    bad = np.flatnonzero(~(np.diff(t) > 0))
    if bad.size:
        i = bad[0] + 1
        raise ValueError(
            f"{who}: t_s not strictly ascending: t_s[{i}] = {float(t[i])!r} "
            f"after {float(t[i - 1])!r}"
        )


def _check_header(path: Path, columns: list[str]) -> None:
    def error(msg: str, col: int | None) -> ValueError:
        return ValueError(f"{path}: {msg}")

    check_column_names(columns, error)


def _check_folder_name(name: str) -> None:
    if not name or name in (".", "..") or "/" in name or "\\" in name:
        raise ValueError(f"{name!r} cannot be a run sub-folder name")


# --------------------------------------------------------------------------- file helpers


def _read_text(path: Path) -> str:
    return decode(path, read_bytes(path))


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path``: a temp file beside it, fsync, rename (the temp
    file removed if that fails)."""
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8", newline="") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:  # a full disk, a size limit: no temporary file left behind
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def _subfolders(folder: Path) -> list[Path]:
    try:
        return [c for c in folder.iterdir() if c.is_dir()]
    except OSError as e:
        raise RunFormatError(folder, f"cannot list: {e.strerror or e}") from None


def _is_run_folder(p: Path) -> bool:
    return (p / RUN_JSON).is_file()


# --------------------------------------------------------------------------- JSON


def _line_col(text: str, pos: int) -> tuple[int, int]:
    """1-based line and character column of ``pos`` in ``text``."""
    line = text.count("\n", 0, pos) + 1
    return line, pos - (text.rfind("\n", 0, pos) + 1) + 1


def _locate_key(text: str, key: str) -> tuple[int, int] | None:
    """Line/column of the value of top-level ``key`` in valid JSON ``text`` (None if absent)."""
    pos = _key_value_pos(text, key)
    return None if pos is None else _line_col(text, pos)


def _key_value_pos(text: str, key: str) -> int | None:
    """Index of the value of top-level ``key`` in valid JSON ``text`` (None if absent)."""
    depth, i, n = 0, 0, len(text)
    while i < n:
        c = text[i]
        if c == '"':
            s, end = json.decoder.scanstring(text, i + 1)
            rest = end
            while rest < n and text[rest] in " \t\r\n":
                rest += 1
            if depth == 1 and s == key and rest < n and text[rest] == ":":
                rest += 1
                while rest < n and text[rest] in " \t\r\n":
                    rest += 1
                return rest
            i = end
            continue
        if c in "{[":
            depth += 1
        elif c in "}]":
            depth -= 1
        i += 1
    return None


def _locate_string_after(text: str, value: str, key: str) -> tuple[int | None, int | None]:
    """Best-effort line/column of the JSON string ``value`` after top-level ``key``."""
    start = _key_value_pos(text, key) or 0
    pos = text.find(json.dumps(value, ensure_ascii=False), start)
    return _line_col(text, pos) if pos >= 0 else (None, None)


def _parse_json_object(path: Path, text: str) -> dict[str, Any]:
    """Parse a JSON object; syntax errors carry the decoder's line and character column."""
    try:
        obj = json.loads(text, object_pairs_hook=no_duplicate_keys)
    except json.JSONDecodeError as e:
        raise RunFormatError(path, f"invalid JSON: {e.msg}", e.lineno, e.colno) from None
    except RecursionError:
        raise RunFormatError(path, "JSON nested too deeply (more levels than any run has)") \
            from None
    except DuplicateKey as e:
        line, col = _locate_duplicate(text, e.key)
        message = f"key {e.key!r} appears twice in one object"
        raise RunFormatError(path, message, line, col) from None
    if not isinstance(obj, dict):
        raise RunFormatError(path, f"expected a JSON object, got {type(obj).__name__}", 1, 1)
    return obj


def _locate_duplicate(text: str, key: str) -> tuple[int | None, int | None]:
    """Line/column of the second occurrence of ``"key":`` (best effort)."""
    needle = json.dumps(key, ensure_ascii=False)
    first = text.find(needle)
    second = text.find(needle, first + 1) if first >= 0 else -1
    return _line_col(text, second) if second >= 0 else (None, None)


def _check_format_key(path: Path, text: str, meta: dict[str, Any], expected: str) -> None:
    if "format" not in meta:
        line, col = _line_col(text, text.find("{"))
        raise RunFormatError(path, f"no 'format' key (expected {expected!r})", line, col)
    if meta["format"] != expected:
        line, col = _locate_key(text, "format") or (None, None)
        raise RunFormatError(
            path, f"'format' is {meta['format']!r}, expected {expected!r}", line, col
        )


def _read_run_json(path: Path) -> dict[str, Any]:
    text = _read_text(path)
    meta = _parse_json_object(path, text)
    _check_format_key(path, text, meta, RUN_FORMAT)
    rid = meta.get("run_id")
    if "run_id" not in meta:
        line, col = _line_col(text, text.find("{"))
        raise RunFormatError(path, "no 'run_id' key in the top-level object", line, col)
    if not isinstance(rid, str) or not rid:
        line, col = _locate_key(text, "run_id") or (None, None)
        raise RunFormatError(path, f"'run_id' must be a non-empty string, got {rid!r}", line, col)
    _check_ids(path, text, meta)
    for key in ("unit", "test", "sensors"):
        if key in meta and not isinstance(meta[key], dict):
            line, col = _locate_key(text, key) or (None, None)
            raise RunFormatError(
                path, f"{key!r} must be an object, got {type(meta[key]).__name__}", line, col
            )
    from rig.runformat.meta_check import meta_problems

    problems = meta_problems(meta)
    if problems:
        key = problems[0].split(":", 1)[0].split(".")[-1]
        line, col = _locate_key(text, key) or (None, None)
        raise RunFormatError(path, "; ".join(problems), line, col)
    return meta


def _check_ids(path: Path, text: str, meta: dict[str, Any]) -> None:
    """``run_id`` and ``campaign_id`` (when present) are names: the rule of :mod:`rig.core.ids`
    (an id becomes a folder or file name when the run is exported or stored)."""
    for key, kind in (("run_id", "run"), ("campaign_id", "campaign")):
        if meta.get(key) is None:
            continue
        problem = id_problem(meta[key], kind)
        if problem is not None:
            line, col = _locate_key(text, key) or (None, None)
            raise RunFormatError(path, f"{key!r}: {problem}", line, col)


def _campaign_run_names(path: Path, text: str, runs: Any) -> list[str]:
    line, col = _locate_key(text, "runs") or (None, None)
    if not isinstance(runs, list) or not all(isinstance(r, str) for r in runs):
        raise RunFormatError(path, "'runs' must be a list of run sub-folder names", line, col)
    for name in runs:
        try:
            _check_folder_name(name)
        except ValueError as e:
            where = _locate_string_after(text, name, "runs")
            raise RunFormatError(path, f"in 'runs': {e}", *where) from None
    if len(set(runs)) != len(runs):
        raise RunFormatError(path, f"'runs' lists a folder twice: {runs}", line, col)
    return list(runs)


# --------------------------------------------------------------------------- samples files


def _read_bare_csv(path: Path, allow_truncated_tail: bool) -> Run:
    columns, data, notes = read_samples_csv(path, allow_truncated_tail)
    meta = {"format": RUN_FORMAT, "run_id": id_from_text(path.stem, "samples")}
    notes.insert(0, f"read from a bare CSV file {path} (samples only): no run.json, minimal meta")
    return Run(meta=meta, columns=columns, data=data, path=path, notes=notes)


def _read_bare_parquet(path: Path) -> Run:
    columns, data, notes = read_samples_parquet(path)
    meta = {"format": RUN_FORMAT, "run_id": id_from_text(path.stem, "samples")}
    notes.insert(0, f"read from a bare Parquet file {path} (samples only): no run.json, "
                 "minimal meta")
    return Run(meta=meta, columns=columns, data=data, path=path, notes=notes)


def _read_samples(folder: Path, allow_truncated_tail: bool) -> Samples:
    """A run folder's samples: ``samples.parquet`` (a stored run) if present, else
    ``samples.csv``."""
    parquet = folder / SAMPLES_PARQUET
    if parquet.is_file():
        return read_samples_parquet(parquet)
    csv_path = folder / SAMPLES_CSV
    try:
        return read_samples_csv(csv_path, allow_truncated_tail)
    except (RunFormatError, OSError):  # OSError: pyarrow found the CSV gone while opening it
        if csv_path.exists() or not parquet.is_file():
            raise
    return read_samples_parquet(parquet)  # the store finalised the run meanwhile
