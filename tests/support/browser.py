"""The browser of the page tests: Debian's chromium, headless, driven by Playwright (never a
downloaded browser), and the folder their screenshots go to."""

from __future__ import annotations

import itertools
import re
from pathlib import Path
from typing import Any

import pytest
from playwright.sync_api import expect

from tests.support.paths import REPO

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--no-first-run", "--disable-sync"]
ARTIFACTS = REPO / "artifacts" / "e2e"
DESKTOP = {"width": 1440, "height": 900}
"""The operator's desktop viewport (issue 33: every page item is checked at both widths)."""
PHONE = {"width": 390, "height": 844}
"""A phone's viewport."""
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


def open_page(browser: Any, link: str, width: int, height: int) -> tuple[Any, list[str]]:
    """A new page of ``width`` x ``height`` px at ``link``; returns (page, the JavaScript
    errors it raises, collected as they come)."""
    page = browser.new_page(viewport={"width": width, "height": height})
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.goto(link)
    return page, errors


def desktop_and_phone(browser: Any, link: str) -> tuple[Any, list[str], Any, list[str]]:
    """The operator page at both widths (:data:`DESKTOP`, :data:`PHONE`), each signed in as
    the operator and idle: (desktop page, its errors, phone page, its errors)."""
    page, errors = open_page(browser, link, DESKTOP["width"], DESKTOP["height"])
    phone, phone_errors = open_page(browser, link, PHONE["width"], PHONE["height"])
    for p in (page, phone):
        expect(p.locator("#role")).to_have_text("operator", timeout=60_000)
        expect(p.locator("#state")).to_have_text("idle", timeout=90_000)
    return page, errors, phone, phone_errors


def no_sideways_scroll(page: Any) -> None:
    """Nothing on ``page`` reaches past the viewport's right edge (the first five that do are
    named)."""
    wide = page.evaluate("""() => [...document.querySelectorAll('body *')].filter(
        (e) => e.getBoundingClientRect().right > innerWidth + 0.5).slice(0, 5).map(
        (e) => e.tagName + '#' + e.id + '.' + e.className)""")
    assert page.evaluate("document.scrollingElement.scrollWidth <= innerWidth"), wide


def confirm_lock(page: Any) -> None:
    """Confirm the input lock on the page and wait (30 s at most) until it says so (the
    request answers at once; the input may still be moving: "moving to ... (not confirmed
    yet)", issue 33 item 7)."""
    page.click("#lock")
    expect(page.locator("#lock-state")).to_have_text(re.compile(r"^confirmed"),
                                                     timeout=30_000)


OPERATOR = "E2E Operator"
"""The operator the page tests type when a test gives none."""
_serials = itertools.count(1)


def fill_identity(page: Any, operator: str | None = None, serial: str | None = None) -> None:
    """Type the operator and the unit's serial on the set-up form (Start needs both, issue 33
    item 9): the given ones, else :data:`OPERATOR` and a new serial ``E2E-<n>`` where the
    field is empty (a serial typed by the test, or an operator the page remembered, is
    kept)."""
    form = page.locator("#setup")
    for name, value, default in (("operator", operator, OPERATOR),
                                 ("serial", serial, None)):
        field = form.locator(f"input[name={name}]")
        if value is not None:
            field.fill(value)
        elif not field.input_value().strip():
            field.fill(default if default is not None else f"E2E-{next(_serials)}")


def start_run(page: Any, operator: str | None = None, serial: str | None = None) -> None:
    """Type the operator and serial where empty (:func:`fill_identity`), confirm the input
    lock, wait until Start is enabled and press it."""
    fill_identity(page, operator, serial)
    confirm_lock(page)
    expect(page.locator("#start")).to_be_enabled()
    page.click("#start")
