"""``rig model UNIT.json``: the seed 000 design chain and the reference nominal model of a unit;
for a ``cycloid`` or ``beveloid`` unit its kind's nominal model and production batch band, with
how the two relate (docs/unit-kinds.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.table import Table

from analysis.errors import AnalysisError
from analysis.models.seed000 import Seed000Design, design_chain, format_arcmin
from rig.commands.options import in_range, json_option
from rig.core.ranges import BAND_PCT, RATED_TORQUE_NM
from rig.runformat.unit_file import load_unit_mapping


def _mm(value: float | None, digits: int = 4) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


def _angle(value: float | None) -> str:
    return "—" if value is None else f"{value:.3f}  ({format_arcmin(value)})"


def _table(design: Seed000Design, path: Path) -> Table:
    d = design.to_dict()
    table = Table(title=f"Seed 000 model of {path.name}")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    table.add_column("paper form of eq. (15)", justify="right")
    shift = d["equivalent_shift_mm"]
    table.add_row("equivalent shift, ring / pinion (mm)",
                  f"{shift['internal']:+.4f} / {shift['external']:+.4f}", "")
    table.add_row("working pressure angle (deg)",
                  _mm(d["working_pressure_angle_deg"]["standard"], 3),
                  _mm(d["working_pressure_angle_deg"]["paper"], 3))
    table.add_row("zero-backlash center distance a' (mm)",
                  _mm(d["zero_backlash_center_distance_mm"]["standard"]),
                  _mm(d["zero_backlash_center_distance_mm"]["paper"]))
    table.add_row("eccentric distance to set a'' (eq. 9, mm)",
                  _mm(d["recommended_eccentric_distance_mm"]["standard"]),
                  _mm(d["recommended_eccentric_distance_mm"]["paper"]))
    fit = d["fit_check"]
    if fit:
        here = fit["at_center_distance"]
        table.add_row(f"at a = {design.unit.center_distance_mm:g} mm: margin (um)",
                      f"{here['standard']['margin_um']:+.1f} {here['standard']['verdict']}",
                      f"{here['paper']['margin_um']:+.1f} {here['paper']['verdict']}")
        other = fit.get("standard_form_at_paper_eccentric_distance")
        if other:
            table.add_row(
                f"standard form at the paper's a'' = {other['eccentric_distance_mm']:.4f} mm",
                f"{other['margin_um']:+.1f} um {other['verdict']}", "")
    for key, label in (("tooth_thickness", "eq. 2 tooth thickness"),
                       ("center_distance", "eq. 3 center distance"),
                       ("runout_worst_case", "eq. 7 runout, worst case"),
                       ("bearing_clearance_worst_case", "eq. 7 bearing clearance, worst case")):
        um = d["backlash_budget_um"][key]
        table.add_row(f"backlash: {label} (um / arcmin)",
                      "—" if um is None else
                      f"{um:.2f} / {d['backlash_budget_arcmin'][key]:.3f}", "")
    table.add_row("design lost motion, Table 3 (arcmin)",
                  _angle(d["design_lost_motion_arcmin"]), "")
    table.add_row("after eq. (9) compensation (arcmin)",
                  _angle(d["compensated_lost_motion_arcmin"]), "")
    table.add_row("nominal play, reference model (arcmin)", _angle(d["nominal_play_arcmin"]), "")
    stiffness = d["torsional_stiffness_Nm_per_arcmin"]
    table.add_row("torsional stiffness (N·m/arcmin)", _mm(stiffness, 2), "")
    table.add_row("eq. (4) period (crank revolutions)", str(d["center_distance_period_rev"]), "")
    return table


def kind_model(mapping: dict[str, Any], rated_torque_Nm: float, pct: float) -> dict[str, Any]:
    """The nominal model of a unit of another kind than the seed 000 pair (by_kind) and its
    batch band (:func:`rig.plans.campaign_file.batch_band`), as ``rig model --json`` writes
    them."""
    from analysis.models.by_kind import MODEL_NAMES, nominal_model_for_unit
    from rig.plans.campaign_file import batch_band

    kind = str(mapping.get("kind"))
    model, assumptions = nominal_model_for_unit(mapping, rated_torque_Nm)
    names = MODEL_NAMES.get(kind, (f"nominal model of kind {kind}", "the design's tolerances"))
    return {"kind": kind, "model_name": names[0], "band_source": names[1],
            "rated_torque_Nm": rated_torque_Nm, "lost_motion_pct": pct,
            "nominal": model.to_dict(),
            "lost_motion_arcmin": model.lost_motion_arcmin(rated_torque_Nm, pct),
            "batch": batch_band(mapping, rated_torque_Nm, pct), "assumptions": assumptions}


def _kind_table(doc: dict[str, Any], path: Path) -> Table:
    table = Table(title=f"Unit kind {doc['kind']}: {path.name}")
    table.add_column("quantity")
    table.add_column("value (arcmin)", justify="right")
    pct, rated = doc["lost_motion_pct"], doc["rated_torque_Nm"]
    table.add_row(f"nominal lost motion at +-{pct:g} % of {rated:g} N·m ({doc['model_name']})",
                  f"{doc['lost_motion_arcmin']:.3f}")
    nominal = doc["nominal"]
    if "play_min_arcmin" in nominal:
        table.add_row("nominal free play over the mesh phases (min .. max)",
                      f"{nominal['play_min_arcmin']:.3f} .. {nominal['play_max_arcmin']:.3f}")
    batch = doc["batch"]
    if batch:
        low, high = batch["band_95_arcmin"]
        table.add_row(f"production batch, worst position, 95 % ({doc['band_source']})",
                      f"{low:.3f} .. {high:.3f}")
        if batch.get("position_band_95_arcmin"):
            low, high = batch["position_band_95_arcmin"]
            table.add_row("production batch, one random position, 95 %",
                          f"{low:.3f} .. {high:.3f}")
    else:
        table.add_row("production batch", "none (the batch model cannot use this unit)")
    return table


def register(app: typer.Typer) -> None:
    @app.command(short_help="Seed 000 design chain and a unit's nominal model.")
    def model(
        unit_file: Annotated[Path, typer.Argument(help="unit JSON (or a whole run.json)")],
        json_out: json_option("Write the model as JSON") = None,
        rated_torque: Annotated[float, typer.Option(
            "--rated-torque", callback=in_range(RATED_TORQUE_NM),
            help="rated torque (N·m) of a cycloid or beveloid unit's lost "
            "motion and batch band")] = 10.0,
        pct: Annotated[float, typer.Option(
            "--pct", callback=in_range(BAND_PCT),
            help="lost motion at +-PCT % of the rated torque (cycloid, beveloid)")] = 3.0,
    ) -> None:
        """Seed 000 design chain (eqs. 1-16) and the reference nominal model of a gear unit;
        for a cycloid (seed 002) or beveloid (seed 001) unit its kind's nominal model and
        production batch band."""
        from rig.commands.output import JsonOutput

        out = JsonOutput(json_out)
        console = Console(stderr=out.to_stdout)
        mapping = load_unit_mapping(unit_file)
        if mapping.get("kind", "internal_involute") != "internal_involute":
            try:
                doc = kind_model(mapping, rated_torque, pct)
            except AnalysisError as exc:
                raise AnalysisError(f"{unit_file}: {exc}") from None
            console.print(_kind_table(doc, unit_file))
            if doc["batch"] and doc["batch"].get("nominal_relation"):
                console.print(f"nominal and band: {doc['batch']['nominal_relation']}")
            for note in doc["assumptions"]:
                console.print(f"[yellow]assumed:[/yellow] {note}")
            out.write(doc, ensure_ascii=True)
            return
        try:
            design = design_chain(mapping)
        except AnalysisError as exc:
            raise AnalysisError(f"{unit_file}: {exc}") from None
        console.print(_table(design, unit_file))
        for note in design.assumptions:
            console.print(f"[yellow]assumed:[/yellow] {note}")
        out.write(design.to_dict(), ensure_ascii=True)
