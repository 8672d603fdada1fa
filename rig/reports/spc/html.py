"""The HTML page of ``rig spc``: a jinja2 template (rig/templates/spc.html.j2) with the
control charts drawn by matplotlib, embedded as PNG.

Each individuals chart's points are also hover targets on the page: an element placed over
each drawn point (its position in % of the image, so it follows the image when the page
scales it to a phone's width) names the unit test's order, serial, value and verdict, as a
``title`` and as a tooltip shown by CSS on hover or focus (no script: the page's
Content-Security-Policy forbids inline script). The x axis is the test order, 1, 2, ...,
with integer ticks.
"""

from __future__ import annotations

import base64
import io
from dataclasses import dataclass
from pathlib import Path
from typing import Any

TEMPLATES = Path(__file__).resolve().parents[2] / "templates"
DPI = 90
FIGSIZE_IN = (10.0, 5.2)
POINT_COLOUR = "#1f77b4"


def _fmt(value: Any) -> str:
    return "" if value is None else f"{value:.4g}"


@dataclass(frozen=True)
class ChartImage:
    """One metric's charts as a PNG, with where its individuals points were drawn.

    ``points``: (x, y) of each individuals point in pixels of the PNG, from its top left;
    ``xticks``: the tick positions of the shared test-order axis inside the data range.
    """

    png: bytes
    width: int
    height: int
    points: list[tuple[float, float]]
    xticks: list[float]

    @property
    def base64(self) -> str:
        return base64.b64encode(self.png).decode("ascii")


def _limit_line(ax: Any, x: list[int], limits: list[float | None], label: str) -> None:
    """A unit's own limit (its campaign's), as a step line over the points it applies to."""
    if all(v is None for v in limits):
        return
    ys = [float("nan") if v is None else v for v in limits]
    ax.step(x, ys, where="mid", color="#d62728", ls=":", lw=1.2, label=label)


