"""``rig te-calibrate RUN_A RUN_B``: the output encoder's mounting eccentricity by reversal
(docs/transmission-error.md): two TE runs of one unit, the second with the coupling between
the output and the encoder indexed by 180 deg; prints the ``[calibration.encoder]`` keys."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from rig.commands.options import in_range, json_option
from rig.commands.output import make_console
from rig.core.ranges import INDEX_DEG


def register(app: typer.Typer) -> None:
    @app.command("te-calibrate", short_help="Remove the output encoder's eccentricity from TE.")
    def te_calibrate(
        run_a: Annotated[Path, typer.Argument(help="TE run, coupling as mounted.")],
        run_b: Annotated[Path, typer.Argument(help="TE run, coupling indexed by 180 deg.")],
        json_file: json_option("Write the result as JSON") = None,
        indexed_by: Annotated[float | None, typer.Option(
            "--indexed-by", callback=in_range(INDEX_DEG),
            help="How far RUN_B's coupling is indexed against RUN_A's (deg; "
            "must be 180), for runs that do not record test.coupling_index_deg.")] = None,
    ) -> None:
        """Separate the output encoder's once-per-turn eccentricity from the unit's own TE by
        the reversal of two runs; print the rig configuration lines that remove it."""
        from rig.commands.output import JsonOutput
        from rig.results.te import reversal_calibration
        from rig.runformat import read_run

        json_out = JsonOutput(json_file)
        console = make_console(stderr=json_out.to_stdout)
        cal = reversal_calibration(read_run(run_a), read_run(run_b), indexed_by_deg=indexed_by)
        console.print(f"encoder eccentricity {cal['eccentricity_arcsec']:.2f} ± "
                      f"{cal['eccentricity_u_arcsec']:.2f} arcsec at "
                      f"{cal['eccentricity_phase_deg']:.1f} deg (A cos(theta + p)); the unit's "
                      f"own once-per-output-turn TE {cal['unit_order1_arcsec']:.2f} arcsec")
        console.print("add to the output encoder's table of the rig configuration:",
                      highlight=False)
        console.print("[calibration.encoder]\n"
                      f"eccentricity_arcsec = {cal['eccentricity_arcsec']:.3f}\n"
                      f"eccentricity_phase_deg = {cal['eccentricity_phase_deg']:.2f}\n"
                      f"eccentricity_u_arcsec = {cal['eccentricity_u_arcsec']:.3f}",
                      highlight=False, markup=False)
        if json_file is not None:
            json_out.write(cal, ensure_ascii=True)
