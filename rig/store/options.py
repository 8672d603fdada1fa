"""The ``--store`` and ``--samples`` options every command that opens the store shares."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

STORE_HELP = ("Store: a folder (index.sqlite inside) or a database URL postgresql://... "
              "Default: the RIG_STORE environment variable if set, else ./rig-store in the "
              "current directory.")
SAMPLES_HELP = ("With a database --store: the folder of the run files (samples), shared by "
                "every rig. Default: the RIG_SAMPLES_DIR environment variable.")

StoreOption = Annotated[str, typer.Option("--store", envvar="RIG_STORE", help=STORE_HELP)]
SamplesOption = Annotated[Path | None, typer.Option(
    "--samples", envvar="RIG_SAMPLES_DIR", help=SAMPLES_HELP)]
DEFAULT_STORE = "rig-store"