def draw_chart(name: str, view: dict[str, Any]) -> ChartImage:
    """Individuals chart (top, with the measured distribution and the batch band beside it)
    and moving-range chart (bottom) of one metric, on the test order (1, 2, ...)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    chart = view["chart"]
    ind, mr = chart["individuals"], chart["moving_range"]
    order = [p["order"] for p in view["points"]]
    x = order if len(order) == len(ind["values"]) else list(range(1, len(ind["values"]) + 1))
    fig = plt.figure(figsize=FIGSIZE_IN, dpi=DPI, layout="constrained")
    grid = fig.add_gridspec(2, 2, width_ratios=[4, 1], height_ratios=[3, 2], wspace=0.02)
    ax_i = fig.add_subplot(grid[0, 0])
    ax_h = fig.add_subplot(grid[0, 1], sharey=ax_i)
    ax_m = fig.add_subplot(grid[1, 0], sharex=ax_i)
    ax_i.plot(x, ind["values"], "o-", color=POINT_COLOUR, ms=4, lw=0.8)
    lcl_style = ":" if ind.get("lcl_clipped") else "--"
    for y, style in ((ind["centre"], "-"), (ind["ucl"], "--"), (ind["lcl"], lcl_style)):
        ax_i.axhline(y, color="#2ca02c", ls=style, lw=1)
    for key, label in (("usl", "USL"), ("lsl", "LSL")):
        own = [p.get(key) for p in view["points"]]
        if len(own) == len(x):
            _limit_line(ax_i, x, own, f"{label} (each unit's own)" if view.get(
                "limits_differ") else label)
        if view.get(key) is not None:
            ax_h.axhline(view[key], color="#d62728", ls=":", lw=1.2)
    bad_i = sorted({v["index"] for v in chart["violations"] if v["chart"] == "I"})
    ax_i.plot([x[i] for i in bad_i], [ind["values"][i] for i in bad_i], "o", color="#d62728",
              ms=7, mfc="none", label="rule signal")
    ax_i.set_ylabel(name)
    ax_i.set_title(f"{name}: individuals (centre ± 3σ"
                   + (", LCL at 0: one-sided" if ind.get("lcl_clipped") else "")
                   + ") and moving range", fontsize=10)
    ax_i.legend(loc="upper left", fontsize=8)
    ax_h.hist(ind["values"], bins=min(30, max(5, len(x) // 4)), orientation="horizontal",
              color=POINT_COLOUR, alpha=0.6)
    band = (view.get("batch") or {}).get("band")
    if band:
        low, high = band["band_95_arcmin"]
        ax_h.axhspan(low, high, color="0.5", alpha=0.3, label="seed 000 batch 95 %")
        ax_h.axhline(band["median_arcmin"], color="0.3", lw=1)
        ax_h.legend(loc="upper right", fontsize=7)
    ax_h.tick_params(labelleft=False)
    ax_h.set_xlabel("units")
    ax_m.plot(x[1:], mr["values"], "o-", color="#ff7f0e", ms=3, lw=0.8)
    ax_m.axhline(mr["centre"], color="#2ca02c", lw=1)
    ax_m.axhline(mr["ucl"], color="#2ca02c", ls="--", lw=1)
    bad_m = sorted({v["index"] for v in chart["violations"] if v["chart"] == "MR"})
    ax_m.plot([x[i] for i in bad_m], [mr["values"][i - 1] for i in bad_m], "o",
              color="#d62728", ms=6, mfc="none")
    ax_m.set_ylabel("moving range")
    ax_m.set_xlabel("unit test (test order: 1 = first unit tested)")
    ax_m.xaxis.set_major_locator(MaxNLocator(integer=True, min_n_ticks=1))
    ax_i.tick_params(labelbottom=False)
    fig.canvas.draw()  # the final layout: the point positions below are those of the PNG
    width, height = fig.canvas.get_width_height()
    points = [(float(px), float(height - py)) for px, py in
              ax_i.transData.transform(list(zip(x, ind["values"], strict=True)))]
    lo, hi = min(x), max(x)
    xticks = [float(t) for t in ax_m.get_xticks() if lo <= t <= hi]
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    plt.close(fig)
    return ChartImage(buf.getvalue(), width, height, points, xticks)


def hover_targets(image: ChartImage, view: dict[str, Any], unit: str) -> list[dict[str, Any]]:
    """One hover target per individuals point: its place in % of the image and its text
    (test order, serial, value, verdict; escaped by the template)."""
    out = []
    for (px, py), p in zip(image.points, view["points"], strict=True):
        serial = p["unit_serial"] if p["unit_serial"] is not None else "serial not recorded"
        text = f"unit test {p['order']}: {serial} · {_fmt(p['value'])} {unit}"
        if p.get("verdict"):
            text += f" · {p['verdict']}"
        left, top = 100.0 * px / image.width, 100.0 * py / image.height
        out.append({"left": f"{left:.3f}", "top": f"{top:.3f}", "text": text,
                    "order": p["order"], "right": left > 50.0, "upper": top < 50.0})
    return out


UNITS = {"lost_motion_arcmin": "arcmin", "backlash_arcmin": "arcmin",
         "stiffness_Nm_per_arcmin": "N·m/arcmin", "te_pp_arcsec": "arcsec"}


def render_html(doc: dict[str, Any]) -> str:
    """The page of an ``rig spc`` document (:func:`rig.reports.spc.spc_report`)."""
    from jinja2 import Environment, FileSystemLoader

    # every value escaped whatever the template's name (select_autoescape() escapes only
    # .html/.htm/.xml, and this template is .html.j2: issue 21 item 1)
    env = Environment(loader=FileSystemLoader(TEMPLATES), autoescape=True)
    figures: list[dict[str, Any]] = []
    for d in doc["designs"]:
        per_metric = {}
        for name, m in d["metrics"].items():
            if not m["chart"]:
                continue
            image = draw_chart(name, m)
            per_metric[name] = {"png": image.base64,
                                "targets": hover_targets(image, m, UNITS.get(name, ""))}
        figures.append(per_metric)
    return env.get_template("spc.html.j2").render(doc=doc, figures=figures, fmt=_fmt)
