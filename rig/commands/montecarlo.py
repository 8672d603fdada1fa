"""``rig montecarlo``: seed 003's Monte Carlo of a 3-stage planetary train's transmission error.

Runs the three methods of the paper for its example (random errors, the maximum deviation
method, maximum deviation with random phases), ranks the error sources and names the
dominant spectral line (the report: :func:`rig.reports.montecarlo.montecarlo_report`), prints
the comparison with the paper and optionally writes JSON.
"""

from __future__ import annotations

from typing import Annotated, Any

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from analysis.models.seed003_montecarlo import PAPER_FIGURES_ARCSEC, check_sample_count
from analysis.models.seed003_planetary import PaperReading
from rig.commands.options import in_range, json_option
from rig.commands.output import make_console
from rig.core.errors import RigError
from rig.core.ranges import MONTE_CARLO_SAMPLES, SEED, WINDOW_REVS
from rig.reports.montecarlo import montecarlo_report

SIGNS = ("printed", "consistent")
PLANET_ROWS = ("E_A_f10", "E_f", "E_A")
SPEEDS = ("kinematic", "printed")


def _choice(value: str, allowed: tuple[str, ...], option: str) -> str:
    if value not in allowed:
        raise typer.BadParameter(
            f"must be one of {', '.join(allowed)}, got {value!r}", param_hint=option
        )
    return value


def _print_report(console: Console, report: dict[str, Any]) -> None:
    revs = report["window_output_revs"]
    table = Table(title=f"max |dtheta| over {revs:g} output revolution(s), arcsec")
    for column in ("method", "statistic", "paper", "ours", "difference"):
        table.add_column(column, justify="right" if column != "method" else "left")
    for method, figures in PAPER_FIGURES_ARCSEC.items():
        ours = report[method]
        for key, paper in figures.items():
            diff = 100.0 * (ours[key] - paper) / paper
            table.add_row(method, key, f"{paper:.0f}", f"{ours[key]:.1f}", f"{diff:+.1f} %")
    console.print(table)
    lines = report["spectrum"]
    console.print(
        f"dominant line: {lines['dominant_frequency_per_rev']:g} cycle/output rev, "
        f"{lines['dominant_amplitude_arcsec']:.1f} arcsec, "
        f"from {', '.join(lines['dominant_sources'])}"
    )
    ranking = Table(title="sensitivity: drop of the mean max |dtheta| without the source")
    for column in ("source", "description", "drop (arcsec)", "mean amplitude (arcsec)"):
        ranking.add_column(column)
    for item in report["sensitivity_ranking"][:8]:
        ranking.add_row(
            item["source"],
            item["description"],
            f"{item['mean_reduction_arcsec']:.1f}",
            f"{item['mean_amplitude_arcsec']:.1f}",
        )
    console.print(ranking)


def register(app: typer.Typer) -> None:
    @app.command(short_help="Seed 003: Monte Carlo TE of a planetary train.")
    def montecarlo(
        samples: Annotated[int, typer.Option(
            "--samples", "-n", callback=in_range(MONTE_CARLO_SAMPLES), help="Samples.")] = 50_000,
        seed: Annotated[int, typer.Option(
            "--seed", callback=in_range(SEED), help="Random seed.")] = 0,
        json_path: json_option("Write the report as JSON") = None,
        signs: Annotated[
            str, typer.Option("--signs", help="Table 1 signs: " + "|".join(SIGNS))
        ] = "printed",
        planet_row: Annotated[
            str, typer.Option("--planet-row", help="Table 2 row III p: " + "|".join(PLANET_ROWS))
        ] = "E_A_f10",
        planet_speed: Annotated[
            str, typer.Option("--planet-speed", help="Planet speed: " + "|".join(SPEEDS))
        ] = "kinematic",
        window_revs: Annotated[
            float, typer.Option("--window-revs", callback=in_range(WINDOW_REVS),
                                help="Output revolutions searched for the max.")
        ] = 1.0,
        quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress/tables.")] = False,
    ) -> None:
        """Seed 003: Monte Carlo transmission error of the paper's 3-stage planetary train."""
        reading = PaperReading(
            table1_signs=_choice(signs, SIGNS, "--signs"),  # type: ignore[arg-type]
            planet_speed=_choice(planet_speed, SPEEDS, "--planet-speed"),  # type: ignore[arg-type]
            stage3_planet_row=_choice(planet_row, PLANET_ROWS, "--planet-row"),  # type: ignore
        )
        check_sample_count(samples)
        from rig.commands.output import JsonOutput, json_to_stdout

        if (json_path is not None and not json_to_stdout(json_path)
                and not json_path.parent.is_dir()):
            raise RigError(f"{json_path}: cannot write the report: no directory {json_path.parent}")
        json_out = JsonOutput(json_path)
        console = make_console(stderr=True)
        if quiet:
            report = montecarlo_report(samples, seed, reading, window_revs=window_revs)
        else:
            columns = (
                TextColumn("{task.description}"),
                BarColumn(),
                MofNCompleteColumn(),
                TimeElapsedColumn(),
            )
            with Progress(*columns, console=console, transient=False) as progress:

                def tracker(label: str, total: int) -> Any:
                    task = progress.add_task(label, total=total)
                    return lambda done: progress.update(task, completed=done)

                report = montecarlo_report(samples, seed, reading, tracker, window_revs)
            _print_report(make_console(stderr=json_out.to_stdout), report)
        json_out.write(report)
