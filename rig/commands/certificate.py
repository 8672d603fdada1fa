"""``rig certificate RUN_OR_CAMPAIGN --pdf FILE [--html FILE]``: the unit's test certificate."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from rig.commands.options import DEFAULT_STORE, RunOrCampaignArgument, SamplesOption, StoreOption


def register(app: typer.Typer) -> None:
    @app.command(short_help="The test certificate of a run or campaign.")
    def certificate(
        target: RunOrCampaignArgument,
        pdf: Annotated[Path | None, typer.Option(
            "--pdf", help="Write the certificate as PDF (one A4 page).")] = None,
        html: Annotated[Path | None, typer.Option(
            "--html", help="Write the certificate as HTML (self-contained).")] = None,
        store: StoreOption = DEFAULT_STORE,
        samples: SamplesOption = None,
    ) -> None:
        """The test certificate of a unit from a stored run or campaign: unit, serial,
        operator, date, rig, software, sensors and calibration, the loop, the metrics with
        their uncertainties against the limits, OK / NOT OK / INCOMPLETE / NO LIMITS; for a
        campaign the lost motion against position with the batch band and the diagnosis
        verdict if one was made. --store is read only when RUN_OR_CAMPAIGN is not a folder."""
        from rig.reports.certificate import CertificateError, resolve_subject, write_certificate

        if pdf is None and html is None:
            raise CertificateError("give --pdf FILE and/or --html FILE: nothing to write")
        for option, path in (("--pdf", pdf), ("--html", html)):
            # refused before any work, and nothing made: a mistyped folder is not created
            if path is not None and not path.parent.is_dir():
                raise CertificateError(f"{option} {path}: no folder {path.parent} (make it "
                                       "first, or give an existing one)")
        subject = resolve_subject(target, store, samples)
        context = write_certificate(subject, pdf=pdf, html=html)
        header = context["header"]
        typer.echo(f"certificate of {header['subject']} (unit {header['serial']}): "
                   f"{context['outcome_word']}")
        for path in (pdf, html):
            if path is not None:
                typer.echo(f"written to {path}")
