"""What every command shares: its console, the measuring progress bar, the outcome's word in
colour, the exit code of a verdict, and ``--json FILE`` (``--json -`` is stdout).

With ``--json -`` the JSON is the only thing on stdout (a script pipes it to ``jq`` or reads
it whole): what the command prints for people (tables, progress, "written to ...") goes to
stderr, through a console made with ``Console(stderr=out.to_stdout)``.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rich.console import Console

from rig.core.errors import RigError
from rig.core.json_files import finite_for_json

if TYPE_CHECKING:
    from rich.table import Table

    from rig.engine.events import ProgressEvent

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


def write_json(path: str | Path | None, payload: Any, **dumps: Any) -> None:
    """``payload`` as ``--json`` gives it: to the file ``path``, stdout for ``-``, nowhere for
    None (:class:`JsonOutput`)."""
    JsonOutput(path).write(payload, **dumps)


DEFAULT_WIDTH = 120
"""Columns of a command's output into a pipe or file when ``COLUMNS`` is not set."""


def columns_env() -> int | None:
    """The width ``COLUMNS`` asks for (columns; None if unset or not a positive integer)."""
    text = os.environ.get("COLUMNS", "").strip()
    return int(text) if text.isdigit() and int(text) > 0 else None


def make_console(*, stderr: bool = False, width: int | None = None) -> Console:
    """A command's console: on a terminal its width; into a pipe or file ``COLUMNS``, else
    :data:`DEFAULT_WIDTH` columns (rich alone would wrap at 80); ``width`` overrides both."""
    stream = sys.stderr if stderr else sys.stdout
    if width is None and not stream.isatty():
        width = columns_env() or DEFAULT_WIDTH
    return Console(stderr=stderr, width=width)


def console() -> Console:
    """The console of a measuring command: stderr, :func:`make_console`'s width."""
    return make_console(stderr=True)


def natural_width(console: Console, table: Table) -> int:
    """The columns ``table`` takes on ``console`` with no cell wrapped."""
    from rich.measure import Measurement

    return Measurement.get(console, console.options.update_width(10_000), table).maximum


def fit_table(console: Console, table: Table) -> Table:
    """``table`` made for ``console``'s width: no cell cut with "…" (what does not fit wraps,
    a word longer than its column folds), and no rules between the columns when it does not
    fit boxed (one space between columns instead of three, no edges)."""
    from rich import box

    for column in table.columns:
        column.overflow = "fold"
    if natural_width(console, table) > console.width:
        table.box, table.show_edge, table.padding = box.SIMPLE_HEAD, False, (0, 0)
    return table


OUTCOME_STYLE = {"ok": "green", "not_ok": "red", "incomplete": "yellow"}
"""How the CLI colours an outcome's word (the words: rig/results/outcome.py)."""


def outcome_markup(code: str | None) -> str:
    """The outcome's word (rig/results/outcome.py, the one vocabulary) in its colour, rich
    markup."""
    from rich.markup import escape

    from rig.results.outcome import outcome_word

    word = escape(outcome_word(code))
    style = OUTCOME_STYLE.get(code or "")
    return f"[{style}]{word}[/{style}]" if style else word


def print_outcome(out: Console, result: dict[str, Any]) -> None:
    """``outcome: WORD (what it means)`` and each cause on its own indented line."""
    from rich.markup import escape

    from rig.results.outcome import OUTCOME_MEANINGS

    code = result.get("outcome")
    meaning = OUTCOME_MEANINGS.get(code or "")
    out.print(f"outcome: {outcome_markup(code)}" + (f" ({meaning})" if meaning else ""))
    for cause in result.get("failures") or []:
        out.print(f"  {escape(cause)}")


def exit_code(code: str | None) -> int:
    """0 OK or NO LIMITS (nothing failed), 1 NOT OK, 2 INCOMPLETE (no verdict)."""
    return {"ok": 0, "no_limits": 0, "not_ok": 1}.get(code or "", 2)


@contextmanager
def exit_2_on_ctrl_c(out: Console, kept: str) -> Iterator[None]:
    """Ctrl-C (or SIGTERM) during a measurement: say that the rig is in its safe state and
    what is ``kept``, and exit 2."""
    import typer

    try:
        yield
    except KeyboardInterrupt:
        out.print(f"[red]interrupted: the rig is in its safe state; {kept}[/red]")
        raise typer.Exit(2) from None


