"""``rig version``: print the software version."""

from __future__ import annotations

import typer

from rig import __version__


def register(app: typer.Typer) -> None:
    @app.command()
    def version() -> None:
        """Print the backlash-rig version."""
        typer.echo(__version__)
