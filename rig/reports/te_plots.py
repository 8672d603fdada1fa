"""Figures of a transmission error run: TE against the output angle, both directions, with
the model's curve and band (docs/transmission-error.md)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure

from rig.results.te import TERunAnalysis

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["draw_te", "plot_te"]


def draw_te(ax: Axes, item: TERunAnalysis, *, title: str | None = None,
            limit_arcsec: float | None = None) -> Axes:
    """TE (arcsec) of each direction against the output angle (deg), revolution-averaged,
    with the model's nominal curves (dashed) and the peak-to-peak limit as a band around the
    mean when given; returns ``ax``."""
    r = item.result
    colors = {1: "tab:blue", -1: "tab:orange"}
    for code, curve in r.curves.items():
        pp = float(np.ptp(curve.mean_arcsec))
        ax.plot(curve.grid_deg, curve.mean_arcsec, color=colors[code], lw=0.9,
                label=f"{curve.name} (p-p {pp:.1f}″)")
    pred = item.prediction
    if pred is not None and pred.curve_deg is not None:
        order = np.argsort(np.mod(pred.curve_deg, 360.0))
        for code, curve in pred.curve_arcsec.items():
            ax.plot(np.mod(pred.curve_deg, 360.0)[order], curve[order], color=colors[code],
                    lw=0.7, ls="--", alpha=0.8,
                    label="model" if code == 1 else None)
    if limit_arcsec is not None:
        ax.axhspan(-limit_arcsec / 2.0, limit_arcsec / 2.0, color="0.92", zorder=0,
                   label=f"limit {limit_arcsec:g}″ p-p")
    m = r.metrics
    text = (f"TE p-p {m['te_pp_arcsec']:.1f}″  F'i {m['te_total_Fi_arcsec']:.1f}″  "
            f"f'i {m['te_tooth_fi_arcsec'] or float('nan'):.1f}″  "
            f"hysteresis {m['te_hysteresis_arcmin']:.2f}′")
    ax.text(0.01, 0.02, text, transform=ax.transAxes, fontsize=8, va="bottom")
    ax.set_xlim(0.0, 360.0)
    ax.set_xlabel("output angle (deg)")
    ax.set_ylabel("transmission error (arcsec)")
    ax.set_title(title or f"Transmission error: {item.run.run_id}", fontsize=10)
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=7, loc="upper right")
    return ax


def plot_te(item: TERunAnalysis, path: str | Path, *, title: str | None = None,
            limit_arcsec: float | None = None) -> Path:
    """Write :func:`draw_te` as a PNG (no pyplot: safe in a server thread)."""
    path = Path(path)
    fig = Figure(figsize=(7.5, 4.2), dpi=120)
    draw_te(fig.add_subplot(), item, title=title, limit_arcsec=limit_arcsec)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path
