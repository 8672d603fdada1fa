"""Options several commands declare alike, written once: ``--json FILE`` (``-``: stdout)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer


def json_option(what: str) -> Any:
    """The ``--json FILE`` option of a command: ``what`` it writes there ("Write the report
    as JSON"); ``-`` is stdout for every command (:class:`rig.commands.output.JsonOutput`)."""
    return Annotated[Path | None, typer.Option("--json", help=f"{what} ('-': stdout).")]
