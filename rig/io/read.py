"""Reading the mapped columns of another lab's file: delimited text (pyarrow), NI TDMS
(npTDMS), or the rig's own parquet, xlsx and mat exports (:mod:`rig.io.read_exports`).
Values come back as float64 in the file's own units; :mod:`rig.io.importer` converts them.
Every problem is a one-line :class:`rig.io.map.RunImportError` naming the file and the column
(channel), and for text files the line.
"""

from __future__ import annotations

import csv
import difflib
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pacsv

from rig.io.map import ImportMap, RunImportError, known_unit
from rig.io.read_exports import export_format, read_export_columns

__all__ = ["SourceData", "read_source"]

NUMBER = r"^[+-]?(([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?|nan|inf|infinity)$"
"""A number in a delimited file, once the decimal mark is a point (any case for nan/inf)."""


@dataclass
class SourceData:
    """The mapped columns of a file: run column -> float64 values in the file's units.

    ``where(run_column, index)``: the file, line/sample and column of a value, for errors.
    """

    values: dict[str, np.ndarray]
    where: Callable[[str, int | None], str]
    format: str
    units: dict[str, str | None] = field(default_factory=dict)
    """Run column -> the unit the file itself gives (a catman header's ``[N*m]``, a TDMS
    channel's ``unit_string``), None where it gives none."""
    extra: dict[str, np.ndarray | list[str]] = field(default_factory=dict)
    """Every other column (channel) of the file, by its own name, in file order: float64
    (blank = NaN) when every cell is a number, else the cells' texts as read. rig-run/1 keeps
    extra columns on round trip, and ``rig analyse`` uses some (``torque_command_Nm``)."""


def read_source(path: Path, mapping: ImportMap) -> SourceData:
    """The columns ``mapping`` names, read from ``path`` (its format: the map's or by the
    extension, ``.tdms`` for TDMS)."""
    if not path.is_file():
        raise RunImportError(f"{path}: no such file")
    if mapping.file_format(path) == "tdms":
        return _read_tdms(path, mapping)
    fmt = export_format(path)
    if fmt is not None:
        return _read_export(path, mapping, fmt)
    return _read_delimited(path, mapping)


def _read_export(path: Path, mapping: ImportMap, fmt: str) -> SourceData:
    """The mapped columns of a ``rig export`` parquet, xlsx or mat file (the round trip):
    columns by name, as a delimited file's header names them."""
    columns = read_export_columns(path, fmt)
    have = list(columns)
    wanted = _wanted(mapping)
    first_row = 2 if fmt == "xlsx" else 1  # an xlsx sheet's row 1 is the header

    def where(run_column: str, index: int | None) -> str:
        name = _source_name(wanted, have, run_column)
        row = f" row {first_row + index}" if index is not None else ""
        return f"{path}: column {name!r} ({run_column}){row}"

    values: dict[str, np.ndarray] = {}
    for run_column, name in wanted.items():
        if name not in columns:
            raise RunImportError(_missing(path, run_column, name, have, f"{fmt} column"))
        data = columns[name]
        if not isinstance(data, np.ndarray):
            raise RunImportError(f"{where(run_column, None)}: holds text, not numbers")
        values[run_column] = data
    extra = {name: data for name, data in columns.items() if name not in wanted.values()}
    return SourceData(values, where, fmt, {run_column: None for run_column in wanted}, extra)


def _wanted(mapping: ImportMap) -> dict[str, str]:
    """Run column -> file column (channel) for every column the map names."""
    refs = mapping.columns.model_dump(exclude_none=True)
    return {name: ref["column"] for name, ref in refs.items()}


def _source_name(wanted: dict[str, str], have: list[str], run_column: str) -> str:
    """The file's column (channel) an error about ``run_column`` names: the mapped one, an
    extra column of that name, else the torque's."""
    return wanted.get(run_column) or (run_column if run_column in have
                                      else wanted["torque_Nm"])


def _missing(path: Path, run_column: str, name: str, have: list[str], what: str) -> str:
    near = difflib.get_close_matches(name, have, n=1, cutoff=0.6)
    hint = f"; did you mean {near[0]!r}?" if near else ""
    return (f"{path}: {what} {name!r} (mapped to {run_column}) is not in the file; "
            f"it has {have}{hint}")


# --------------------------------------------------------------------------- delimited text


