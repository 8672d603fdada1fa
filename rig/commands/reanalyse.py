"""``rig reanalyse``: re-compute the metrics and diagnoses of stored runs on Dask."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from rig.commands.options import DEFAULT_STORE, SamplesOption, StoreOption
from rig.commands.output import make_console


def register(app: typer.Typer) -> None:
    @app.command(short_help="Analyse and diagnose the stored results again.")
    def reanalyse(
        store: StoreOption = DEFAULT_STORE,
        samples: SamplesOption = None,
        since: Annotated[str | None, typer.Option(
            "--since", help="Only runs and campaigns started on or after this UTC date/time "
            "(ISO 8601).")] = None,
        dask: Annotated[str | None, typer.Option(
            "--dask", help="A Dask scheduler's address (tcp://scheduler:8786); its workers "
            "must reach the sample files at the same path.")] = None,
        workers: Annotated[int | None, typer.Option(
            "--workers", min=1, help="Processes of the local Dask cluster (default 1).")
        ] = None,
        json_out: Annotated[bool, typer.Option(
            "--json", help="Print the summary as JSON on stdout (--json, --json -), or write "
            "it to a file (--json FILE).")] = False,
        json_file: Annotated[Path | None, typer.Argument(
            hidden=True, metavar="FILE", help="With --json: the summary's file ('-': stdout).")
        ] = None,
    ) -> None:
        """Analyse every completed run and diagnose every completed campaign again with this
        software version; the results are kept beside the older ones (docs/deployment.md).

        Runs and campaigns that already have a result of this version are skipped: after an
        interruption, run the same command again to go on. Exit code 1 if a run's files were
        missing or unreadable (each is named).
        """
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

        from rig.commands.output import JsonOutput
        from rig.core.errors import RigError
        from rig.store import Store
        from rig.store.reanalyse import reanalyse as run_reanalysis

        if json_file is not None and not json_out:
            raise RigError(f"{json_file}: the summary's file goes with --json (--json FILE)")
        if dask and workers:
            raise RigError("give --dask (a scheduler) or --workers (a local cluster), not both")
        st = Store(store, create=False, samples=samples)
        st.check_writable("a re-analysis")
        err = make_console(stderr=True)
        progress = Progress("re-analysing", BarColumn(), MofNCompleteColumn(),
                            TimeRemainingColumn(), console=err, transient=False)
        task = progress.add_task("jobs", total=None)

        def on_progress(done: int, total: int) -> None:
            progress.update(task, completed=done, total=total)

        try:
            with progress:
                summary = run_reanalysis(st, since=since, dask_address=dask, workers=workers,
                                         on_progress=on_progress)
        except KeyboardInterrupt:
            err.print("[red]interrupted[/red]: the results written so far are kept; run the "
                      "same command again to go on")
            raise typer.Exit(2) from None
        except (OSError, TimeoutError) as exc:
            raise RigError(f"Dask scheduler {dask}: {exc}") from exc
        except ValueError as exc:
            raise RigError(str(exc)) from exc
        if json_out:
            JsonOutput(json_file or "-").write(summary.to_dict(), ensure_ascii=True)
        else:
            err.print(f"software {summary.software_version}: {summary.n_runs} runs, "
                      f"{summary.n_campaigns} campaigns; {summary.written} results written, "
                      f"{summary.skipped} done before, {summary.errors} not analysable")
        for message in summary.unreadable:
            err.print(f"[red]unreadable[/red] {message}")
        if summary.unreadable:
            raise typer.Exit(1)
