"""``rig validate-diagnosis [--cases N] [--seed S]``: the diagnosis on withheld effects."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.progress import Progress
from rich.table import Table

console = Console()


def register(app: typer.Typer) -> None:
    @app.command("validate-diagnosis")
    def validate_diagnosis(
        cases: Annotated[int, typer.Option(min=1, help="Number of simulated campaigns.")] = 33,
        seed: Annotated[int, typer.Option(help="Seed of the case draws.")] = 0,
        json_file: Annotated[
            Path | None, typer.Option("--json", help="Write the summary as JSON.")
        ] = None,
    ) -> None:
        """Generate campaigns with one effect withheld (plus null and out-of-vocabulary cases),
        diagnose them blind, print the confusion matrix and the four figures."""
        from rig.validate import KINDS, iter_validation, meets_targets, summarise

        results = []
        with Progress(console=console) as progress:
            task = progress.add_task("diagnosing campaigns", total=cases)
            for res in iter_validation(cases, seed):
                results.append(res)
                progress.advance(task)
        summary = summarise(results)
        verdicts = sorted({r.verdict for r in results})
        table = Table(title="Confusion matrix (true effect -> verdict)")
        table.add_column("true")
        for v in verdicts:
            table.add_column(v, justify="right")
        for kind in KINDS:
            row = summary["confusion"].get(kind)
            if row:
                table.add_row(kind, *[str(row.get(v, "")) for v in verdicts])
        console.print(table)

        def pct(x: float | None) -> str:
            return "n/a" if x is None else f"{x:.1%}"

        console.print(f"correct verdicts (in vocabulary + null): {pct(summary['correct_share'])}"
                      " (target >= 95 %)")
        console.print(f"false alarms on null cases: {pct(summary['false_alarm_share'])}"
                      " (target <= 5 %)")
        console.print("out-of-vocabulary called unexplained/ambiguous: "
                      f"{pct(summary['oov_unexplained_or_ambiguous_share'])} (target >= 80 %)")
        ms = summary["median_shrink"]
        console.print(f"median held-out shrink: {'n/a' if ms is None else f'{ms:.3f}'}"
                      " (target >= 0.7)")
        console.print(f"mean diagnosis time per case: {summary['seconds_per_case']:.2f} s")
        console.print("targets met" if meets_targets(summary) else "[red]targets NOT met[/red]")
        if json_file is not None:
            json_file.parent.mkdir(parents=True, exist_ok=True)
            json_file.write_text(json.dumps(summary, indent=2) + "\n")
