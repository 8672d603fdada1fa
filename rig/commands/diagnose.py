"""``rig diagnose CAMPAIGN --json REPORT.json [--html REPORT.html]``: the sim-to-real gap."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape
from rich.table import Table

from rig.commands.options import in_range, json_option
from rig.core.ranges import ALPHA


def _candidates(report: dict[str, Any], rms_header: str, alarm_header: str,
                words: bool = True) -> Table:
    """The ranking of the report's candidates: every name and figure whole on one line, the
    cross-validation in words wrapped (the two headers given as they fit; ``words`` False:
    without those words, to measure the rest)."""
    table = Table(title="Candidates (held-out gap)")
    for col in ("effect", "shrink", rms_header, alarm_header, "ΔBIC", "cross-validation"):
        table.add_column(col, no_wrap=col != "cross-validation")
    for r in report["ranking"]:
        after = (r.get("gap_after") or {}).get("rms_arcsec")
        ev = r.get("evidence", {})
        fa = r.get("false_alarm_probability")
        shrink = r.get("shrink")
        table.add_row(escape(r["effect"]), "" if shrink is None else f"{shrink:.3f}",
                      "" if after is None else f"{after:.3f}",
                      "" if fa is None else f"{fa:.2g}", str(ev.get("delta_bic", "")),
                      escape(str(ev.get("cv", ev.get("from", "")))) if words else "")
    return table


def register(app: typer.Typer) -> None:
    @app.command(short_help="Where model and measurement disagree, and why.")
    def diagnose(
        campaign: Annotated[Path, typer.Argument(help="A campaign folder (or one run folder).")],
        json_file: json_option("Write the rig-diagnosis/1 report") = None,
        html_file: Annotated[
            Path | None, typer.Option("--html", help="Write the HTML report (self-contained).")
        ] = None,
        alpha: Annotated[
            float, typer.Option("--alpha", callback=in_range(ALPHA),
                                help="Level of every calibrated decision: an effect is called "
                                     "when its false-alarm probability is at most this.")
        ] = 0.01,
        self_check: Annotated[
            int, typer.Option("--self-check", min=0,
                              help="Diagnose N labelled campaigns made with this campaign's "
                                   "design (rig validate-diagnosis --like) and put the summary "
                                   "in the report (self_check).")
        ] = 0,
        jobs: Annotated[int, typer.Option("--jobs", min=1,
                                          help="Worker processes of the self-check.")] = 2,
    ) -> None:
        """Where model and measurement disagree, which unmodelled effect, how far it shrinks."""
        from rig.commands.output import JsonOutput, fit_table, make_console, natural_width
        from rig.results.diagnose import diagnose_path, report_dict

        json_out = JsonOutput(json_file)
        console = make_console(stderr=json_out.to_stdout)
        with console.status("diagnosing..."):
            camp, result = diagnose_path(campaign, alpha=alpha)
            report = report_dict(camp, result)
        if self_check:
            from rig.reports.diagnosis_html import self_check_words
            from rig.validate.like import self_check as run_self_check

            with console.status(f"self-check on {self_check} campaigns like this one..."):
                summary = run_self_check(camp, cases=self_check, jobs=jobs)
                # the per-case records stay with rig validate-diagnosis --like --json
                report["self_check"] = {k: v for k, v in summary.items() if k != "results"}
            console.print(self_check_words(report["self_check"]))
        console.print(f"[bold]verdict: {report['verdict']}[/bold] — {report['reason']}")
        if report.get("candidates"):
            console.print(f"candidates: {', '.join(report['candidates'])}")
        if report.get("next_experiment"):
            console.print(f"next experiment: {report['next_experiment']}")
        loc = report["localization"]
        console.print(f"where: {loc['where']} — {loc['detail']}")
        table = _candidates(report, "RMS after, arcsec", "false alarm")
        if natural_width(console, _candidates(report, "RMS after, arcsec", "false alarm",
                                              words=False)) > console.width:  # narrow
            table = _candidates(report, "RMS after,\narcsec", "false alarm")
        console.print(fit_table(console, table))
        console.print(f"gap before: {report['gap_before']['rms_arcsec']:.3f} arcsec RMS "
                      f"(noise {report['noise_arcsec']:.3f})")
        if json_file is not None:
            json_out.write(report, ensure_ascii=True)
            console.print(f"report written to {json_out.where}")
        if html_file is not None:
            from rig.reports.certificate.header import header_for_campaign
            from rig.reports.diagnosis_html import write_html

            write_html(report, result, html_file, header=header_for_campaign(camp))
            console.print(f"HTML report written to {html_file}")
