"""``rig batch UNIT.json``: lost motion a production batch of seed 000 pairs will show."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from rig.commands.options import in_range, json_option
from rig.commands.output import make_console
from rig.core.ranges import BAND_PCT, BATCH_UNITS, RATED_TORQUE_NM, SEED


def register(app: typer.Typer) -> None:
    @app.command(short_help="Monte Carlo lost motion of a batch of one design.")
    def batch(
        unit_file: Annotated[Path, typer.Argument(help="A unit JSON (or a whole run.json).")],
        samples: Annotated[int, typer.Option(
            "--samples", "-n", callback=in_range(BATCH_UNITS), help="Units sampled.")] = 20_000,
        seed: Annotated[int, typer.Option(callback=in_range(SEED), help="Random seed.")] = 0,
        compensate: Annotated[
            bool,
            typer.Option(help="Set each unit's eccentric distance by seed 000 eq. (9)."),
        ] = False,
        rated_torque: Annotated[float, typer.Option(
            callback=in_range(RATED_TORQUE_NM), help="Rated torque, N·m.")] = 10.0,
        percent: Annotated[float, typer.Option(
            callback=in_range(BAND_PCT), help="Lost-motion band, % of rated.")] = 3.0,
        json_file: json_option("Write the report as JSON") = None,
    ) -> None:
        """Monte Carlo lost motion of a batch built to this design within seed 000 Table 1.

        Seed 003's method (random errors within their tolerance grades) on the seed 000 pair:
        M value deviations, runouts with random phases, bearing clearances and the eccentric
        distance error; each unit's lost motion at its worst eccentric-shaft position.
        """
        from rig.commands.output import JsonOutput
        from rig.reports.batch import batch_report

        json_out = JsonOutput(json_file)
        report = batch_report(unit_file, samples=samples, seed=seed, compensate=compensate,
                              rated_torque_Nm=rated_torque, lost_motion_pct=percent)
        table = Table(
            title=f"Lost motion of {samples} units (±{percent:g} % of {rated_torque:g} N·m)"
        )
        for column in ("position", "mean", "std", "2.5 %", "median", "97.5 %", "max"):
            table.add_column(column, justify="right")
        for key, label in (
            ("worst_position_arcmin", "worst"),
            ("random_position_arcmin", "random"),
        ):
            row = report[key]
            table.add_row(
                label,
                *(f"{row[k]:.3f}'" for k in ("mean", "std", "p2_5", "median", "p97_5", "max")),
            )
        console = make_console(stderr=json_out.to_stdout)
        console.print(table)
        console.print(
            f"units that bind somewhere (play < 0): {100 * report['interference_fraction']:.1f} % "
            f"(deepest {report['interference_max_um']:.2f} um)"
        )
        json_out.write(report)
