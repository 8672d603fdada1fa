"""The ``rig`` command line. Sub-commands live in :mod:`rig.commands`, one module each."""

from __future__ import annotations

import importlib
import pkgutil
import sys

import typer

from analysis.errors import AnalysisError
from drivers.errors import DeviceError
from rig.errors import RigError

app = typer.Typer(
    name="rig",
    help="backlash-rig: measure the lost motion of a gear reducer and compare it with the model.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


@app.callback()
def _root() -> None:
    """backlash-rig: measure the lost motion of a gear reducer and compare it with the model."""


def _register_commands() -> None:
    import rig.commands as pkg

    for info in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda i: i.name):
        module = importlib.import_module(f"{pkg.__name__}.{info.name}")
        register = getattr(module, "register", None)
        if register is not None:
            register(app)


_register_commands()


def main() -> None:
    """Entry point of the console script.

    Usage errors exit 2 (click's rule); the project's own errors (bad files, device faults,
    metrics that cannot be computed) are printed as one line on stderr and exit 2.
    """
    try:
        app()
    except (RigError, DeviceError, AnalysisError) as exc:
        print(f"rig: error: {exc}", file=sys.stderr)
        sys.exit(2)
