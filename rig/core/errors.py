"""Errors of the application layer. The CLI prints them as one line and exits with code 2."""

from __future__ import annotations

from pathlib import Path


class RigError(Exception):
    """Base of every error the application reports to the user as one clear line."""


class RunFormatError(RigError):
    """A run or campaign file is malformed. Names the file and, where known, line and column."""

    def __init__(
        self, path: str | Path, message: str, line: int | None = None, column: int | None = None
    ) -> None:
        self.path = str(path)
        self.line = line
        self.column = column
        self.reason = message
        where = self.path
        if line is not None:
            where += f":{line}"
            if column is not None:
                where += f":{column}"
        super().__init__(f"{where}: {message}")
