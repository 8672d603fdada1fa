"""Reading a ``samples.csv`` of rig-run/1 (docs/run-format.md) with pyarrow.

The fast path hands the file to ``pyarrow.csv`` with explicit float64 types. Whatever pyarrow
refuses, and any value the format forbids (a missing or non-finite value in a required column,
time not strictly ascending), is located by a slow pure-Python pass over the text that names
the file, the 1-based line and the 1-based CSV field index (the message names the column
header). That pass only runs when something is wrong (or the file is unusual: quoted header,
no newline at the end, blank lines at the end).

A number is what both pyarrow and the format accept: ASCII digits with an optional sign,
point and exponent, or ``nan``/``inf``/``infinity`` in any case; spaces or tabs around it
are allowed. ``1_000`` or non-ASCII digits are not numbers (Python's ``float`` takes them).
An empty (or blank) field is a missing value (NaN). There are no comment lines: a line
starting with ``#`` is a row like any other and is refused where its text is not a number.
"""

from __future__ import annotations

import codecs
import csv
import io
import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv

from rig.core.errors import RunFormatError
from rig.runformat.arrow_arrays import float64_from_arrow
from rig.runformat.base import (
    KNOWN_NUMERIC_COLUMNS,
    REQUIRED_COLUMNS,
    Column,
    Samples,
    check_column_names,
    decode,
    read_bytes,
)

NUMBER = re.compile(
    r"[ \t]*[+-]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|inf|infinity|nan)[ \t]*",
    re.IGNORECASE,
)
BLANK = re.compile(r"[ \t]*")
_PROBE_BYTES = 1 << 16
_CONVERSION = re.compile(r"In CSV column #(\d+): .*conversion error to double")


def read_samples_csv(path: Path, allow_truncated_tail: bool) -> Samples:
    """Read a samples CSV into (columns, data, notes); errors name file, line, field index.

    ``allow_truncated_tail``: a last line without newline is dropped (noted) instead of read.
    """
    fast = _read_fast(path, allow_truncated_tail)
    if fast is not None:
        return fast
    return read_located(path, allow_truncated_tail)


# --------------------------------------------------------------------------- fast path


def _read_fast(path: Path, allow_truncated_tail: bool) -> Samples | None:
    """Read with pyarrow; None when the slow pass must decide (an error or an unusual file)."""
    try:
        with open(path, "rb") as f:
            size = f.seek(0, io.SEEK_END)
            f.seek(0)
            head = f.read(_PROBE_BYTES)
            f.seek(max(0, size - _PROBE_BYTES))
            tail = f.read()
    except OSError:
        return None  # the slow pass words the error
    if head.startswith(codecs.BOM_UTF8):
        head = head[len(codecs.BOM_UTF8) :]
    end = head.find(b"\n")
    if end < 0 or b'"' in head[:end]:
        return None
    if not tail.endswith(b"\n") or tail.rstrip(b"\r\n").count(b"\n") != tail.count(b"\n") - 1:
        return _read_fast_in_memory(path, allow_truncated_tail)
    try:
        header = head[:end].decode("utf-8").rstrip("\r").split(",")
    except UnicodeDecodeError:
        return None
    return _parse(path, header, lambda: pa.OSFile(str(path)), size, [])


