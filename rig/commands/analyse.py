"""``rig analyse PATH``: loop metrics of a run or campaign beside the model's prediction."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.console import Console
from rich.table import Table

from rig.json_files import finite_for_json

if TYPE_CHECKING:
    from rig.analyse import RunAnalysis

console = Console()


def _num(value: Any, digits: int = 3) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


def _table(items: list[RunAnalysis]) -> Table:
    table = Table(
        title=f"Hysteresis loop metrics (±{items[0].lost_motion_pct:g} % of rated torque)"
    )
    table.add_column("run")
    table.add_column("lost motion\narcmin", justify="right")
    table.add_column("model\narcmin", justify="right")
    table.add_column("backlash\narcmin", justify="right")
    table.add_column("model\narcmin", justify="right")
    table.add_column("stiffness\nN·m/arcmin", justify="right")
    table.add_column("model\nN·m/arcmin", justify="right")
    table.add_column("loop area\nJ", justify="right")
    table.add_column("T offset\nN·m", justify="right")
    for item in items:
        d = item.to_dict()
        u = d.get("uncertainty", {})
        m = d.get("model") or {}

        def with_u(key: str, digits: int = 3, d=d, u=u) -> str:
            if d.get(key) is None:
                return "[red]n/a[/red]"
            text = _num(d[key], digits)
            if u.get(key) is not None:
                text += f" ± {_num(u[key], digits)}"
            return text

        table.add_row(
            d["run_id"],
            with_u("lost_motion_arcmin"),
            _num(m.get("lost_motion_arcmin")),
            with_u("backlash_arcmin"),
            _num(m.get("backlash_arcmin")),
            with_u("stiffness_Nm_per_arcmin", 2),
            _num(m.get("stiffness_Nm_per_arcmin"), 2),
            with_u("loop_area_J", 4),
            with_u("torque_offset_Nm", 4),
        )
    return table


def register(app: typer.Typer) -> None:
    @app.command()
    def analyse(
        path: Annotated[
            Path, typer.Argument(help="A run folder, run.json, bare CSV, or campaign folder.")
        ],
        profile: Annotated[
            str, typer.Option(help="Lost-motion band: nabtesco (±3 %) or harmonic-drive (±4 %).")
        ] = "nabtesco",
        percent: Annotated[
            float | None, typer.Option(help="Custom lost-motion band in percent of rated torque.")
        ] = None,
        rated_torque: Annotated[
            float | None,
            typer.Option(help="Rated torque in N·m (overrides run.json test.rated_torque_Nm)."),
        ] = None,
        hd_t1: Annotated[
            float | None, typer.Option(help="Harmonic Drive T1 (N·m) for K1/K2/K3.")
        ] = None,
        hd_t2: Annotated[
            float | None, typer.Option(help="Harmonic Drive T2 (N·m) for K1/K2/K3.")
        ] = None,
        json_file: Annotated[
            Path | None, typer.Option("--json", help="Write the metrics as JSON.")
        ] = None,
        plot: Annotated[
            Path | None, typer.Option(help="Write the Fig. 6-style loop picture (PNG).")
        ] = None,
    ) -> None:
        """Compute lost motion, backlash, stiffness, loop area and torque offset, with the model."""
        from rig.analyse import analyse_run
        from rig.runformat import is_campaign, read_run_or_campaign

        campaign = read_run_or_campaign(path)
        items = [
            analyse_run(
                run,
                profile=profile,
                percent=percent,
                rated_torque_Nm=rated_torque,
                hd_T1_Nm=hd_t1,
                hd_T2_Nm=hd_t2,
            )
            for run in campaign.runs
        ]
        console.print(_table(items))
        for item in items:
            for key, why in item.loop.errors.items():
                console.print(f"[yellow]{item.run.run_id}: {key}: {why}[/yellow]")
            for note in item.assumptions:
                console.print(f"[dim]{item.run.run_id}: assumed: {note}[/dim]")
        single = not is_campaign(path)
        if json_file is not None:
            if single:
                payload: dict[str, Any] = items[0].to_dict()
            else:
                payload = {
                    "campaign": campaign.meta.get("name"),
                    "runs": [item.to_dict() for item in items],
                }
            json_file.parent.mkdir(parents=True, exist_ok=True)
            text = json.dumps(finite_for_json(payload), indent=2, allow_nan=False)
            json_file.write_text(text + "\n")
            console.print(f"metrics written to {json_file}")
        if plot is not None:
            from rig.plots import plot_loops

            title = None if single else f"Hysteresis loops: campaign {campaign.name}"
            plot_loops(items, plot, title=title)
            console.print(f"loop picture written to {plot}")
