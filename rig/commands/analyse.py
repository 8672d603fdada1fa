"""``rig analyse PATH``: loop metrics of a run or campaign beside the model's prediction."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.markup import escape
from rich.table import Table

from rig.commands.options import json_option
from rig.commands.output import make_console

if TYPE_CHECKING:
    from rig.results.analyse import RunAnalysis


def _num(value: Any, digits: int = 3) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


def significant(value: float, u: float | None = None, digits: int = 3) -> str:
    """``value`` with ``digits`` significant digits (``0.435``, ``12.3``), and ``± u`` with as
    many decimals, or more for a ``u`` that would round to nothing (one significant digit)."""
    if not math.isfinite(value):
        return str(value)
    magnitude = math.floor(math.log10(abs(value))) if value else 0
    decimals = max(0, digits - 1 - magnitude)
    if u is not None and math.isfinite(u) and u > 0:
        decimals = max(decimals, -math.floor(math.log10(u)))
    decimals = min(decimals, 9)
    text = f"{value:.{decimals}f}"
    if u is not None:
        text += f" ± {u:.{decimals}f}"
    return text


ROWS: tuple[tuple[str, str, str, float, Any], ...] = (
    # (metric key, label, unit, factor from the JSON key's unit, format)
    ("lost_motion_arcmin", "lost motion", "arcmin", 1.0, 3),
    ("backlash_arcmin", "backlash", "arcmin", 1.0, 3),
    ("stiffness_Nm_per_arcmin", "stiffness", "N·m/arcmin", 1.0, 2),
    ("loop_area_J", "loop area", "mJ", 1e3, significant),
    ("torque_offset_Nm", "torque offset", "N·m", 1.0, 4),
)
"""The table's rows per run. The loop area is shown in mJ with 3 significant digits: a loop of
the rated ±10 N·m encloses a few tenths of a millijoule, which in J and 4 decimals read
"0.0004 ± 0.0000"."""


def _cell(value: Any, u: Any, fmt: Any, factor: float, key: str = "") -> str:
    """``value ± u`` in the row's unit; a metric that cannot be negative measured below zero
    as rig/results/outcome.py ``below_zero_text`` words it (never as a figure)."""
    from rig.results.outcome import below_zero_text, finite_number

    if value is None:
        return "[red]n/a[/red]"
    u = None if u is None else u * factor
    if key and finite_number(value):
        below = below_zero_text(key, value * factor, u, f".{fmt}f" if isinstance(fmt, int)
                                else ".2g", "")
        if below is not None:
            return f"[yellow]{below}[/yellow]"
    if callable(fmt):
        return fmt(value * factor, u)
    return _num(value * factor, fmt) + ("" if u is None else f" ± {_num(u, fmt)}")


def _metric_table(title: str, model_header: str) -> Table:
    """The columns of both tables: run, metric, measured ± u, the model, unit."""
    table = Table(title=title)
    table.add_column("run", overflow="fold")
    table.add_column("metric", no_wrap=True)
    table.add_column("measured ± u", justify="right", no_wrap=True)
    table.add_column(model_header, justify="right", no_wrap=True)
    table.add_column("unit", no_wrap=True)
    return table


def _table(items: list[RunAnalysis]) -> Table:
    """One row per metric of each run (run, metric, measured ± standard uncertainty, the
    model's prediction, unit): narrow enough for an 80-column terminal with every header and
    figure whole (nine metric columns side by side cut them: "backl…")."""
    table = _metric_table(
        f"Hysteresis loop metrics (±{items[0].lost_motion_pct:g} % of rated torque)", "model")
    for item in items:
        d = item.to_dict()
        u = d.get("uncertainty") or {}
        m = d.get("model") or {}
        for i, (key, label, unit, factor, fmt) in enumerate(ROWS):
            model = m.get(key)
            table.add_row(
                escape(d["run_id"]) if i == 0 else "",
                label,
                _cell(d.get(key), u.get(key), fmt, factor, key),
                "" if model is None else _cell(model, None, fmt, factor),
                unit,
                end_section=i == len(ROWS) - 1,
            )
    return table


TE_ROWS: tuple[tuple[str, str, str], ...] = (
    ("te_pp_arcsec", "TE peak-to-peak", "arcsec"),
    ("te_pp_forward_arcsec", "  forward", "arcsec"),
    ("te_pp_reverse_arcsec", "  reverse", "arcsec"),
    ("te_total_Fi_arcsec", "F'i (ISO 1328)", "arcsec"),
    ("te_total_Fi_forward_arcsec", "  forward", "arcsec"),
    ("te_total_Fi_reverse_arcsec", "  reverse", "arcsec"),
    ("te_tooth_fi_arcsec", "f'i (ISO 1328)", "arcsec"),
    ("te_tooth_fi_short_wave_arcsec", "f_is (short-wave)", "arcsec"),
    ("te_hysteresis_arcmin", "hysteresis", "arcmin"),
)
"""The table's rows of a transmission error run."""


def _te_table(items: list[Any]) -> Table:
    """One row per TE figure (run, metric, measured ± u, model [band], unit), then the
    largest orders."""
    table = _metric_table("Transmission error", "model [band]")
    for item in items:
        d = item.to_dict()
        metrics, model = d["metrics"], d.get("model") or {}
        band = model.get("band") or {}
        rows = []
        for key, label, unit in TE_ROWS:
            value, u = metrics.get(key), metrics.get(f"{key}_u")
            cell = "[red]n/a[/red]" if value is None else significant(value, u)
            m = model.get(key)
            mcell = "" if m is None else significant(m)
            if key in band:
                mcell += f" [{band[key][0]:.3g}, {band[key][1]:.3g}]"
            rows.append((label, cell, mcell, unit))
        biggest = sorted((o for o in metrics["te_orders"] if o["direction"] == "forward"),
                         key=lambda o: -o["amplitude_arcsec"])[:4]
        for o in biggest:
            rows.append((f"order {o['order']:g}/{o['per']}",
                         f"{o['amplitude_arcsec']:.2f} ∠ {o['phase_deg']:.0f}°", "", "arcsec"))
        for i, (label, cell, mcell, unit) in enumerate(rows):
            table.add_row(escape(d["run_id"]) if i == 0 else "", label, cell, escape(mcell),
                          unit, end_section=i == len(rows) - 1)
    return table


def register(app: typer.Typer) -> None:
    @app.command(short_help="Loop metrics or TE figures of a run, with the model.")
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
        json_file: json_option("Write the metrics as JSON") = None,
        plot: Annotated[
            Path | None, typer.Option(help="Write the Fig. 6-style loop picture (PNG).")
        ] = None,
    ) -> None:
        """Compute lost motion, backlash, stiffness, loop area and torque offset, with the model;
        of a transmission error run, its TE figures, orders and the seeds' band."""
        from rig.commands.output import JsonOutput
        from rig.results.any_run import analyse_any_run
        from rig.results.outcome import below_zero_note
        from rig.results.te import TERunAnalysis
        from rig.runformat import is_campaign, read_run_or_campaign

        json_out = JsonOutput(json_file)
        console = make_console(stderr=json_out.to_stdout)
        campaign = read_run_or_campaign(path)
        every: list[Any] = [
            analyse_any_run(run, profile=profile, percent=percent, rated_torque_Nm=rated_torque,
                            hd_T1_Nm=hd_t1, hd_T2_Nm=hd_t2)
            for run in campaign.runs
        ]
        items = [i for i in every if not isinstance(i, TERunAnalysis)]
        te_items = [i for i in every if isinstance(i, TERunAnalysis)]
        if items:
            console.print(_table(items))
        if te_items:
            console.print(_te_table(te_items))
        for item in items:
            note = below_zero_note(item.to_dict())
            if note is not None:
                console.print(f"[yellow]{escape(item.run.run_id)}: {note}[/yellow]")
            for key, why in item.loop.errors.items():
                console.print(f"[yellow]{item.run.run_id}: {key}: {why}[/yellow]")
            for note in item.assumptions:
                console.print(f"[dim]{item.run.run_id}: assumed: {note}[/dim]")
        for item in te_items:
            for key, why in item.result.errors.items():
                console.print(f"[yellow]{escape(item.run.run_id)}: {key}: {escape(why)}[/yellow]")
            for note in item.assumptions + item.result.notes:
                console.print(f"[dim]{escape(item.run.run_id)}: {escape(note)}[/dim]")
            if item.comparison and item.comparison["flagged"]:
                console.print(f"[red]{escape(item.run.run_id)}: outside the model's band: "
                              f"{escape(', '.join(item.comparison['flagged']))}[/red]")
        single = not is_campaign(path)
        if json_file is not None:
            if single:
                payload: dict[str, Any] = every[0].to_dict()
            else:
                payload = {
                    "campaign": campaign.meta.get("name"),
                    "runs": [item.to_dict() for item in every],
                }
            json_out.write(payload, ensure_ascii=True)
            console.print(f"metrics written to {json_out.where}")
        if plot is not None:
            if items:
                from rig.reports.loop_plots import plot_loops

                title = None if single else f"Hysteresis loops: campaign {campaign.name}"
                plot_loops(items, plot, title=title)
                console.print(f"loop picture written to {plot}")
            else:
                from rig.reports.te_plots import plot_te

                plot_te(te_items[0], plot)
                console.print(f"TE picture written to {plot}")
