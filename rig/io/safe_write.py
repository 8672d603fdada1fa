"""Where ``rig export`` and ``rig import --out`` may write, and writing there all or nothing.

- :func:`check_target`: the target's folder must exist and lie outside every store (a
  folder with ``index.sqlite``, or with both ``runs/`` and ``campaigns/``) and every run or
  campaign folder (one holding ``run.json`` or ``campaign.json``), symlinks resolved. An
  existing target, or a symlink, is refused unless ``force``; even then a folder is replaced
  only if it is empty or was written by rig (it holds :data:`MARKER`), never a run folder
  rig did not write, never through a symlink.
- :func:`atomic_file` / :func:`atomic_folder`: the content goes to a temporary name in the
  target's own folder, is synced, and is renamed into place. A write that fails (a full
  disk, a file size limit, a read-only folder) removes the temporary file and leaves the
  previous target as it was: one line, no partial file.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

from rig.core.durable import fsync_path
from rig.core.errors import RigError

__all__ = ["MARKER", "WriteTargetError", "atomic_file", "atomic_folder", "check_target"]

MARKER = ".rig-written"
"""The file rig leaves in a run folder it wrote (``rig export --format csv``, ``rig import
--out``): such a folder may be replaced with ``--force``; any other run folder may not."""

_STORE_INDEX = "index.sqlite"
_RUN_FILES = ("run.json", "campaign.json")


class WriteTargetError(RigError):
    """A target rig may not write to, or a write that failed (one line, exit 2)."""


def _guarded(folder: Path) -> str | None:
    """What ``folder`` is, when nothing may be written into it (a store, a run folder)."""
    if (folder / _STORE_INDEX).exists() or ((folder / "runs").is_dir()
                                             and (folder / "campaigns").is_dir()):
        return "a measurement store"
    for name in _RUN_FILES:
        if (folder / name).exists():
            return f"a {'run' if name == 'run.json' else 'campaign'} folder"
    return None


def check_target(out: Path, *, folder: bool, force: bool,
                 sources: Iterable[Path] = ()) -> Path:
    """``out`` if rig may write it (see the module doc): a file, or with ``folder`` a run
    folder; ``sources`` are the folders being read (never overwritten)."""
    text = str(out)
    if "\x00" in text or "\n" in text:
        raise WriteTargetError(f"{text!r}: a path cannot hold a NUL byte or a newline")
    parent = out.absolute().parent
    if not parent.is_dir():
        raise WriteTargetError(f"{out}: the folder {parent} does not exist (rig does not "
                               "create it)")
    real_parent = parent.resolve()
    for place in (real_parent, *real_parent.parents):
        what = _guarded(place)
        if what is not None:
            raise WriteTargetError(f"{out}: inside {what} ({place}); rig writes only outside "
                                   "stores and run folders: choose another --out")
    if out.is_symlink():
        if not force:
            raise WriteTargetError(f"{out}: is a symlink; not followed (--force replaces the "
                                   "link itself)")
        if folder:
            raise WriteTargetError(f"{out}: is a symlink; a run folder is never written "
                                   "through one")
        return out
    if not out.exists():
        return out
    if not force:
        raise WriteTargetError(f"{out}: exists; --force replaces it")
    real = out.resolve()
    if any(real == Path(s).resolve() for s in sources):
        raise WriteTargetError(f"{out}: is what is being read; choose another --out")
    if not folder:
        if not out.is_file():
            raise WriteTargetError(f"{out}: exists and is not a file; give a file name")
        return out
    if not out.is_dir():
        raise WriteTargetError(f"{out}: exists and is not a folder")
    what = _guarded(out)
    if what == "a measurement store" or (what is not None and not (out / MARKER).is_file()):
        raise WriteTargetError(f"{out}: is {what} rig did not write here; not replaced, even "
                               "with --force")
    if what is None and any(out.iterdir()):
        raise WriteTargetError(f"{out}: is a folder holding other files; not replaced")
    return out


def _failed(out: Path, exc: BaseException) -> WriteTargetError:
    reason = (exc.strerror or str(exc)) if isinstance(exc, OSError) else str(exc)
    reason = " ".join(str(reason).split()) or type(exc).__name__
    kept = "left as it was" if out.exists() else "not written"
    return WriteTargetError(f"{out}: cannot write ({reason}); {out.name} is {kept}")


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_file(out: Path) -> Iterator[Path]:
    """Yield a temporary path beside ``out``; on success sync it and rename it to ``out``,
    on any error remove it (``out`` untouched) and raise one line."""
    try:
        fd, name = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent)
    except OSError as exc:
        raise _failed(out, exc) from None
    os.close(fd)
    tmp = Path(name)
    os.chmod(tmp, 0o666 & ~_umask())  # as open() would make it (mkstemp makes 0600)
    try:
        yield tmp
        fsync_path(tmp)
        os.replace(tmp, out)
        fsync_path(out.absolute().parent)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(exc, WriteTargetError | KeyboardInterrupt | SystemExit):
            raise
        if isinstance(exc, RigError):
            raise
        raise _failed(out, exc) from None


@contextlib.contextmanager
def atomic_folder(out: Path) -> Iterator[Path]:
    """Yield a temporary folder beside ``out``; on success mark it (:data:`MARKER`) and put it
    in place of ``out`` (an existing ``out`` is moved aside first and removed after), on any
    error remove it (``out`` untouched) and raise one line."""
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
    except OSError as exc:
        raise _failed(out, exc) from None
    os.chmod(tmp, 0o777 & ~_umask())  # as mkdir would make it (mkdtemp makes 0700)
    old: Path | None = None
    try:
        yield tmp
        (tmp / MARKER).write_text("written by rig; rig may replace this folder (--force)\n")
        for child in tmp.iterdir():
            fsync_path(child)
        if out.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=out.parent))
            os.replace(out, old / out.name)
        try:
            os.replace(tmp, out)
        except OSError:
            if old is not None:
                os.replace(old / out.name, out)
            raise
        fsync_path(out.absolute().parent)
    except BaseException as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        if isinstance(exc, KeyboardInterrupt | SystemExit | RigError):
            raise
        raise _failed(out, exc) from None
    finally:
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
