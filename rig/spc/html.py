"""The HTML page of ``rig spc``: a jinja2 template (rig/templates/spc.html.j2) with the
control charts drawn by matplotlib, embedded as PNG."""

from __future__ import annotations

import base64
import io
from pathlib import Path
from typing import Any

TEMPLATES = Path(__file__).resolve().parent.parent / "templates"


def _fmt(value: Any) -> str:
    return "" if value is None else f"{value:.4g}"


def metric_figure(name: str, view: dict[str, Any]) -> str:
    """Individuals chart (top, with the measured distribution and the batch band beside it)
    and moving-range chart (bottom) of one metric; a base64 PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    chart = view["chart"]
    ind, mr = chart["individuals"], chart["moving_range"]
    x = list(range(1, len(ind["values"]) + 1))
    fig = plt.figure(figsize=(10, 5.2))
    grid = fig.add_gridspec(2, 2, width_ratios=[4, 1], height_ratios=[3, 2], wspace=0.05)
    ax_i = fig.add_subplot(grid[0, 0])
    ax_h = fig.add_subplot(grid[0, 1], sharey=ax_i)
    ax_m = fig.add_subplot(grid[1, 0], sharex=ax_i)
    ax_i.plot(x, ind["values"], "o-", color="#1f77b4", ms=3, lw=0.8)
    for y, style in ((ind["centre"], "-"), (ind["ucl"], "--"), (ind["lcl"], "--")):
        ax_i.axhline(y, color="#2ca02c", ls=style, lw=1)
    for key, label in (("usl", "USL"), ("lsl", "LSL")):
        if view.get(key) is not None:
            ax_i.axhline(view[key], color="#d62728", ls=":", lw=1.2, label=label)
            ax_h.axhline(view[key], color="#d62728", ls=":", lw=1.2)
    bad_i = sorted({v["index"] for v in chart["violations"] if v["chart"] == "I"})
    ax_i.plot([x[i] for i in bad_i], [ind["values"][i] for i in bad_i], "o", color="#d62728",
              ms=6, mfc="none", label="rule signal")
    ax_i.set_ylabel(name)
    ax_i.set_title(f"{name}: individuals (centre ± 3σ) and moving range", fontsize=10)
    ax_i.legend(loc="upper left", fontsize=8)
    ax_h.hist(ind["values"], bins=min(30, max(5, len(x) // 4)), orientation="horizontal",
              color="#1f77b4", alpha=0.6)
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
    ax_m.set_xlabel("unit test (time order)")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def render_html(doc: dict[str, Any]) -> str:
    """The page of an ``rig spc`` document (:func:`rig.spc.spc_report`)."""
    from jinja2 import Environment, FileSystemLoader

    # every value escaped whatever the template's name (select_autoescape() escapes only
    # .html/.htm/.xml, and this template is .html.j2: issue 21 item 1)
    env = Environment(loader=FileSystemLoader(TEMPLATES), autoescape=True)
    figures = {d["design"]: {name: metric_figure(name, m) for name, m in d["metrics"].items()
                             if m["chart"]} for d in doc["designs"]}
    return env.get_template("spc.html.j2").render(doc=doc, figures=figures, fmt=_fmt)