def _header(path: Path, mapping: ImportMap) -> list[str]:
    encoding = "utf-8-sig" if mapping.encoding.lower().replace("_", "-") in (
        "utf-8", "utf8") else mapping.encoding
    try:
        with open(path, encoding=encoding, newline="") as f:
            for _ in range(mapping.skip_rows):
                if not f.readline():
                    break
            line = f.readline()
    except LookupError:
        raise RunImportError(f"{path}: unknown encoding {mapping.encoding!r} "
                             "(map key 'encoding')") from None
    except UnicodeDecodeError as exc:
        raise RunImportError(f"{path}: not {mapping.encoding} text ({exc.reason} at byte "
                             f"{exc.start}); set 'encoding' in the map") from None
    except UnicodeError as exc:
        raise RunImportError(f"{path}: not {mapping.encoding} text ({exc}); set 'encoding' "
                             "in the map") from None
    except OSError as exc:
        raise RunImportError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if not line.strip():
        raise RunImportError(f"{path}:{mapping.skip_rows + 1}: no header line (after "
                             f"skip_rows = {mapping.skip_rows})")
    return [c.strip() for c in next(csv.reader([line.rstrip("\r\n")],
                                               delimiter=mapping.delimiter))]


BLOCK_BYTES = 8 << 20
"""Bytes of text pyarrow parses at a time (``pyarrow.csv.open_csv``): a file of any size is
read block by block, only the mapped columns' numbers kept."""

HEADER_UNIT = re.compile(r"\[\s*([^\[\]]*?)\s*\]\s*$")
"""A unit in a header, catman style: ``Torque [N*m]``."""


def _read_delimited(path: Path, mapping: ImportMap) -> SourceData:
    header = _header(path, mapping)
    wanted = _wanted(mapping)
    for run_column, name in wanted.items():
        if name not in header:
            raise RunImportError(_missing(path, run_column, name, header, "column"))
        if header.count(name) > 1:
            raise RunImportError(f"{path}:{mapping.skip_rows + 1}: column {name!r} appears "
                                 "twice in the header")
    header_line = mapping.skip_rows + 1

    def where(run_column: str, index: int | None) -> str:
        name = _source_name(wanted, header, run_column)
        col = header.index(name) + 1
        line = f"{header_line + 1 + index}:" if index is not None else f"{header_line}:"
        return f"{path}:{line}{col}: column {name!r} ({run_column})"

    names = list(dict.fromkeys(wanted.values()))
    others = [c for c in header if c and c not in names and header.count(c) == 1]
    chunks: dict[str, list[np.ndarray]] = {run_column: [] for run_column in wanted}
    other_chunks: dict[str, list[pa.Array]] = {name: [] for name in others}
    offset = 0
    try:
        reader = pacsv.open_csv(
            path,
            read_options=pacsv.ReadOptions(skip_rows=mapping.skip_rows,
                                           encoding=mapping.encoding,
                                           block_size=BLOCK_BYTES),
            parse_options=pacsv.ParseOptions(delimiter=mapping.delimiter),
            convert_options=pacsv.ConvertOptions(
                include_columns=names + others,
                column_types={name: pa.string() for name in names + others},
                strings_can_be_null=False, quoted_strings_can_be_null=False),
        )
        for batch in reader:
            for run_column, name in wanted.items():
                texts = batch.column(batch.schema.get_field_index(name))
                chunks[run_column].append(
                    _numbers(texts, mapping.decimal, run_column, where, offset))
            for name in others:
                other_chunks[name].append(batch.column(batch.schema.get_field_index(name)))
            offset += batch.num_rows
    except (pa.ArrowInvalid, OSError, LookupError, UnicodeError) as exc:
        text = " ".join(str(exc).split())
        raise RunImportError(f"{path}: {text}") from None
    values: dict[str, np.ndarray] = {}
    for run_column in wanted:  # one column at a time: its blocks are freed as it is joined
        parts = chunks.pop(run_column)
        values[run_column] = np.concatenate(parts) if parts else np.empty(0)
        del parts
    extra = {name: _extra_column(other_chunks.pop(name), mapping.decimal) for name in others}
    units = {run_column: _header_unit(name) for run_column, name in wanted.items()}
    return SourceData(values, where, "csv", units, extra)


def _extra_column(parts: list[pa.Array], decimal: str) -> np.ndarray | list[str]:
    """An unmapped column's cells: float64 when every cell is a number or blank (blank =
    NaN), else the texts as read."""
    texts = pa.chunked_array(parts, type=pa.string()).combine_chunks()
    cells = pc.utf8_trim_whitespace(texts)
    if decimal == ",":
        if pc.any(pc.match_substring(cells, ".")).as_py():
            return texts.to_pylist()
        cells = pc.replace_substring(cells, ",", ".")
    blank = pc.equal(cells, "")
    ok = pc.or_(blank, pc.match_substring_regex(cells, NUMBER, ignore_case=True))
    if len(cells) and not pc.all(ok).as_py():
        return texts.to_pylist()
    numbers = pc.if_else(blank, pa.scalar(None, pa.string()), cells).cast(pa.float64())
    return numbers.fill_null(np.nan).to_numpy()