@contextmanager
def progress_bar(out: Console, total_s: float) -> Iterator[Callable[[ProgressEvent], None]]:
    """A rich progress bar over the plan's estimated time (s); yields the engine's progress
    callback. A run's end, a fault, an abort, a pause are printed in colour, a completed
    run's figures below (:func:`print_run_figures`)."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    columns = (TextColumn("{task.description}"), BarColumn(),
               TextColumn("step {task.fields[step]}/{task.fields[n]}"), TimeRemainingColumn())
    with Progress(*columns, console=out, transient=False) as bar:
        task = bar.add_task("starting", total=max(total_s, 1e-3), step=0, n=0)

        def on_event(event: ProgressEvent) -> None:
            done = max(0.0, total_s - event.remaining_s)
            label = event.run_label or ""
            if event.kind == "step":
                bar.update(task, completed=done, step=event.step + 1, n=event.n_steps,
                           description=f"{label} {event.description}".strip()[:60])
            elif event.kind in ("run_finished", "fault", "abort", "estop", "paused",
                                "resumed"):
                style = "red" if event.kind in ("fault", "abort", "estop") else "green"
                bar.console.print(f"[{style}]{event.message}[/{style}]")
                print_run_figures(bar.console, event.data)
            elif event.kind == "finished":
                bar.update(task, completed=total_s if event.state == "completed" else done)

        yield on_event


def print_run_figures(out: Console, data: dict[str, Any]) -> None:
    """A completed run's figures (``run_finished`` event data): its outcome, lost motion,
    backlash and stiffness with their uncertainties, or a TE run's (:func:`print_te_figures`)."""
    if not data or data.get("status") != "completed":
        return
    if data.get("te_raw") is not None:
        print_te_figures(out, data)
        return

    from rig.results.outcome import below_zero_note, below_zero_text

    def f(key: str, unit: str, digits: int = 3) -> str:
        value = data.get(key)
        u = (data.get("uncertainty") or {}).get(key)
        if value is None:
            return "n/a"
        below = below_zero_text(key, value, u, f".{digits}f", f" {unit}")
        if below is not None:
            return below
        return (f"{value:.{digits}f}" + (f" ± {u:.{digits}f}" if u is not None else "")
                + f" {unit}")

    model = data.get("model") or {}
    m = model.get("lost_motion_arcmin")
    verdict = f"{outcome_markup(data['outcome'])}: " if data.get("outcome") else ""
    out.print(f"  {verdict}lost motion {f('lost_motion_arcmin', 'arcmin')}"
              + (f" (model {m:.3f})" if m is not None else "")
              + f", backlash {f('backlash_arcmin', 'arcmin')}, stiffness "
              f"{f('stiffness_Nm_per_arcmin', 'N·m/arcmin', 2)}")
    note = below_zero_note(data)
    if note is not None:
        out.print(f"  [yellow]{note}[/yellow]")


def print_te_figures(out: Console, data: dict[str, Any]) -> None:
    """A transmission error run's raw figures (rig/results/te_curve.py: nothing removed)."""
    raw = data.get("te_raw") or {}

    def f(key: str, unit: str) -> str:
        value = raw.get(key)
        return "n/a" if value is None else f"{value:.1f} {unit}"

    verdict = f"{outcome_markup(data['outcome'])}: " if data.get("outcome") else ""
    pp, u = data.get("te_pp_arcsec"), data.get("te_pp_arcsec_u")
    if pp is not None:
        hyst = data.get("te_hysteresis_arcmin")
        out.print(f"  {verdict}TE peak-to-peak {pp:.1f}" + (f" ± {u:.1f}" if u is not None else "")
                  + " arcsec (the run's analysis, docs/transmission-error.md)"
                  + (f", hysteresis {hyst:.3f} arcmin" if hyst is not None else ""))
        verdict = ""
    out.print(f"  {verdict}TE peak-to-peak (raw) {f('pp_arcsec', 'arcsec')}: forward "
              f"{f('pp_forward_arcsec', 'arcsec')}, reverse {f('pp_reverse_arcsec', 'arcsec')}"
              f"; hysteresis {f('hysteresis_arcmin', 'arcmin')}")
