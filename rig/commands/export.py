"""``rig export RUN_OR_CAMPAIGN --format csv|parquet|mat|xlsx [--out PATH]``: a run's samples
and run.json, or a campaign's tidy results table, for other tools (rig/io/exporter.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from rig.commands.options import DEFAULT_STORE, RunOrCampaignArgument, SamplesOption, StoreOption


def register(app: typer.Typer) -> None:
    @app.command(short_help="Export a run or a campaign (csv, parquet, mat, xlsx).")
    def export(
        target: RunOrCampaignArgument,
        fmt: Annotated[str, typer.Option(
            "--format", help="csv (a rig-run/1 run folder; a campaign's table), parquet, "
            "mat (MATLAB) or xlsx (Excel).")],
        out: Annotated[Path | None, typer.Option(
            "--out", help="Where to write (default: RUN_ID[.EXT] or "
            "CAMPAIGN-results.EXT in the current folder).")] = None,
        force: Annotated[bool, typer.Option(
            "--force", help="Replace an existing --out (a file, or a run folder rig wrote).")
        ] = False,
        store: StoreOption = DEFAULT_STORE,
        samples: SamplesOption = None,
    ) -> None:
        """Export a run (samples and run.json) or a campaign (one row per run: conditions,
        metrics with uncertainties, model, limits, outcome). --store is read only when
        RUN_OR_CAMPAIGN is not a folder. Never writes into a store or a run folder; an
        existing --out only with --force; a failed write leaves the old file as it was."""
        from rig.io.exporter import export_campaign, export_run, resolve_target
        from rig.runformat import read_campaign, read_run

        path, is_campaign = resolve_target(target, store, samples)
        if is_campaign:
            campaign = read_campaign(path)
            written = export_campaign(campaign, fmt, out, force=force)
            typer.echo(f"campaign {campaign.name}: {len(campaign.runs)} runs -> {written}")
        else:
            run = read_run(path)
            written = export_run(run, fmt, out, force=force)
            typer.echo(f"run {run.run_id}: {run.n_samples} samples -> {written}")