def _read_fast_in_memory(path: Path, allow_truncated_tail: bool) -> Samples | None:
    """The fast path for a file whose end is unusual (cut off, no newline, blank lines)."""
    raw = read_bytes(path)
    notes: list[str] = []
    start = len(codecs.BOM_UTF8) if raw.startswith(codecs.BOM_UTF8) else 0
    stop = len(raw)
    no_newline = bool(raw) and not raw.endswith(b"\n") and b"\n" in raw
    last_line = raw.count(b"\n") + 1
    if no_newline and allow_truncated_tail:
        stop = raw.rfind(b"\n") + 1
        notes.append(
            f"dropped the incomplete last line {last_line} of {path} (no newline, "
            f"cut off mid-write): {raw[stop:].decode('utf-8', 'replace')[:80]!r}"
        )
        no_newline = False
    if no_newline:
        notes.append(f"the last line {last_line} of {path} has no newline at the end")
    core = raw[start:stop].rstrip(b"\r\n")
    blank_at_end = raw[start + len(core) : stop].count(b"\n") - 1
    if blank_at_end > 0:
        notes.append(f"ignored {blank_at_end} blank line(s) at the end of {path}")
    end = core.find(b"\n")
    head = core if end < 0 else core[:end]
    if not core.strip() or b'"' in head:
        return None
    try:
        header = head.decode("utf-8").rstrip("\r").split(",")
    except UnicodeDecodeError:
        return None
    body = pa.py_buffer(raw).slice(start, min(len(core) + 1, len(raw) - start))
    return _parse(path, header, lambda: pa.BufferReader(body), body.size, notes)


