"""Reading the application's TOML files (rig configurations, campaigns) with clear errors.

Every error names the file and, for a syntax error, line and column (``file:L:C: ...``); for a
value that fails validation, the dotted key (``file: drive.torque_limit_Nm: ...``).
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from rig.core.errors import RigError
from rig.core.json_files import read_bounded_text

MAX_TOML_BYTES = 1024 * 1024
"""A rig configuration or a campaign is a few kB; 1 MB refuses the absurd before reading."""
_TOML_POSITION = re.compile(r"\(at line (\d+), column (\d+)\)")


def read_toml(path: str | Path, error: type[RigError], what: str) -> dict[str, Any]:
    """Parse ``path``; any failure raises ``error`` naming the file (and line:column)."""
    file = Path(path)
    text = read_bounded_text(file, error, what, MAX_TOML_BYTES)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        message = str(exc)
        match = _TOML_POSITION.search(message)
        where = f"{file}:{match.group(1)}:{match.group(2)}" if match else str(file)
        reason = _TOML_POSITION.sub("", message).strip()
        raise error(f"{where}: TOML syntax error: {reason}") from exc
    except RecursionError:
        raise error(f"{file}: TOML nested too deeply (more levels than any {what} has)") \
            from None


def describe_validation_error(exc: ValidationError, source: str) -> str:
    """One line per invalid value: ``source: dotted.key: message (got value)``."""
    lines = []
    for err in exc.errors():
        key = ".".join(str(p) for p in err["loc"]) or "(top level)"
        got = err.get("input")
        shown = "" if isinstance(got, dict) else f" (got {got!r})"
        message = str(err["msg"]).removeprefix("Value error, ")
        lines.append(f"{source}: {key}: {message}{shown}")
    return "\n".join(lines)
