"""The ``rig`` command line. Sub-commands live in :mod:`rig.commands`, one module each."""

from __future__ import annotations

import importlib
import os
import pkgutil
import signal
import sys
import time
import traceback
from pathlib import Path

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


def _register_commands(argv: list[str] | None = None) -> None:
    """Register the sub-commands of :mod:`rig.commands`.

    Each module is named after its command (``validate_diagnosis`` for ``validate-diagnosis``).
    When the command line names one, only that module is imported: the heavy numerics of the
    others (scipy, matplotlib) stay out of a command's start-up. ``rig --help`` imports all.
    """
    import rig.commands as pkg

    names = sorted(info.name for info in pkgutil.iter_modules(pkg.__path__))
    wanted = names
    if argv:
        first = next((arg for arg in argv if not arg.startswith("-")), None)
        if first is not None and first.replace("-", "_") in names:
            wanted = [first.replace("-", "_")]
    for name in wanted:
        module = importlib.import_module(f"{pkg.__name__}.{name}")
        register = getattr(module, "register", None)
        if register is not None:
            register(app)


# Started as the ``rig`` console script: import only the command asked for. Imported as a
# module (tests, scripts): every command is registered on ``app``.
_AS_SCRIPT = bool(sys.argv) and sys.argv[0].replace("\\", "/").rsplit("/", 1)[-1] == "rig"
_register_commands(sys.argv[1:] if _AS_SCRIPT else None)


def main() -> None:
    """Entry point of the console script.

    Usage errors exit 2 (click's rule); the project's own errors (bad files, device faults,
    metrics that cannot be computed) are printed as one line on stderr and exit 2.
    """
    signal.signal(signal.SIGTERM, _terminate_like_ctrl_c)
    from rig.logs import configure_cli_logging

    configure_cli_logging()
    try:
        app()
    except (RigError, DeviceError, AnalysisError) as exc:
        print(f"rig: error: {exc}", file=sys.stderr)
        sys.exit(2)
    except Exception as exc:  # a bug: one line, exit 2 (never 1, "a limit failed"), a log
        log_file = _write_crash_log()
        print(f"rig: internal error: {type(exc).__name__}: {exc} (a bug; the traceback is "
              f"in {log_file})", file=sys.stderr)
        sys.exit(2)


def _terminate_like_ctrl_c(signum: int, frame: object) -> None:
    """SIGTERM (a service manager, ``kill``) stops a measurement as Ctrl-C does: the rig goes
    to its safe state at once and the run and campaign are closed as aborted."""
    raise KeyboardInterrupt(f"signal {signum} (SIGTERM)")


def _write_crash_log() -> Path:
    """The current exception's traceback in ``$RIG_LOG_DIR`` (default
    ``~/.cache/backlash-rig/logs``, else the temporary folder); its path."""
    from rig.logs import log_dir

    folder = log_dir()
    stamp = time.strftime("%Y%m%dT%H%M%S")
    path = folder / f"rig-crash-{stamp}-{os.getpid()}.log"
    path.write_text(f"rig {' '.join(sys.argv[1:])}\n{traceback.format_exc()}",
                    encoding="utf-8")
    return path
