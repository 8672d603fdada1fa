"""A store this test's processes may only read, for real: permission bits that forbid
writing, and a child process that obeys them even as root (tests run as root in CI, and
root's CAP_DAC_OVERRIDE ignores the bits)."""

from __future__ import annotations

import ctypes
import os
from pathlib import Path


def drop_dac_capabilities() -> None:
    """In the child (``preexec_fn``): root keeps the folder's permission bits too (no
    CAP_DAC_OVERRIDE or CAP_DAC_READ_SEARCH in the bounding set, so the exec'd program does
    not get them). Nothing to do for another user."""
    if os.geteuid() != 0:
        return
    libc = ctypes.CDLL(None, use_errno=True)
    pr_capbset_drop, cap_dac_override, cap_dac_read_search = 24, 1, 2
    for cap in (cap_dac_override, cap_dac_read_search):
        if libc.prctl(pr_capbset_drop, cap, 0, 0, 0) != 0:
            raise OSError(ctypes.get_errno(), "prctl(PR_CAPBSET_DROP)")


def set_writable(folder: Path, writable: bool) -> None:
    """Every folder under ``folder`` (itself included) 0755 / 0555, every file 0644 / 0444."""
    for path in [folder, *folder.rglob("*")]:
        if path.is_dir():
            path.chmod(0o755 if writable else 0o555)
        else:
            path.chmod(0o644 if writable else 0o444)
