"""Issue 21 item 1 in a real headless Chromium: a unit whose design and serial carry a
script that copies the operator token into the page title is in the store. The operator
opens the control page with the operator link (the token in sessionStorage), then "Quality
(SPC)". Nothing of the store runs: the titles stay the pages' own, no dialog opens, the
hostile text is shown as text, and the Content-Security-Policy refuses an inline script
even when one is put into the page. The control page itself runs under that policy with no
violation (its scripts are static files)."""

from __future__ import annotations

from pathlib import Path
from urllib.parse import quote

import pytest
from playwright.sync_api import expect, sync_playwright

from tests.support.browser import launch_browser
from tests.support.hostile import hostile, write_hostile_store
from tests.support.serve import TOKEN, rig_serve

# a loaded machine: store, server and SPC take a while
pytestmark = [pytest.mark.realtime, pytest.mark.timeout(360)]

INJECT = """() => new Promise((done) => {
  document.addEventListener("securitypolicyviolation",
    (e) => done(e.violatedDirective), { once: true });
  const s = document.createElement("script");
  s.textContent = 'document.title = "inline script ran"';
  document.body.appendChild(s);
  setTimeout(() => done(null), 3000);
})"""


def test_hostile_design_on_spc_does_not_run(tmp_path: Path):
    store, _, _ = write_hostile_store(tmp_path / "store")
    store.close()
    with rig_serve(tmp_path / "store") as (url, link), sync_playwright() as pw:
        browser = launch_browser(pw)
        page = browser.new_page(viewport={"width": 1440, "height": 900})
        dialogs: list[str] = []
        errors: list[str] = []
        csp_reports: list[str] = []
        page.on("dialog", lambda d: (dialogs.append(d.message), d.dismiss()))
        page.on("pageerror", lambda exc: errors.append(str(exc)))
        page.on("console", lambda m: csp_reports.append(m.text)
                if "Content Security Policy" in m.text else None)

        page.goto(link)
        expect(page.locator("#role")).to_have_text("operator")
        expect(page.locator("#state")).to_have_text("idle", timeout=90_000)
        # History lists the hostile serials, as text
        expect(page.locator("#runs tbody tr")).not_to_have_count(0, timeout=30_000)
        expect(page.locator("#runs tbody")).to_contain_text(hostile("serial 9"))
        assert page.title() == "simulated · backlash-rig control page"
        assert page.evaluate("sessionStorage.getItem('rigToken')") == TOKEN
        # the page's own escaping, for element content and quoted attributes alike
        assert page.evaluate("esc(`\"><img src=x onerror=alert(1)>'`)") == \
            "&quot;&gt;&lt;img src=x onerror=alert(1)&gt;&#39;"
        assert page.locator("#runs img, #campaigns img").count() == 0

        page.click("#spc-link", timeout=90_000)
        page.wait_for_url("**/spc", timeout=120_000)
        expect(page.locator("h2").first).to_contain_text(hostile("design"), timeout=120_000)
        assert page.title() == "Production quality"
        assert page.evaluate("sessionStorage.getItem('rigToken')") == TOKEN  # what it wanted
        assert page.locator("script").count() == 0
        assert page.locator("body img:not([src^='data:image/png'])").count() == 0
        assert page.locator("svg").count() == 0
        assert csp_reports == [], csp_reports  # both pages run under the policy as they are
        # even an inline script put into the page is refused by the policy
        assert page.evaluate(INJECT) == "script-src-elem"
        assert page.title() == "Production quality"

        page.goto(url + "spc?design=" + quote(hostile("design"), safe=""))
        expect(page.locator("h1")).to_contain_text(hostile("design"), timeout=120_000)
        # the title shows the design's text; run, it would have been "XSS-<token>"
        assert page.title() == "Production quality: " + hostile("design")
        assert TOKEN not in page.title()
        assert dialogs == [], dialogs
        assert errors == [], errors
        browser.close()
