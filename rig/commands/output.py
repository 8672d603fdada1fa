"""``--json FILE`` of every command; ``--json -`` is stdout.

With ``-`` the JSON is the only thing on stdout (a script pipes it to ``jq`` or reads it
whole): what the command prints for people (tables, progress, "written to ...") goes to
stderr, through a console made with ``Console(stderr=out.to_stdout)``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from rig.core.errors import RigError
from rig.core.json_files import finite_for_json

STDOUT = "-"


def json_to_stdout(path: str | Path | None) -> bool:
    """Whether ``--json`` names stdout (``-``)."""
    return path is not None and str(path) == STDOUT


class JsonOutput:
    """Where a command's ``--json`` goes: a file, stdout (``-``) or nowhere (None).
    ``to_stdout``: the command's own output then goes to stderr."""

    def __init__(self, path: str | Path | None) -> None:
        self.path = None if path is None else Path(path)
        self.to_stdout = json_to_stdout(path)

    @property
    def where(self) -> str:
        """``stdout`` or the file's path (for "... written to WHERE")."""
        return "stdout" if self.to_stdout else str(self.path)

    def write(self, payload: Any, **dumps: Any) -> None:
        """``payload`` as strict JSON (NaN and infinities as null), indented."""
        if self.path is None:
            return
        options = {"indent": 2, "ensure_ascii": False} | dumps
        self.write_text(json.dumps(finite_for_json(payload), allow_nan=False, **options) + "\n")

    def write_text(self, text: str) -> None:
        """``text`` (JSON already) to stdout or the file (its folder made if missing)."""
        if self.path is None:
            return
        if self.to_stdout:
            sys.stdout.write(text)
            sys.stdout.flush()
            return
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.path.write_text(text, encoding="utf-8")
        except OSError as exc:
            raise RigError(f"{self.path}: cannot write the JSON: {exc.strerror or exc}"
                           ) from exc
