"""Reading JSON files users hand to the rig (units, labels) with bounds and clear errors.

A unit file names one file on disk: only a regular file of at most :data:`MAX_JSON_BYTES` is
read (``/dev/zero`` or a FIFO would read forever), and JSON nested deeper than Python's
recursion limit is refused in one line instead of a ``RecursionError`` traceback.
"""

from __future__ import annotations

import json
import math
import os
import stat
from pathlib import Path
from typing import Any

import numpy as np

from rig.core.errors import RigError

__all__ = ["MAX_JSON_BYTES", "DuplicateKey", "check_bounded_file", "finite_for_json",
           "no_duplicate_keys", "parse_json_text", "read_bounded_text", "read_json_file"]

MAX_JSON_BYTES = 4 * 1024 * 1024
"""A unit or a run.json is a few kB; 4 MB leaves room for long notes and refuses the absurd."""


def read_json_file(path: str | Path, error: type[RigError], what: str,
                   max_bytes: int = MAX_JSON_BYTES) -> Any:
    """The parsed JSON of ``path``; ``error`` naming the file (and line:column) otherwise."""
    file = Path(path)
    text = read_bounded_text(file, error, what, max_bytes, "cannot read {file}, the {what}")
    return parse_json_text(text, str(file), error)


def read_bounded_text(file: Path, error: type[RigError], what: str, max_bytes: int,
                      unreadable: str = "{file}: cannot read the {what}") -> str:
    """The UTF-8 text of ``file``, a regular file of at most ``max_bytes``; ``error`` naming
    the file otherwise (``unreadable``, formatted with file and what, when it cannot be
    stat'ed)."""
    try:
        info = file.stat()
    except OSError as exc:
        where = unreadable.format(file=file, what=what)
        raise error(f"{where} ({exc.strerror or exc})") from exc
    check_bounded_file(file, info, error, what, max_bytes)
    try:
        return file.read_text(encoding="utf-8")
    except OSError as exc:
        raise error(f"{file}: cannot read the {what} ({exc.strerror or exc})") from exc
    except UnicodeDecodeError as exc:
        raise error(f"{file}: not UTF-8 text ({exc.reason} at byte {exc.start})") from exc


def check_bounded_file(file: Path, info: os.stat_result, error: type[RigError], what: str,
                       max_bytes: int) -> None:
    """``error`` unless ``file`` (its ``stat``) is a regular file of at most ``max_bytes``:
    a device or FIFO (``/dev/zero``) would be read for ever."""
    if not stat.S_ISREG(info.st_mode):
        raise error(f"{file}: the {what} must be a regular file, not a device, FIFO or "
                    "directory")
    if info.st_size > max_bytes:
        raise error(f"{file}: the {what} is {info.st_size} bytes, more than the "
                    f"{max_bytes} a {what} can be")


class DuplicateKey(ValueError):
    """A JSON object gives ``key`` twice (raised by :func:`no_duplicate_keys`)."""

    def __init__(self, key: str) -> None:
        super().__init__(key)
        self.key = key


def no_duplicate_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """``object_pairs_hook`` for ``json.loads``: the object; DuplicateKey for a key given
    twice."""
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise DuplicateKey(key)
        out[key] = value
    return out


def parse_json_text(text: str, where: str, error: type[RigError], **kwargs: Any) -> Any:
    """``json.loads`` with one-line errors: ``where:line:column: reason``."""
    try:
        return json.loads(text, **kwargs)
    except json.JSONDecodeError as exc:
        raise error(f"{where}:{exc.lineno}:{exc.colno}: {exc.msg}") from exc
    except RecursionError:
        raise error(f"{where}: JSON nested too deeply (more levels than any run or unit "
                    "file has)") from None


def finite_for_json(obj: Any) -> Any:
    """``obj`` with every NaN or infinity as None and numpy scalars as Python numbers: JSON
    has no NaN, and a report must never carry one as a number."""
    if isinstance(obj, dict):
        return {str(k): finite_for_json(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [finite_for_json(v) for v in obj]
    if isinstance(obj, float | np.floating):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def json_safe(value: Any) -> Any:
    """A copy with NaN/inf floats as None and numpy scalars as Python numbers (strict JSON)."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