def _parse(path: Path, header: list[str], source: Callable[[], Any], size: int,
           notes: list[str]) -> Samples | None:
    names = [h.strip() for h in header]
    if names != header:
        notes.append(f"stripped spaces around column names in the header of {path}")
    if len(names) == 1 or any(not n for n in names) or len(set(names)) != len(names):
        return None  # the slow pass words the header error
    check_column_names(names, lambda msg, col: RunFormatError(path, msg, line=1, column=col))
    # every row takes at least one byte per column (its commas and its newline)
    columns = _arrow_columns(source, names, size // len(names) + 1)
    if columns is None:
        return None
    data: dict[str, Column] = {}
    for name, values in zip(names, columns, strict=True):
        if isinstance(values, list):
            numbers = _numbers_or_none(values)
            data[name] = values if numbers is None else numbers
        else:
            data[name] = values
    if not _values_ok(data):
        return None
    return names, data, notes


def _arrow_columns(source: Callable[[], Any], names: list[str], max_rows: int) -> (
        list[Column] | None):
    """Parse with float64 for every column, batch by batch, each batch copied at once into
    arrays sized for ``max_rows`` (an upper bound: only the pages written become memory), so
    that Arrow data never piles up and peak memory stays near the data's size.

    Returns the columns: float64 arrays, or lists of str for an extra column that pyarrow
    cannot read as numbers (read again as text). None if a standard column or the rows
    themselves are refused.
    """
    keys = [f"f{j}" for j in range(len(names))]
    text: set[int] = set()
    while True:
        types = {k: pa.string() if j in text else pa.float64() for j, k in enumerate(keys)}
        out: list[Column] = [[] if j in text else np.empty(max_rows) for j in range(len(names))]
        n = 0
        try:
            with source() as stream:
                reader = pacsv.open_csv(
                    stream,
                    read_options=pacsv.ReadOptions(column_names=keys, skip_rows=1),
                    parse_options=pacsv.ParseOptions(newlines_in_values=True,
                                                     ignore_empty_lines=False),
                    convert_options=pacsv.ConvertOptions(
                        column_types=types, null_values=[""], strings_can_be_null=False),
                )
                for batch in reader:
                    m = batch.num_rows
                    if n + m > max_rows:
                        return None  # cannot happen (max_rows bounds the lines); be safe
                    for j, col in enumerate(batch.columns):
                        target = out[j]
                        if isinstance(target, list):
                            target.extend(col.to_pylist())
                        else:
                            target[n : n + m] = float64_from_arrow(col)
                    n += m
                    del batch
            return [c if isinstance(c, list) else c[:n] for c in out]
        except (pa.ArrowInvalid, UnicodeDecodeError) as e:
            match = _CONVERSION.search(str(e))
            if match is None:
                return None
            j = int(match.group(1))
            if j in text or j >= len(names) or names[j] in KNOWN_NUMERIC_COLUMNS:
                return None
            text.add(j)


def _numbers_or_none(texts: list[str]) -> np.ndarray | None:
    """The texts as float64 if every one is a number or blank (the format's rule), else None."""
    if not all(NUMBER.fullmatch(t) or BLANK.fullmatch(t) for t in texts):
        return None
    return np.array([float(t) if NUMBER.fullmatch(t) else math.nan for t in texts],
                    dtype=np.float64)


def _values_ok(data: dict[str, Column]) -> bool:
    for name in REQUIRED_COLUMNS:
        if not np.isfinite(data[name]).all():
            return False
    return bool((np.diff(data["t_s"]) > 0).all())


# --------------------------------------------------------------------------- slow pass


class _Table:
    """The header of a samples file; words errors about its fields (line, field index)."""

    def __init__(self, path: Path, header: list[str], no_newline_at_end: bool) -> None:
        self.path = path
        self.header = header
        self.no_newline_at_end = no_newline_at_end

    def error(self, row_line: int, col: int | None, message: str, last: bool) -> RunFormatError:
        if col is not None and 1 <= col <= len(self.header):
            message = f"column {self.header[col - 1]!r}: {message}"
        if last and self.no_newline_at_end:
            message += (
                " (the last line has no newline: cut off mid-write? "
                "read_run(..., allow_truncated_tail=True) drops it)"
            )
        return RunFormatError(self.path, message, line=row_line, column=col)


def read_located(path: Path, allow_truncated_tail: bool) -> Samples:
    """The slow pass: the csv module over the decoded text, every field checked in file order.

    Raises the RunFormatError of the first problem (file, line, field index); returns the
    samples when there is none (a file pyarrow refused but the format accepts).
    """
    raw = read_bytes(path)
    notes: list[str] = []
    if raw.startswith(codecs.BOM_UTF8):
        raw = raw[len(codecs.BOM_UTF8) :]
    no_newline = bool(raw) and not raw.endswith(b"\n") and b"\n" in raw
    if no_newline and allow_truncated_tail:
        cut = raw.rfind(b"\n") + 1
        tail = raw[cut:].decode("utf-8", "replace")
        line = raw.count(b"\n") + 1
        notes.append(
            f"dropped the incomplete last line {line} of {path} (no newline, cut off "
            f"mid-write): {tail[:80]!r}"
        )
        raw = raw[:cut]
        no_newline = False
    text = decode(path, raw, csv_fields=True)
    if no_newline:
        notes.append(f"the last line {text.count(chr(10)) + 1} of {path} has no newline at the end")
    core = text.rstrip("\r\n")
    blank_at_end = text[len(core) :].count("\n") - 1
    if blank_at_end > 0:
        notes.append(f"ignored {blank_at_end} blank line(s) at the end of {path}")
    if not core.strip():
        raise RunFormatError(path, "empty file: no header line", line=1)
    header, rows, row_lines = _rows_by_csv(core)
    stripped = [h.strip() for h in header]
    if stripped != header:
        notes.append(f"stripped spaces around column names in the header of {path}")
    table = _Table(path, stripped, no_newline)

    def header_error(msg: str, col: int | None) -> RunFormatError:
        return RunFormatError(path, msg, line=1, column=col)

    if len(stripped) == 1:
        for sep, name in ((";", "semicolon"), ("\t", "tab")):
            if sep in stripped[0]:
                raise header_error(f"header is {name}-separated; rig-run/1 uses commas", 1)
    check_column_names(stripped, header_error)
    columns = _columns_by_rows(table, rows, row_lines)
    line_of = row_lines.__getitem__
    data = _columns_from_texts(table, columns, line_of)
    _check_values(table, data, line_of, lambda r, col: columns[col - 1][r])
    return stripped, data, notes


def _rows_by_csv(core: str) -> tuple[list[str], list[list[str]], list[int]]:
    """Split CSV with the csv module; return header, rows and each row's first line."""
    reader = csv.reader(io.StringIO(core, newline=""))
    header = next(reader)
    rows: list[list[str]] = []
    lines: list[int] = []
    start = reader.line_num + 1
    for row in reader:
        rows.append(row)
        lines.append(start)
        start = reader.line_num + 1
    return header, rows, lines


def _field_count_error(table: _Table, line: int, fields: list[str], last: bool) -> RunFormatError:
    n_col = len(table.header)
    if len(fields) <= 1 and not "".join(fields).strip():
        return table.error(line, None, "blank line inside the data", last)
    if len(fields) < n_col:
        col = len(fields) + 1
        msg = f"row has {len(fields)} fields, the header has {n_col}: field {col} missing"
    else:
        col = n_col + 1
        msg = f"row has {len(fields)} fields, the header has {n_col}: unexpected field {col}"
    return table.error(line, col, msg, last)


def _columns_by_rows(
    table: _Table, rows: list[list[str]], row_lines: list[int]
) -> list[list[str]]:
    """Check the field count of csv-module rows and turn them into columns of texts."""
    for r, row in enumerate(rows):
        if len(row) != len(table.header):
            raise _field_count_error(table, row_lines[r], row, r == len(rows) - 1)
    if not rows:
        return [[] for _ in table.header]
    return [list(c) for c in zip(*rows, strict=True)]


def _columns_from_texts(
    table: _Table, columns: list[list[str]], line_of: Any
) -> dict[str, Column]:
    """Convert each column of texts: numeric if every field is a number or blank, else text.

    The required and standard optional columns must be numeric: the first field in file
    order that is not a number is an error.
    """
    data: dict[str, Column] = {}
    first_bad: tuple[int, int, str] | None = None
    for j, (name, texts) in enumerate(zip(table.header, columns, strict=True)):
        values, bad = _parse_floats(texts)
        if bad is None:
            data[name] = values
        elif name in KNOWN_NUMERIC_COLUMNS:
            if first_bad is None or bad < first_bad[0]:
                first_bad = (bad, j + 1, texts[bad])
        else:
            data[name] = texts
    if first_bad is not None:
        r, col, txt = first_bad
        last = r == len(columns[0]) - 1
        raise table.error(line_of(r), col, f"cannot read {txt!r} as a number", last)
    return data


def _parse_floats(texts: list[str]) -> tuple[np.ndarray, int | None]:
    """Texts to float64 by the format's number rule (blank = NaN); (values, first bad index)."""
    values = np.empty(len(texts), dtype=np.float64)
    for i, t in enumerate(texts):
        if NUMBER.fullmatch(t):
            values[i] = float(t)
        elif BLANK.fullmatch(t):
            values[i] = math.nan
        else:
            return np.empty(0), i
    return values, None


def _check_values(table: _Table, data: dict[str, Column], line_of: Any, field_text: Any) -> None:
    """Required values finite, time strictly ascending; errors name line and field index.

    ``line_of(row)`` gives a row's file line, ``field_text(row, column)`` the text of a field.
    """
    n = len(data["t_s"])
    worst: tuple[int, int] | None = None
    for name in REQUIRED_COLUMNS:
        bad = np.flatnonzero(~np.isfinite(data[name]))
        if bad.size:
            cand = (int(bad[0]), table.header.index(name) + 1)
            worst = cand if worst is None or cand < worst else worst
    if worst is not None:
        r, col = worst
        value = data[table.header[col - 1]][r]
        if np.isnan(value):
            txt = field_text(r, col)
            what = "empty value" if not txt.strip() else f"value {txt.strip()!r} (NaN)"
        else:
            what = f"non-finite value {float(value)!r}"
        raise table.error(line_of(r), col, f"{what} in a required column", r == n - 1)
    t = data["t_s"]
    bad = np.flatnonzero(~(np.diff(t) > 0))
    if bad.size:
        r = int(bad[0]) + 1
        raise table.error(
            line_of(r),
            table.header.index("t_s") + 1,
            f"time must be strictly ascending: {float(t[r])!r} after {float(t[r - 1])!r} on line "
            f"{line_of(r - 1)}",
            r == n - 1,
        )
