"""``rig rotor``: critical speeds of the seed 004 geared rotor beside the paper's Table 3."""

from __future__ import annotations

from typing import Annotated

import typer
from rich.table import Table

from rig.commands.options import in_range, json_option
from rig.commands.output import make_console
from rig.core.ranges import SHAFT_ELEMENTS, SHAFT_FRACTION


def register(app: typer.Typer) -> None:
    @app.command(short_help="Seed 004: rotor critical speeds, paper vs ours.")
    def rotor(
        json_file: json_option("Write all critical speeds as JSON") = None,
        disc_at: Annotated[
            float, typer.Option(callback=in_range(SHAFT_FRACTION),
                                help="Disc position, fraction of each shaft's length.")
        ] = 1.0 / 3.0,
        gear_at: Annotated[
            float, typer.Option(callback=in_range(SHAFT_FRACTION),
                                help="Gear position, fraction of each shaft's length.")
        ] = 2.0 / 3.0,
        elements: Annotated[int, typer.Option(
            callback=in_range(SHAFT_ELEMENTS), help="Shaft elements per rotor.")] = 24,
    ) -> None:
        """Seed 004 Table 3: single-rotor and coupled critical speeds (r/min), paper vs ours."""
        from analysis.models.seed004_paper import Assumptions, table3
        from rig.commands.output import JsonOutput

        json_out = JsonOutput(json_file)
        console = make_console(stderr=json_out.to_stdout)
        result = table3(Assumptions(disc_at=disc_at, gear_at=gear_at, elements=elements))
        table = Table(title="Seed 004 Table 3: critical speeds (r/min), paper vs ours")
        for col in ("", "paper", "ours", "difference", "%"):
            table.add_column(col, justify="left" if not col else "right")
        for label, paper, ours in result.rows + result.family_rows:
            table.add_row(label, f"{paper:.2f}", f"{ours:.2f}", f"{ours - paper:+.2f}",
                          f"{100 * (ours - paper) / paper:+.1f}")
        console.print(table)
        modes = Table(title="Coupled critical speeds (driving rotor's 1X line)")
        for col in ("r/min", "kind", "rotor", "waves", "torsion share", "forward fraction"):
            modes.add_column(col, justify="right")
        for c in result.coupled:
            modes.add_row(f"{c.speed_rpm:.2f}", c.kind, str(c.dominant_rotor + 1), f"{c.waves:g}",
                          f"{c.torsion_share:.3f}", f"{c.forward_fraction:.3f}")
        console.print(modes)
        mesh = result.mesh
        console.print(
            f"mesh: k_m = {mesh.mesh_stiffness_N_per_m:.4g} N/m (eps = {mesh.contact_ratio:.4f}),"
            f" c_m = {mesh.mesh_damping_Ns_per_m:.4g} N s/m; eq. (11) equivalent mass "
            f"{mesh.equivalent_mass_standard_kg:.4f} kg (printed form "
            f"{mesh.equivalent_mass_paper_kg:.4f} kg)"
        )
        console.print("[dim]assumptions: steel E 206 GPa, rho 7850 kg/m^3; bearings at the shaft "
                      f"ends; disc at {disc_at:.3f} L, gear at {gear_at:.3f} L; J_d = J_p / 2 "
                      "(docs/seed004.md)[/dim]")
        if json_file is not None:
            json_out.write(result.to_dict(), ensure_ascii=True)
            console.print(f"critical speeds written to {json_out.where}")
