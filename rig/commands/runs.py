"""``rig runs``: list the runs of a measurement store with their status, verdict (OK / NOT OK /
INCOMPLETE / NO LIMITS, rig/results/outcome.py) and lost motion."""

from __future__ import annotations

import math
import sys
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from rig.commands.options import DEFAULT_STORE, SamplesOption, StoreOption, json_option
from rig.commands.output import outcome_markup

if TYPE_CHECKING:
    from rig.store.records import RunInfo

STATUS_STYLE = {"running": "yellow", "completed": "green", "aborted": "red"}


def lost_motion(info: RunInfo) -> tuple[Any, Any]:
    """The run's recorded lost motion and its standard uncertainty (arcmin; None if none)."""
    metrics = info.metrics or {}
    return (metrics.get("lost_motion_arcmin"),
            (metrics.get("uncertainty") or {}).get("lost_motion_arcmin"))


def lost_motion_text(info: RunInfo) -> str:
    """``4.123 ± 0.004`` (arcmin), the value alone without an uncertainty, "" if none."""
    value, u = lost_motion(info)
    if isinstance(value, bool) or not isinstance(value, int | float):
        return ""
    if not math.isfinite(value):
        return f"{value} (not a number)" if math.isnan(value) else str(value)
    text = f"{value:.3f}"
    if isinstance(u, int | float) and not isinstance(u, bool) and math.isfinite(u):
        text += f" ± {u:.3f}"
    return text


def run_json(info: RunInfo) -> dict[str, Any]:
    """One run of ``rig runs --json``: the index row (:meth:`RunInfo.to_dict`) with its
    ``verdict`` (the displayed word of ``outcome``) and ``lost_motion_arcmin`` /
    ``lost_motion_arcmin_u`` (arcmin) beside; strict JSON (NaN, infinities as null)."""
    from rig.core.json_files import finite_for_json
    from rig.results.outcome import outcome_word

    value, u = lost_motion(info)
    verdict = None if info.outcome is None else outcome_word(info.outcome)
    return finite_for_json({**info.to_dict(), "verdict": verdict,
                            "lost_motion_arcmin": value, "lost_motion_arcmin_u": u})


def _table(runs: list[RunInfo], root: str) -> Table:
    table = Table(title=f"Runs in {root} (newest first)")
    table.add_column("run", no_wrap=True)
    table.add_column("status")
    table.add_column("outcome", no_wrap=True)
    table.add_column("lost motion arcmin", justify="right", no_wrap=True)
    table.add_column("reason")
    table.add_column("unit")
    table.add_column("operator")
    table.add_column("plan")
    table.add_column("started (UTC)")
    table.add_column("samples", justify="right")
    table.add_column("campaign")
    for info in runs:
        style = STATUS_STYLE.get(info.status, "")
        plan = " ".join(p for p in (info.plan_name, info.plan_version) if p)
        status = f"[{style}]{info.status}[/{style}]" if style else info.status
        if info.calibration_warnings:
            status += " [red]cal. past due[/red]"
        table.add_row(
            info.run_id,
            status,
            outcome_markup(info.outcome),
            lost_motion_text(info),
            escape(info.reason or ""),
            info.unit_serial or "",
            info.operator or "",
            plan,
            info.started_at.replace("T", " ").removesuffix("Z"),
            "" if info.n_samples is None else str(info.n_samples),
            info.campaign_id or "",
        )
    return table


def register(app: typer.Typer) -> None:
    @app.command()
    def runs(
        store: StoreOption = DEFAULT_STORE,
        samples: SamplesOption = None,
        json_file: json_option("Also write the list as JSON") = None,
        status: Annotated[
            str | None,
            typer.Option(help="Only runs with this status: running, completed, aborted."),
        ] = None,
        campaign: Annotated[str | None, typer.Option(help="Only runs of this campaign id.")] = None,
        limit: Annotated[int | None, typer.Option(min=1, help="At most this many runs.")] = None,
    ) -> None:
        """List the stored runs with their status, outcome (OK / NOT OK / INCOMPLETE / NO
        LIMITS) and lost motion (newest first).

        Each run's record is its folder's run.json; the index is a copy, read again where
        a run.json changed after its run ended. Opening the store marks runs left "running"
        by a process that has ended as aborted.
        The store is --store, else $RIG_STORE, else ./rig-store: a folder, or a database
        URL postgresql://... whose run files are in --samples (else $RIG_SAMPLES_DIR).
        --json lists every run once, with its run_id.
        """
        from rig.commands.output import JsonOutput
        from rig.store import Store

        if status is not None and status not in ("running", "completed", "aborted"):
            raise typer.BadParameter(
                f"{status!r} is not one of running, completed, aborted", param_hint="--status"
            )
        st = Store(store, create=False, samples=samples)
        infos = st.list_runs(campaign_id=campaign, status=status, limit=limit)
        json_out = JsonOutput(json_file)
        if json_file is not None:
            json_out.write({"store": st.location, "recovered": st.recovered,
                            "runs": [run_json(i) for i in infos]})
            if json_out.to_stdout:
                return
        # rich wraps to 80 columns when not writing to a terminal: allow a wide table then
        console = Console(width=None if sys.stdout.isatty() else 200)
        for run_id in st.recovered:
            console.print(f"[red]marked aborted[/red] {run_id}: its process ended during the run")
        if not infos:
            console.print(f"no runs in {st.location}")
            return
        console.print(_table(infos, st.location))
        for info in infos:
            for message in info.calibration_warnings:
                console.print(f"[red]warning[/red] {info.run_id}: {message}")
