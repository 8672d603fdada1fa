"""Figures: the Fig. 6-style hysteresis loop (seed 000) with the model loop and the ±p % band."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib as mpl
from matplotlib.figure import Figure

from rig.results.analyse import RunAnalysis, loop_centre_arcmin

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["draw_loops", "plot_loops"]


def _fmt(value: float | None, unit: str) -> str:
    return "n/a" if value is None else f"{value:.3f} {unit}"


def plot_loops(
    analyses: Sequence[RunAnalysis], path: str | Path, *, title: str | None = None
) -> Path:
    """Draw measured loops (twist in arcmin against torque in N·m) with the model overlaid.

    One axes for all runs (a campaign's loops on top of each other, each with its model loop),
    the ±p % lost-motion band shaded, and the first run's metrics in the legend box
    (:func:`draw_loops`). Writes a PNG (or whatever matplotlib infers from the suffix) and
    returns its path. No pyplot: safe in a server thread, and the caller's backend is untouched.
    """
    if not analyses:
        raise ValueError("nothing to plot")
    path = Path(path)
    fig = Figure(figsize=(7.5, 5.2), dpi=120)
    draw_loops(fig.add_subplot(), analyses, title=title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


def draw_loops(ax: Axes, analyses: Sequence[RunAnalysis], *, title: str | None = None) -> Axes:
    """Draw the loops of :func:`plot_loops` into ``ax`` (torque in N·m on x, twist in arcmin
    centred on the loop on y) and return it."""
    if not analyses:
        raise ValueError("nothing to plot")
    colors = mpl.rcParams["axes.prop_cycle"].by_key()["color"]
    first = analyses[0]
    band = first.lost_motion_pct / 100.0 * first.rated_torque_Nm
    ax.axvspan(-band, band, color="0.9", zorder=0, label=f"±{first.lost_motion_pct:g} % of rated")
    for i, item in enumerate(analyses):
        color = colors[i % len(colors)]
        torque = item.run.torque_Nm
        centre = loop_centre_arcmin(item.twist_arcmin)
        twist = item.twist_arcmin - centre
        label = item.run.run_id if len(analyses) > 1 else "measured"
        ax.plot(torque, twist, color=color, lw=0.9, label=label)
        model = item.model_twist_arcmin()
        if model is not None:
            model = model - centre
            ax.plot(
                torque,
                model,
                color="black" if len(analyses) == 1 else color,
                lw=1.0,
                ls="--",
                alpha=0.8,
                label="model" if i == 0 else None,
            )
    metrics = first.to_dict()
    text = "\n".join(
        [
            f"lost motion {_fmt(metrics['lost_motion_arcmin'], 'arcmin')}",
            f"backlash {_fmt(metrics['backlash_arcmin'], 'arcmin')}",
            f"stiffness {_fmt(metrics['stiffness_Nm_per_arcmin'], 'N·m/arcmin')}",
        ]
    )
    if metrics.get("model"):
        text += f"\nmodel lost motion {_fmt(metrics['model']['lost_motion_arcmin'], 'arcmin')}"
    ax.text(
        0.02,
        0.98,
        text,
        transform=ax.transAxes,
        va="top",
        ha="left",
        fontsize=8,
        bbox={"boxstyle": "round", "fc": "white", "ec": "0.7"},
    )
    ax.axhline(0, color="0.6", lw=0.5)
    ax.axvline(0, color="0.6", lw=0.5)
    ax.set_xlabel("output torque T (N·m)")
    ax.set_ylabel("output twist (arcmin, centred on the loop)")
    ax.set_title(title or f"Hysteresis loop: {first.run.run_id}")
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(loc="lower right", fontsize=8)
    return ax
