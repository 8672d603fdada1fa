"""The figures of a test certificate, as SVG data URIs (vector in the PDF, no files beside).

The loop is :func:`rig.reports.loop_plots.plot_loops` (the Fig. 6-style loop of ``rig analyse
--plot``);
lost motion against the input position is drawn here, with the nominal model's line and the
production batch band of the design (:func:`rig.plans.campaign_file.batch_band`, as stored by a
campaign).
"""

from __future__ import annotations

import base64
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from rig.results.analyse import RunAnalysis

__all__ = ["draw_positions", "loop_svg", "position_svg", "svg_uri"]


def svg_uri(svg: bytes) -> str:
    """An SVG document as a ``data:image/svg+xml;base64,...`` URI."""
    return "data:image/svg+xml;base64," + base64.b64encode(svg).decode("ascii")


SVG_TEXT = {"svg.fonttype": "none"}
"""The figures' words as SVG text, not glyph outlines: the PDF's text (``pdftotext``) and
the HTML hold what the figure says (its legend, its box of figures)."""


def loop_svg(analyses: Sequence[RunAnalysis], title: str | None = None, *,
             box: int | None = None, box_heading: str | None = None) -> str:
    """The loops (torque vs twist, with the model loop and the ±p % band) as an SVG URI;
    ``box``, ``box_heading``: whose figures the box shows
    (:func:`rig.reports.loop_plots.draw_loops`)."""
    import matplotlib as mpl

    from rig.reports.loop_plots import plot_loops

    with tempfile.TemporaryDirectory() as tmp, mpl.rc_context(SVG_TEXT):
        path = plot_loops(analyses, Path(tmp) / "loop.svg", title=title, box=box,
                          box_heading=box_heading)
        return svg_uri(path.read_bytes())


def position_svg(points: Sequence[dict[str, Any]], model_arcmin: float | None,
                 batch: dict[str, Any] | None, limit_arcmin: float | None) -> str:
    """Lost motion against the input angle (:func:`draw_positions`) as an SVG URI."""
    import io

    from matplotlib.figure import Figure

    fig = Figure(figsize=(5.0, 3.3))
    draw_positions(fig.add_subplot(), points, model_arcmin, batch, limit_arcmin)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="svg")
    return svg_uri(buf.getvalue())


def draw_positions(ax: Axes, points: Sequence[dict[str, Any]], model_arcmin: float | None,
                   batch: dict[str, Any] | None, limit_arcmin: float | None) -> Axes:
    """Draw lost motion (arcmin) against the input (eccentric shaft) angle (deg) into ``ax``:
    each run with its uncertainty, the nominal model (no runout) as a line, the batch's 95 %
    band shaded, and the limit. ``points``: dicts with input_angle_deg, lost_motion_arcmin,
    uncertainty. Returns ``ax``."""
    if batch and batch.get("band_95_arcmin"):
        low, high = batch["band_95_arcmin"]
        ax.axhspan(low, high, color="0.85", zorder=0,
                   label="production batch of the design, 95 %")
        if batch.get("median_arcmin") is not None:
            ax.axhline(batch["median_arcmin"], color="0.6", lw=0.8, ls=":")
    if model_arcmin is not None:
        ax.axhline(model_arcmin, color="black", lw=1.0, ls="--",
                   label=f"nominal model (no runout) {model_arcmin:.3f}")
    if limit_arcmin is not None:
        ax.axhline(limit_arcmin, color="#c00", lw=1.2, label=f"limit {limit_arcmin:g}")
    xs = [p["input_angle_deg"] for p in points]
    ys = [p["lost_motion_arcmin"] for p in points]
    errs = [p.get("uncertainty") or 0.0 for p in points]
    ax.errorbar(xs, ys, yerr=errs, fmt="o", ms=4, color="tab:blue", capsize=3,
                label="measured")
    ax.set_xlabel("input (eccentric shaft) angle, deg")
    ax.set_ylabel("lost motion, arcmin")
    ax.set_xlim(-15, 375)
    ax.set_xticks(range(0, 361, 60))
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(fontsize=7, loc="best")
    return ax
