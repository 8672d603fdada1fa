"""``rig campaign run FILE``: a campaign (positions, amplitudes, temperatures, repeats) into a
rig-campaign/1 folder of the store, with pass/fail against the file's limits.

Exit codes: 0 every limit passed (outcome OK, or NO LIMITS when none was set), 1 a limit
failed (NOT OK, also when the campaign was then aborted), 2 an error or an incomplete
campaign (bad file, device fault, an aborted campaign, a limited metric that could not be
measured).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape
from rich.table import Table

from rig.commands.options import DEFAULT_STORE, SamplesOption, StoreOption, json_option
from rig.commands.output import (
    console,
    exit_2_on_ctrl_c,
    exit_code,
    outcome_markup,
    print_outcome,
    progress_bar,
    write_json,
)


def _summary_table(result: dict[str, Any]) -> Table:
    table = Table(title=f"Campaign {result['campaign']} ({result['status']})")
    for name in ("run", "input angle\ndeg", "lost motion\narcmin", "backlash\narcmin",
                 "stiffness\nN·m/arcmin", "status", "outcome"):
        table.add_column(name, justify="left" if name in ("run", "status", "outcome")
                         else "right")
    for r in result["runs"]:
        u = r.get("uncertainty") or {}

        def f(key: str, digits: int = 3, r=r, u=u) -> str:
            v = r.get(key)
            if v is None:
                return "n/a"
            return f"{v:.{digits}f}" + (f" ± {u[key]:.{digits}f}" if u.get(key) else "")

        angle = r.get("input_angle_deg")
        table.add_row(r.get("label") or r["run_id"], "" if angle is None else f"{angle:g}",
                      f("lost_motion_arcmin"), f("backlash_arcmin"),
                      f("stiffness_Nm_per_arcmin", 2), r["status"],
                      outcome_markup(r.get("outcome")))
    return table


def register(app: typer.Typer) -> None:
    campaign_app = typer.Typer(help="Measurement campaigns (TOML files, docs/campaigns.md).",
                               no_args_is_help=True, rich_markup_mode=None)
    app.add_typer(campaign_app, name="campaign")

    @campaign_app.command("run", short_help="Run a campaign into the store.")
    def run(
        file: Annotated[Path, typer.Argument(help="Campaign file (TOML).")],
        simulated: Annotated[bool, typer.Option(
            "--simulated", help="Start the simulated rig (its own process) with the "
            "campaign's unit for the duration.")] = False,
        rig: Annotated[Path | None, typer.Option(
            "--rig", help="Rig configuration (TOML) of real or simulated device addresses.")
        ] = None,
        store: StoreOption = DEFAULT_STORE,
        samples: SamplesOption = None,
        json_file: json_option(
            "Write the per-run metrics and the campaign summary as JSON") = None,
        preview: Annotated[bool, typer.Option(
            "--preview", help="List the plan's steps and its duration; measure nothing.")
        ] = False,
        confirm_long: Annotated[bool, typer.Option(
            "--confirm-long", help="Run (or preview) a campaign expected to take longer than "
            "8 h (at most 30 days); or the file's confirm_long = true.")] = False,
    ) -> None:
        """Run a campaign; write its runs and campaign.json under the store's campaigns/."""
        from rig.core.errors import RigError
        from rig.measurement.service import open_session, plant_config_for, run_campaign
        from rig.plans.campaign_file import load_campaign
        from rig.plans.diagnosability import design_effects
        from rig.plans.estimate import check_duration, estimate
        from rig.store import Store

        out = console()
        camp = load_campaign(file)
        plan = camp.build_plan()
        est = estimate(plan.steps())
        check_duration(est, confirmed=confirm_long or camp.confirm_long,
                       how=f"--confirm-long (or confirm_long = true in {camp.source})")
        effects = design_effects(camp)  # what the diagnosis can test, said before measuring
        if preview:
            for line in plan.listing():
                out.print(line, highlight=False)
            out.print(f"{est.n_steps} steps, {est.n_runs} runs, about {est.total_s:.1f} s "
                      f"({est.dwell_s:.1f} s dwelling)")
            for line in effects.lines() if effects else []:
                out.print(line, highlight=False, markup=False, soft_wrap=True)
            return
        plant_cfg = plant_config_for(camp.unit_data(), camp.simulation, camp.source) \
            if simulated else None
        st = Store(store, samples=samples)
        st.check_writable("a campaign")  # said before the rig starts
        out.print(f"campaign {camp.name}: {est.n_runs} runs, about {est.total_s:.0f} s")
        for line in effects.lines() if effects else []:
            out.print(line, highlight=False, markup=False, soft_wrap=True)
        with open_session(rig=rig, simulated=simulated, plant=plant_cfg) as session, \
                progress_bar(out, est.total_s) as on_event, \
                exit_2_on_ctrl_c(out, "the runs are kept"):
            result = run_campaign(camp, session, st, progress=on_event)
        if effects is not None:
            result["diagnosis_design"] = effects.to_dict()
        write_json(json_file, result)
        out.print(_summary_table(result))
        lm = result["lost_motion_arcmin"]
        if lm["mean"] is not None:
            out.print(f"lost motion over {lm['n']} runs: mean {lm['mean']:.3f}, min "
                      f"{lm['min']:.3f}, max {lm['max']:.3f}, std {lm['std']:.3f} arcmin")
        sig = result.get("runout_signature")
        if sig:
            out.print(f"runout signature (once per input revolution): amplitude "
                      f"{sig['amplitude']:.3f} arcmin at {sig['phase_deg']:.0f} deg, "
                      f"residual {sig['residual_rms']:.3f} arcmin")
        from analysis.models.by_kind import MODEL_NAMES

        kind = result.get("unit_kind") or "internal_involute"
        model_name, band_source = MODEL_NAMES.get(kind, (kind, "the design's tolerances"))
        model = result.get("model") or {}
        if model.get("lost_motion_arcmin") is not None:
            out.print(f"unit kind {kind}; model ({model_name}): lost motion "
                      f"{model['lost_motion_arcmin']:.3f} arcmin")
        batch = result.get("batch") or {}
        band = batch.get("band_95_arcmin")
        if band:
            out.print(f"production batch of this design ({band_source}, 95 %): "
                      f"{band[0]:.3f} .. {band[1]:.3f} arcmin")
        advice = batch.get("advice") or {}
        if advice.get("band_95_arcmin"):
            what = (f"rotation modification Delta2 = {advice['rotation_modification_mm']:.4f} mm"
                    if "rotation_modification_mm" in advice
                    else f"gear axial position {advice['axial_shift_mm']:+.3f} mm")
            low, high = advice["band_95_arcmin"]
            out.print(f"compensation advice: {what} gives {low:.3f} .. {high:.3f} arcmin "
                      f"({100 * advice['binding_fraction']:.1f} % of units binding)")
        out.print(f"campaign folder: {result['path']}")
        if result["status"] != "completed":
            out.print(f"[red]campaign aborted: {escape(str(result['reason']))}[/red]")
            print_outcome(out, result)
            raise typer.Exit(1 if result["outcome"] == "not_ok" else 2)
        if not result["passed"] and not result["failures"]:
            raise RigError("campaign failed without a cause (a bug)")
        print_outcome(out, result)
        raise typer.Exit(exit_code(result["outcome"]))
