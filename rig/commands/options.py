"""Options several commands declare alike, written once: ``--json FILE`` (``-``: stdout),
``--store`` and ``--samples`` (every command that opens the store), ``RUN_OR_CAMPAIGN``."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer

from rig.core.ranges import Range


def json_option(what: str) -> Any:
    """The ``--json FILE`` option of a command: ``what`` it writes there ("Write the report
    as JSON"); ``-`` is stdout for every command (:class:`rig.commands.output.JsonOutput`)."""
    return Annotated[Path | None, typer.Option("--json", help=f"{what} ('-': stdout).")]


STORE_HELP = ("Store: a folder (index.sqlite inside) or a database URL postgresql://... "
              "Default: the RIG_STORE environment variable if set, else ./rig-store in the "
              "current directory.")
SAMPLES_HELP = ("With a database --store: the folder of the run files (samples), shared by "
                "every rig. Default: the RIG_SAMPLES_DIR environment variable.")

StoreOption = Annotated[str, typer.Option("--store", envvar="RIG_STORE", help=STORE_HELP)]
SamplesOption = Annotated[Path | None, typer.Option(
    "--samples", envvar="RIG_SAMPLES_DIR", help=SAMPLES_HELP)]
DEFAULT_STORE = "rig-store"

RunOrCampaignArgument = Annotated[str, typer.Argument(
    metavar="RUN_OR_CAMPAIGN",
    help="A run or campaign folder, or a run or campaign id of the --store.")]


def in_range(rng: Range) -> Callable[[Any], Any]:
    """A typer ``callback`` that refuses a number outside ``rng`` (rig/core/ranges.py), NaN
    and infinities included, in one line naming the option and the range (exit 2)."""

    def check(value: Any) -> Any:
        if value is not None and not rng.contains(value):
            raise typer.BadParameter(f"expected {rng.text()} (got {value!r})")
        return value

    return check