def _header_unit(name: str) -> str | None:
    """The unit a header names in brackets when it is one rig knows (``[Ch 3]`` is not)."""
    match = HEADER_UNIT.search(name)
    return match.group(1) if match and known_unit(match.group(1)) else None


def _numbers(texts: pa.Array, decimal: str, run_column: str,
             where: Callable[[str, int | None], str], offset: int = 0) -> np.ndarray:
    """Text cells as float64: blank = missing (NaN); anything else must be a number.
    ``offset``: the index of the first cell in the file (for the line of an error)."""
    cells = pc.utf8_trim_whitespace(texts)
    if decimal == ",":
        points = pc.match_substring(cells, ".")
        if pc.any(points).as_py():
            i = _first(points)
            raise RunImportError(f"{where(run_column, offset + i)}: {cells[i].as_py()!r} has a "
                                 "'.' but "
                                 "the map's decimal mark is ','")
        cells = pc.replace_substring(cells, ",", ".")
    blank = pc.equal(cells, "")
    ok = pc.or_(blank, pc.match_substring_regex(cells, NUMBER, ignore_case=True))
    if not pc.all(ok).as_py():
        i = _first(pc.invert(ok))
        raise RunImportError(f"{where(run_column, offset + i)}: {texts[i].as_py()!r} is not "
                             "a number")
    numbers = pc.if_else(blank, pa.scalar(None, pa.string()), cells).cast(pa.float64())
    return numbers.fill_null(np.nan).to_numpy()


def _first(mask: pa.Array) -> int:
    return int(np.flatnonzero(mask.to_numpy(zero_copy_only=False))[0])


# --------------------------------------------------------------------------- NI TDMS


def _read_tdms(path: Path, mapping: ImportMap) -> SourceData:
    from nptdms import TdmsFile

    try:
        with TdmsFile.open(path) as tdms:  # channels are read one by one, as needed
            return _tdms_columns(path, mapping, tdms)
    except RunImportError:
        raise
    except Exception as exc:  # npTDMS raises ValueError, KeyError, struct.error ... on junk
        text = " ".join(str(exc).split()) or type(exc).__name__
        raise RunImportError(f"{path}: not a readable TDMS file ({text})") from None


def _tdms_columns(path: Path, mapping: ImportMap, tdms: Any) -> SourceData:
    groups = [g.name for g in tdms.groups()]
    if mapping.group is None:
        if len(groups) != 1:
            raise RunImportError(f"{path}: the file has the groups {groups}; name one with "
                                 "'group' in the map")
        group_name = groups[0]
    elif mapping.group not in groups:
        raise RunImportError(_missing(path, "group", mapping.group, groups, "group"))
    else:
        group_name = mapping.group
    group = tdms[group_name]
    have = [c.name for c in group.channels()]
    wanted = _wanted(mapping)
    for run_column, name in wanted.items():
        if name not in have:
            raise RunImportError(_missing(path, run_column, name, have,
                                          f"channel of group {group_name!r}"))

    def where(run_column: str, index: int | None) -> str:
        name = _source_name(wanted, have, run_column)
        sample = f" sample {index + 1}" if index is not None else ""
        return f"{path}: group {group_name!r} channel {name!r} ({run_column}){sample}"

    values: dict[str, np.ndarray] = {}
    units: dict[str, str | None] = {}
    for run_column, name in wanted.items():
        channel = group[name]
        data = np.asarray(channel[:])
        if data.dtype.kind not in "fiu":
            raise RunImportError(f"{where(run_column, None)}: holds {data.dtype} values, "
                                 "not numbers")
        values[run_column] = data.astype(np.float64, copy=False)
        unit = channel.properties.get("unit_string")
        units[run_column] = str(unit).strip() or None if unit is not None else None
    if "t_s" not in values:
        channel = group[wanted["torque_Nm"]]
        try:
            values["t_s"] = np.asarray(channel.time_track(), dtype=np.float64)
        except (KeyError, ValueError) as exc:
            raise RunImportError(
                f"{where('torque_Nm', None)}: the map names no t_s channel and this channel "
                f"has no waveform timing ({exc}); add t_s to [columns]") from None
    n = len(values["torque_Nm"])
    for run_column, data in values.items():
        if len(data) != n:
            raise RunImportError(f"{where(run_column, None)}: {len(data)} samples, but the "
                                 f"torque channel has {n}")
    extra: dict[str, np.ndarray | list[str]] = {}
    for name in have:  # the group's other channels of the same length
        if name in wanted.values() or not name or have.count(name) > 1:
            continue
        channel = group[name]
        if len(channel) != n:
            continue
        data = np.asarray(channel[:])
        extra[name] = data.astype(np.float64, copy=False) if data.dtype.kind in "fiub" \
            else [str(v) for v in data]
    return SourceData(values, where, "tdms", units, extra)
