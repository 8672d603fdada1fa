"""``rig import FILE --map MAP.toml --unit UNIT.json (--out RUN | --into STORE)``: another
lab's file (delimited text, NI TDMS) as a rig-run/1 run folder or a stored run.

The module cannot be named ``import`` (a Python keyword); the command is."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from rig.commands.options import SAMPLES_HELP


def register(app: typer.Typer) -> None:
    @app.command("import", short_help="Import another lab's measurement through a map.")
    def import_(
        file: Annotated[Path, typer.Argument(
            metavar="FILE", help="The file to import: delimited text (CSV, catman ASCII) or "
            "NI TDMS (.tdms).")],
        map_file: Annotated[Path, typer.Option(
            "--map", help="The import map (TOML): columns, units, delimiter, decimal mark, "
            "test keys (docs/import-export.md).")],
        unit: Annotated[Path, typer.Option(
            "--unit", help="Unit data (run.json 'unit' JSON) of the unit measured.")],
        out: Annotated[Path | None, typer.Option(
            "--out", help="Write a rig-run/1 run folder here.")] = None,
        into: Annotated[str | None, typer.Option(
            "--into", help="Add the run to this store (folder or postgresql:// URL).")] = None,
        samples: Annotated[Path | None, typer.Option(
            "--samples", envvar="RIG_SAMPLES_DIR", help=SAMPLES_HELP)] = None,
        force: Annotated[bool, typer.Option(
            "--force", help="Replace an existing --out run folder that rig wrote.")] = False,
        run_id: Annotated[str | None, typer.Option(
            "--run-id", help="The run id of a run folder (default: the map's run_id, else "
            "the file name). A stored run gets the store's id.")] = None,
    ) -> None:
        """Import another lab's measurement through a map: units converted to the run's
        (s, N·m, deg, °C), run.json with the unit, the map's test keys and source
        {file, map}. Exactly one of --out and --into. --out is never inside a store or a
        run folder, and an existing one is replaced only with --force."""
        from rig.io.importer import import_run, store_imported, write_imported
        from rig.io.map import RunImportError

        if (out is None) == (into is None):
            raise RunImportError("give exactly one of --out RUN_FOLDER and --into STORE")
        run = import_run(file, map_file, unit, run_id=run_id)
        if out is not None:
            folder = write_imported(run, out, force=force, source=file)
            typer.echo(f"imported {file}: {run.n_samples} samples -> run folder {folder}")
        else:
            stored = store_imported(run, into, samples=samples)
            from rig.core.redact import redact

            typer.echo(f"imported {file}: {run.n_samples} samples -> run {stored} in "
                       f"{redact(into)}")
