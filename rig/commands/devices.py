"""``rig devices``: connect to every device of a rig configuration and report its health."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from rig.commands.options import json_option
from rig.commands.output import make_console


def _fmt(value: float | None, digits: int = 6) -> str:
    return "" if value is None else f"{value:.{digits}g}"


def _table(reports: list, title: str) -> Table:
    from rig.hardware.device_check import DeviceReport

    table = Table(title=title)
    for column in ("device", "samples", "rate Hz", "expected Hz", "lost", "late", "last",
                   "errors"):
        table.add_column(column, justify="right" if column not in ("device", "errors")
                         else "left", overflow="fold")
    rep: DeviceReport
    for rep in reports:
        errors = "; ".join(f"{m} (x{n})" if n > 1 else m for m, n in rep.errors.items())
        style = "green" if rep.healthy else "red"
        table.add_row(f"[{style}]{rep.name}[/{style}]\n{rep.device}", str(rep.samples),
                      f"{rep.rate_Hz:.1f}", _fmt(rep.expected_rate_Hz, 4), str(rep.lost),
                      str(rep.late), f"{_fmt(rep.last)} {rep.unit}".strip(),
                      f"[red]{errors}[/red]" if errors else "[green]none[/green]")
    return table


def register(app: typer.Typer) -> None:
    @app.command(short_help="Connect to a rig's devices and report each one.")
    def devices(
        rig_file: Annotated[Path, typer.Option("--rig", help="Rig configuration (TOML).")],
        seconds: Annotated[float, typer.Option(min=0.1, help="How long to read, s.")] = 5.0,
        json_file: json_option("Also write the report as JSON") = None,
    ) -> None:
        """Connect to every device of a rig, read for a while and report each one.

        Exit 0 when every device is healthy, 1 when one has errors, 2 on a bad configuration.
        """
        from rig.commands.output import JsonOutput
        from rig.hardware.config import RigConfigError, load_rig_config
        from rig.hardware.device_check import check_devices
        from rig.reports.devices import devices_report

        err = make_console(stderr=True)
        try:
            config = load_rig_config(rig_file)
        except RigConfigError as exc:
            for line in str(exc).splitlines():
                print(f"rig: error: {line}", file=sys.stderr)
            raise typer.Exit(2) from exc
        with err.status(f"reading {len(config.device_names())} devices for {seconds:g} s"):
            reports = check_devices(config, seconds)
        doc = devices_report(config, rig_file, seconds, reports)
        json_out = JsonOutput(json_file)
        console = make_console(stderr=json_out.to_stdout)
        console.print(_table(reports, f"Devices of rig {config.rig.rig_id} ({rig_file}), "
                                      f"{seconds:g} s"))
        json_out.write(doc, ensure_ascii=True)
        raise typer.Exit(0 if doc["healthy"] else 1)
