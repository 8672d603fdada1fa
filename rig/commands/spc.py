"""``rig spc``: the production quality view of a store (control charts, rules, Cp/Cpk)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from rig.commands.options import DEFAULT_STORE, SamplesOption, StoreOption, json_option


def register(app: typer.Typer) -> None:
    @app.command(short_help="Control charts and Cp/Cpk of each design over time.")
    def spc(
        store: StoreOption = DEFAULT_STORE,
        samples: SamplesOption = None,
        design: Annotated[str | None, typer.Option(
            "--design", help="Only units of this design (run.json unit.design, else "
            "unit.model, else the name made of its gear data that the output shows; or the "
            "label or design key of one build of it).")] = None,
        since: Annotated[str | None, typer.Option(
            "--since", help="Only tests started on or after this UTC date/time "
            "(ISO 8601, e.g. 2026-11-01).")] = None,
        html: Annotated[Path | None, typer.Option(
            "--html", help="Write the charts as an HTML page.")] = None,
        json_file: json_option("Write every figure as JSON") = None,
    ) -> None:
        """Lost motion, backlash and stiffness per unit over time: individuals/moving-range
        charts with control limits (one-sided, LCL 0, where centre - 3 sigma < 0), the
        Western Electric rules, Cp/Cpk against each unit's own campaign limits and the seed
        000 batch band of the design (docs/deployment.md)."""
        from rich.markup import escape
        from rich.table import Table

        from rig.commands.output import JsonOutput, fit_table, make_console
        from rig.core.errors import RigError
        from rig.reports.spc import spc_report
        from rig.reports.spc.html import render_html
        from rig.store import Store

        st = Store(store, create=False, samples=samples)
        try:
            doc = spc_report(st, design=design, since=since)
        except ValueError as exc:
            raise RigError(str(exc)) from exc
        json_out = JsonOutput(json_file)
        json_out.write(doc)
        if html is not None:
            html.write_text(render_html(doc), encoding="utf-8")
            typer.echo(f"charts written to {html}", err=json_out.to_stdout)
        if json_out.to_stdout:
            return
        out = make_console()

        def f(value: float | None) -> str:
            return "" if value is None else f"{value:.4g}"

        for e in doc["excluded"]:
            out.print(f"left out of the charts: run {escape(e['run_id'])} (unit "
                      f"{escape(str(e['unit_serial'] or 'not recorded'))}): "
                      f"{escape(e['reason'])}")
        if not doc["designs"]:
            out.print(f"no completed runs in {st.location}"
                      + (f" of design {design}" if design else ""))
        for d in doc["designs"]:
            table = Table(title=f"design {d['design']}: {d['n_tests']} unit tests, "
                                f"{d['n_runs']} runs")
            for col in ("metric", "n", "mean", "LCL", "UCL", "MR̄", "Cpk", "signals"):
                table.add_column(col, justify="left" if col == "metric" else "right",
                                 no_wrap=col != "LCL")  # names and figures whole
            no_chart = []
            for name, m in d["metrics"].items():
                if m["chart"] is None:  # why: under the table, where it has the whole width
                    table.add_row(escape(name), "", "no chart", "", "", "", "", "")
                    no_chart.append(f"  {escape(name)}: no chart: {escape(m['error'])}")
                    continue
                c, cap = m["chart"], m["capability"]
                lcl = f(c["individuals"]["lcl"]) + (
                    " (one-sided)" if c["individuals"].get("lcl_clipped") else "")
                table.add_row(name, str(cap["n"]), f(c["individuals"]["centre"]),
                              lcl, f(c["individuals"]["ucl"]),
                              f(c["moving_range"]["centre"]), f(cap["cpk"]),
                              str(len(c["violations"])))
            out.print(fit_table(out, table))
            for line in no_chart:
                out.print(line)
