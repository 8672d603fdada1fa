"""The control page in Debian's headless Chromium: latency from a sample measured to the
sample drawn, and the frame rate with 10,000 points on screen.

Latency: the page on the simulated rig (its own process) measures one default run (the
GB/T loop of examples/campaigns/seed000-pair1.toml, ~12 s). Each live batch carries the wall
time its newest sample was measured (the engine's run clock, rig/web/live_tap.py); after
drawing it the page takes ``Date.now()`` minus that time: the latency of the newest sample
(merge wait for the torque stream + the 50 ms pump tick + SSE + one animation frame). The
oldest sample of a batch waited up to one pump tick longer: reported too.

Frame rate: 10,000 loop points in the live plot; every animation frame one point is added
(the oldest dropped) and the plot redrawn (uPlot ``setData``), for ``BENCH_SECONDS`` (default
5 s): frames per second and the time of one redraw (ms, from ``setData`` to uPlot's ``draw``
hook: scales, paths and canvas strokes of the 10,000 points).
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from pathlib import Path
from tempfile import TemporaryDirectory
from typing import Any

import numpy as np

CHROMIUM = "/usr/bin/chromium"
ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--no-first-run", "--disable-sync"]
TOKEN = "bench-operator-token"

FPS_JS = """async ([nPoints, seconds]) => {
  const live = window.rigPage.live;
  live.stored = null;
  live.model = null;
  live.T = []; live.W = [];
  for (let i = 0; i < nPoints; i++) {
    const ph = 2 * Math.PI * i / 2000;
    live.T.push(10 * Math.sin(ph));
    live.W.push(2 * Math.sign(Math.cos(ph)) + 0.05 * Math.sin(ph) * 10);
  }
  let frames = 0, drawMs = 0, k = 0, a = 0;
  const plot = window.rigPage.plot;
  (plot.hooks.draw = plot.hooks.draw || []).push(() => { drawMs += performance.now() - a; });
  const t0 = performance.now();
  await new Promise((resolve) => {
    function frame() {
      const ph = 2 * Math.PI * (nPoints + k++) / 2000;
      live.T.shift(); live.W.shift();
      live.T.push(10 * Math.sin(ph)); live.W.push(2 * Math.sign(Math.cos(ph)));
      a = performance.now();
      plot.setData([null, [live.T, live.W], [[], []]]);
      frames++;
      if (performance.now() - t0 < seconds * 1000) requestAnimationFrame(frame);
      else resolve();
    }
    requestAnimationFrame(frame);
  });
  const elapsed = (performance.now() - t0) / 1000;
  return {fps: frames / elapsed, draw_ms: drawMs / frames, points: live.T.length};
}"""


def _page_on_simulated_rig(root: Path) -> Any:
    from rig.store import Store
    from rig.web import create_app
    from rig.web.controller import RigController
    from rig.web.live import LiveHub
    from rig.web.settings import resolve_settings
    from rig.web.simulated import simulated_session_factory

    store = Store(root)
    controller = RigController(store, LiveHub(), simulated_session_factory(), simulated=True)
    return create_app(resolve_settings(store_root=root, token=TOKEN), controller)


def _measure(seconds: float) -> dict[str, Any]:
    from playwright.sync_api import expect, sync_playwright

    from rig.web.server import BackgroundServer

    with TemporaryDirectory(prefix="bench-web-") as tmp, \
            BackgroundServer(_page_on_simulated_rig(Path(tmp))) as server, \
            sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, headless=True, args=ARGS)
        page = browser.new_page(viewport={"width": 1400, "height": 1200})
        page.goto(f"{server.url}#token={TOKEN}")
        expect(page.locator("#state")).to_have_text("idle", timeout=90_000)
        page.click("#lock")
        expect(page.locator("#lock-state")).to_contain_text("confirmed", timeout=30_000)
        t0 = time.monotonic()
        page.click("#start")
        expect(page.locator("#state")).to_have_text("completed", timeout=120_000)
        run_s = time.monotonic() - t0
        stats = page.evaluate("window.rigStats")
        fps = page.evaluate(FPS_JS, [10_000, seconds])
        browser.close()
    return {"stats": stats, "fps": fps, "run_s": run_s}


def run() -> Iterator[dict[str, Any]]:
    if not os.path.exists(CHROMIUM):
        raise RuntimeError("Debian's chromium is not installed (/usr/bin/chromium)")
    seconds = float(os.environ.get("BENCH_SECONDS", "5"))
    out = _measure(seconds)
    newest = np.asarray(out["stats"]["latency_s"]) * 1000.0
    oldest = np.asarray(out["stats"]["latency_oldest_s"]) * 1000.0
    n = int(newest.size)
    for label, values in (("newest", newest), ("oldest", oldest)):
        for q in (50, 99):
            yield {"name": f"web_latency_{label}_sample_p{q}", "value": round(
                float(np.percentile(values, q)), 1), "unit": "ms", "batches": n,
                "run_s": round(out["run_s"], 1)}
    yield {"name": "web_frame_rate_10k_points", "value": round(out["fps"]["fps"], 1),
           "unit": "frames/s", "points": out["fps"]["points"], "seconds": seconds}
    yield {"name": "web_redraw_10k_points", "value": round(out["fps"]["draw_ms"], 2),
           "unit": "ms"}
