"""The browser of the page tests: Debian's chromium, headless, driven by Playwright (never a
downloaded browser), and the folder their screenshots go to."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.support.paths import REPO

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--no-first-run", "--disable-sync"]
ARTIFACTS = REPO / "artifacts" / "e2e"
"""Screenshots of the page tests."""
NEEDS_CHROMIUM = pytest.mark.skipif(
    not CHROMIUM.exists(),
    reason="Debian's chromium is not installed (/usr/bin/chromium missing; .ci/install "
           "installs it)")
"""The mark of a module that drives the browser."""


def launch_browser(playwright: Any) -> Any:
    """Debian's chromium, headless, driven by Playwright (never a downloaded browser)."""
    return playwright.chromium.launch(executable_path=str(CHROMIUM), headless=True,
                                      args=CHROMIUM_ARGS)
