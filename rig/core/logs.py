"""Where the command line's log goes: everything, with tracebacks, to a log file; on the
terminal one line per warning of the rig's own code and nothing of the libraries'.

Outside-probe row 15 of issue 12: when the SLCAN link dropped or ``rig sim`` was killed,
python-can printed a ~30-line traceback on stderr above the rig's own one-line message. The
libraries (python-can, canopen, pymodbus, pyserial, asyncio) log to the file only; their
uncaught thread exceptions too. The file is ``$RIG_LOG_DIR/rig-YYYYMMDD.log`` (default
``~/.cache/backlash-rig/logs``), readable by its user only (mode 0600). No secret reaches it
or the terminal: every record is scrubbed of passwords in connection strings, ``PGPASSWORD``
and the operator token (:func:`rig.core.redact.redact_text`), a database URL's
``?password=...`` included (issue 21 item 5).
"""

from __future__ import annotations

import logging
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

from rig.core.redact import redact_text

__all__ = ["LIBRARY_LOGGERS", "configure_cli_logging", "log_dir", "write_private"]

LIBRARY_LOGGERS = ("can", "canopen", "pymodbus", "serial", "asyncio", "urllib3")


def log_dir() -> Path:
    """The folder of the rig's log files (created; the temporary folder if it cannot be)."""
    folder = Path(os.environ.get("RIG_LOG_DIR") or Path.home() / ".cache" / "backlash-rig"
                  / "logs")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        folder = Path(tempfile.gettempdir())
    return folder


def write_private(path: Path, text: str) -> None:
    """Write ``text`` to a new file only its user can read (0600, whatever the umask)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    os.fchmod(fd, 0o600)  # an existing file keeps its mode under O_CREAT
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(text)


def _private_file(path: Path) -> None:
    """Create ``path`` if missing and make it 0600 (the log handler then appends to it)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
    try:
        os.fchmod(fd, 0o600)
    finally:
        os.close(fd)


class _Redacted(logging.Formatter):
    """The log file's lines (traceback included) with every secret as ``***``."""

    def format(self, record: logging.LogRecord) -> str:
        return redact_text(super().format(record))


class _OneLine(logging.Formatter):
    """``rig: warning: message`` without the traceback (that is in the log file)."""

    def format(self, record: logging.LogRecord) -> str:
        text = record.getMessage().splitlines()[0] if record.getMessage() else ""
        return f"rig: {record.levelname.lower()}: {redact_text(text)}"


class _NotLibraries(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return record.name.split(".")[0] not in LIBRARY_LOGGERS


class _Once(logging.Filter):
    """Each kind of warning once on the terminal (the first 24 characters of its message):
    a lost device repeats "safe state not confirmed" from every thread that tried."""

    def __init__(self) -> None:
        super().__init__()
        self._seen: set[str] = set()

    def filter(self, record: logging.LogRecord) -> bool:
        key = record.getMessage()[:24]
        if key in self._seen:
            return False
        self._seen.add(key)
        return True


def configure_cli_logging() -> Path | None:
    """Install the file and terminal handlers once per process; the log file's path."""
    root = logging.getLogger()
    if any(getattr(h, "_rig_cli", False) for h in root.handlers):
        return None
    path = log_dir() / f"rig-{time.strftime('%Y%m%d')}.log"
    try:
        _private_file(path)
        file_handler: logging.Handler = logging.FileHandler(path, encoding="utf-8")
    except OSError:
        file_handler = logging.NullHandler()
    file_handler.setLevel(logging.INFO)
    file_handler.setFormatter(_Redacted(
        f"%(asctime)s {os.getpid()} %(levelname)s %(name)s: %(message)s"))
    terminal = logging.StreamHandler(sys.stderr)
    terminal.setLevel(logging.WARNING)
    terminal.setFormatter(_OneLine())
    terminal.addFilter(_NotLibraries())
    terminal.addFilter(_Once())
    for handler in (file_handler, terminal):
        handler._rig_cli = True  # type: ignore[attr-defined]
        root.addHandler(handler)
    root.setLevel(logging.INFO)
    threading.excepthook = _thread_exception_to_log
    return path


def _thread_exception_to_log(args: threading.ExceptHookArgs) -> None:
    """An exception that ends a library's thread (python-can's receive thread when the link
    drops) is logged with its traceback to the file; the driver reports the device."""
    if args.exc_type is SystemExit:
        return
    name = args.thread.name if args.thread is not None else "?"
    logging.getLogger("rig.threads").debug(
        "thread %s ended by %s", name, args.exc_type.__name__,
        exc_info=(args.exc_type, args.exc_value, args.exc_traceback))
    logging.getLogger("can.thread").error("thread %s ended: %s: %s", name,
                                          args.exc_type.__name__, args.exc_value)
