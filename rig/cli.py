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
from rig.core.errors import RigError
from rig.core.redact import redact_argv, redact_environment, redact_text

app = typer.Typer(
    name="rig",
    help="backlash-rig: measure the lost motion of a gear reducer and compare it with the model.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # click's plain help: rich's option table cuts long option names at 80 columns
    # ("--realtime-prior…"); click's wraps the help text and keeps every name whole
    rich_markup_mode=None,
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


def _started_as_command(argv0: str) -> bool:
    """Started as the ``rig`` console script, as ``python -m rig`` or as
    ``python -c "from rig.cli import main; main()" CMD`` (how the rig starts its own
    simulated devices, ``rig sim``): then the command line names the command."""
    path = argv0.replace("\\", "/")
    return path.rsplit("/", 1)[-1] == "rig" or path.endswith("rig/__main__.py") or path == "-c"


# Started as a command: import only the command asked for (1.8 s and 135 MB less for
# ``rig sim`` than importing them all). Imported as a module (tests, scripts): every command
# is registered on ``app``.
_AS_SCRIPT = bool(sys.argv) and _started_as_command(sys.argv[0])
_register_commands(sys.argv[1:] if _AS_SCRIPT else None)


def main() -> None:
    """Entry point of the console script.

    Usage errors exit 2 (click's rule); the project's own errors (bad files, device faults,
    metrics that cannot be computed) are printed as one line on stderr and exit 2.
    """
    signal.signal(signal.SIGTERM, _terminate_like_ctrl_c)
    from rig.core.logs import configure_cli_logging

    configure_cli_logging()
    try:
        code = app(standalone_mode=False)
    except typer.TyperException as exc:  # a usage error (click's, in typer): one line, exit 2
        if type(exc).__name__ == "NoArgsIsHelpError":  # `rig` alone: the help, as click does
            exc.show()
        else:
            print(usage_error_line(exc), file=sys.stderr)
        sys.exit(2)
    except typer.Abort:  # end of input at a prompt
        print("rig: error: aborted", file=sys.stderr)
        sys.exit(2)
    except (RigError, DeviceError, AnalysisError) as exc:
        print(f"rig: error: {redact_text(str(exc))}", file=sys.stderr)
        sys.exit(2)
    except Exception as exc:  # a bug: one line, exit 2 (never 1, "a limit failed"), a log
        log_file = _write_crash_log()
        print(f"rig: internal error: {type(exc).__name__}: {redact_text(str(exc))} (a bug; "
              f"the traceback is in {log_file})", file=sys.stderr)
        sys.exit(2)
    # click's non-standalone mode returns the code of ``typer.Exit`` (a command's own value
    # is None)
    sys.exit(code if isinstance(code, int) and not isinstance(code, bool) else 0)


def usage_error_line(exc: typer.TyperException) -> str:
    """click's error (an option without its value, a value out of range, an unknown command
    with the nearest names) as one line, with where the help is: ``rig: error: Invalid value
    for '--limit': ... (rig runs --help)``. click itself prints a usage line, a hint and the
    error, and typer frames them in a box: 5-6 lines."""
    format_message = getattr(exc, "format_message", None)
    text = format_message() if callable(format_message) else str(exc)
    message = " ".join(redact_text(text).split())
    ctx = getattr(exc, "ctx", None)
    where = f" ({ctx.command_path} --help)" if ctx is not None else ""
    return f"rig: error: {message}{where}"


def _terminate_like_ctrl_c(signum: int, frame: object) -> None:
    """SIGTERM (a service manager, ``kill``) stops a measurement as Ctrl-C does: the rig goes
    to its safe state at once and the run and campaign are closed as aborted."""
    raise KeyboardInterrupt(f"signal {signum} (SIGTERM)")


def _write_crash_log() -> Path:
    """The current exception's traceback in ``$RIG_LOG_DIR`` (default
    ``~/.cache/backlash-rig/logs``, else the temporary folder); its path. The file is the
    user's alone (mode 0600) and holds no secret: the command line, the rig's and libpq's
    environment variables and the traceback with every password and token as ``***``
    (rig/core/redact.py)."""
    from rig.core.logs import log_dir, write_private

    folder = log_dir()
    stamp = time.strftime("%Y%m%dT%H%M%S")
    path = folder / f"rig-crash-{stamp}-{os.getpid()}.log"
    env = "".join(f"{k}={v}\n" for k, v in redact_environment().items())
    text = (f"rig {' '.join(redact_argv(sys.argv[1:]))}\n{env}"
            f"{redact_text(traceback.format_exc())}")
    write_private(path, text)
    return path
