"""``rig runs``: list the runs of a measurement store with their status, verdict (OK / NOT OK /
INCOMPLETE / NO LIMITS, rig/results/outcome.py) and lost motion."""

from __future__ import annotations

import math
import sys
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich import box
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from rig.commands.options import DEFAULT_STORE, SamplesOption, StoreOption, json_option
from rig.commands.output import natural_width, outcome_markup

if TYPE_CHECKING:
    from rig.store.records import RunInfo

STATUS_STYLE = {"running": "yellow", "completed": "green", "aborted": "red"}


def lost_motion(info: RunInfo) -> tuple[Any, Any]:
    """The run's recorded lost motion and its standard uncertainty (arcmin; None if none)."""
    metrics = info.metrics or {}
    return (metrics.get("lost_motion_arcmin"),
            (metrics.get("uncertainty") or {}).get("lost_motion_arcmin"))


def lost_motion_text(info: RunInfo) -> str:
    """``4.123 ± 0.004`` (arcmin), the value alone without an uncertainty, "" if none; a value
    below zero as rig/results/outcome.py ``below_zero_text`` words it."""
    from rig.results.outcome import below_zero_text

    value, u = lost_motion(info)
    if isinstance(value, bool) or not isinstance(value, int | float):
        return ""
    if not math.isfinite(value):
        return f"{value} (not a number)" if math.isnan(value) else str(value)
    below = below_zero_text("lost_motion_arcmin", value, u, ".3f", "")
    if below is not None:
        return below
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


COLUMNS: tuple[tuple[str, dict[str, Any]], ...] = (
    ("run", {"no_wrap": True}),
    ("status", {"no_wrap": True}),
    ("outcome", {"no_wrap": True}),
    ("lost motion arcmin", {"justify": "right"}),
    ("reason", {}),
    ("unit", {}),
    ("operator", {}),
    ("plan", {}),
    ("started (UTC)", {}),
    ("samples", {"justify": "right"}),
    ("campaign", {}),
)
"""The columns of the table, in order (header, rich column options)."""
STARTED = "started (UTC)"
CORE = ("run", "status", "outcome", "lost motion arcmin", STARTED)
"""The columns shown at any width."""
OPTIONAL = ("unit", "reason", "campaign", "plan", "operator", "samples")
"""The other columns, added in this order while the table fits the width whole."""


def _cells(info: RunInfo) -> dict[str, str]:
    """One run's cells by column header (rich markup)."""
    style = STATUS_STYLE.get(info.status, "")
    status = f"[{style}]{info.status}[/{style}]" if style else info.status
    if info.calibration_warnings:
        status += " [red]cal. past due[/red]"
    return {
        "run": escape(info.run_id),
        "status": status,
        "outcome": outcome_markup(info.outcome),
        "lost motion arcmin": lost_motion_text(info),
        "reason": escape(info.reason or ""),
        "unit": escape(info.unit_serial or ""),
        "operator": escape(info.operator or ""),
        "plan": escape(" ".join(p for p in (info.plan_name, info.plan_version) if p)),
        "started (UTC)": info.started_at.replace("T", " ").removesuffix("Z"),
        "samples": "" if info.n_samples is None else str(info.n_samples),
        "campaign": escape(info.campaign_id or ""),
    }


def _table(rows: list[dict[str, str]], root: str, shown: tuple[str, ...],
           compact: bool = False) -> Table:
    """The table of ``shown`` columns; ``compact``: no rules between the columns, one space
    between them (a terminal too narrow for the boxed core columns)."""
    title = f"Runs in {escape(root)} (newest first)"
    table = (Table(title=title, box=box.SIMPLE_HEAD, show_edge=False, padding=(0, 0))
             if compact else Table(title=title))
    for header, options in COLUMNS:
        if header in shown:
            if compact and header == STARTED:  # the date above the time, each whole
                options = {**options, "no_wrap": True}
            table.add_column(header, overflow="fold", **options)
    for cells in rows:
        if compact:
            cells = {**cells, STARTED: cells[STARTED].replace(" ", "\n", 1)}
        table.add_row(*(cells[h] for h, _ in COLUMNS if h in shown))
    return table


def layout(console: Console, rows: list[dict[str, str]], root: str, wide: bool
           ) -> tuple[Table, tuple[str, ...]]:
    """The table to print and the columns left out: every column with ``wide``, else
    :data:`CORE` and those of :data:`OPTIONAL` with content that fit the console's width
    unwrapped (all eleven squeezed an 80-column terminal's cells to nothing); the core
    columns unboxed when they do not fit boxed."""
    every = tuple(h for h, _ in COLUMNS)
    if wide:
        return _table(rows, root, every), ()
    filled = tuple(h for h in every if h in CORE or any(cells[h] for cells in rows))
    shown = CORE
    if natural_width(console, _table(rows, root, shown)) > console.width:
        return (_table(rows, root, shown, compact=True),
                tuple(h for h in filled if h not in shown))
    for header in (h for h in OPTIONAL if h in filled):
        more = shown + (header,)
        if natural_width(console, _table(rows, root, more)) <= console.width:
            shown = more
    return _table(rows, root, shown), tuple(h for h in filled if h not in shown)


def register(app: typer.Typer) -> None:
    @app.command(short_help="List the stored runs: status, outcome, lost motion.")
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
        wide: Annotated[bool, typer.Option(
            "--wide", help="Every column (reason, unit, operator, plan, samples, campaign), "
            "lines as long as they need; without it a narrow terminal shows the columns "
            "that fit and names those left out.")] = False,
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
        from rig.commands.output import JsonOutput, columns_env, make_console
        from rig.results.outcome import below_zero_note
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
        # piped with no COLUMNS (a script reading the rows): every column, whole
        wide = wide or (not sys.stdout.isatty() and columns_env() is None)
        console = make_console()
        for run_id in st.recovered:
            console.print(f"[red]marked aborted[/red] {run_id}: its process ended during the run")
        if not infos:
            console.print(f"no runs in {escape(st.location)}")
            return
        rows = [_cells(info) for info in infos]
        table, left_out = layout(console, rows, st.location, wide)
        if wide:
            console = make_console(width=max(console.width, natural_width(console, table)))
        console.print(table)
        if "reason" in left_out:
            for info in infos:
                if info.reason:
                    console.print(f"{escape(info.run_id)}: {escape(info.reason)}")
        for info in infos:
            note = below_zero_note(info.metrics or {})
            if note is not None:
                console.print(f"[yellow]{escape(info.run_id)}[/yellow]: {note}")
            for message in info.calibration_warnings:
                console.print(f"[red]warning[/red] {info.run_id}: {message}")
        if left_out:
            console.print(f"[dim]left out at {console.width} columns: {', '.join(left_out)} "
                          "(rig runs --wide shows every column)[/dim]")
