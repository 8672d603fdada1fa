"""Figures: the Fig. 6-style hysteresis loop (seed 000) with the model loop and the ±p % band."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib as mpl
import numpy as np
from matplotlib.figure import Figure

from rig.results.analyse import RunAnalysis, loop_centre_arcmin

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["draw_loops", "plot_loops", "run_name", "worst_run"]

MODEL_GID = "model-loop"
"""The SVG id (matplotlib ``gid``) of the nominal model's loop in the figure."""
BOX_GID = "loop-figures"
"""The SVG id of the box of figures in the figure."""


def _fmt(value: float | None, unit: str) -> str:
    return "n/a" if value is None else f"{value:.3f} {unit}"


def run_name(meta: dict[str, Any], run_id: str) -> str:
    """A run as a campaign's views name it: its label and input position, "pos120 (120°)";
    the position alone ("120°") or the label alone when the record has only that; else its id."""
    label = meta.get("label")
    angle = (meta.get("test") or {}).get("input_angle_deg")
    where = (f"{angle:g}°" if isinstance(angle, int | float) and not isinstance(angle, bool)
             else None)
    if label and where:
        return f"{label} ({where})"
    return str(label or where or run_id)


def worst_run(analyses: Sequence[RunAnalysis]) -> int:
    """The index of the run with the largest lost motion (arcmin); 0 when none has one."""
    values = [a.loop.to_dict().get("lost_motion_arcmin") for a in analyses]
    finite = [(v, i) for i, v in enumerate(values)
              if isinstance(v, int | float) and math.isfinite(v)]
    return max(finite)[1] if finite else 0


def _model_curve(item: RunAnalysis, low: float, high: float
                 ) -> tuple[np.ndarray, np.ndarray] | None:
    """The run's model loop (torque N·m, twist arcmin centred as the run's loop is drawn) on a
    clean sweep from ``low`` to ``high`` and back, put as
    :meth:`RunAnalysis.model_twist_arcmin` puts it (on the measured loop's centre); only the
    way up where the way back lies on it (a model whose flanks change at zero torque).
    Never along the measured torque history, and never a line drawn twice: a dashed line
    drawn over itself (steps, noise, repeated cycles, the way back) reads as solid."""
    if item.model is None:
        return None
    on_history = item.model.twist_arcmin(
        item.run.torque_Nm, start_flank=int(item.run.test.get("start_flank", -1) or -1))
    up = np.linspace(low, high, 200)
    sweep = np.concatenate([up, up[::-1]])
    twist = item.model.twist_arcmin(sweep, start_flank=-1) - loop_centre_arcmin(on_history)
    if np.allclose(twist[:up.size], twist[up.size:][::-1], atol=1e-6, equal_nan=True):
        return up, twist[:up.size]
    return sweep, twist


def plot_loops(
    analyses: Sequence[RunAnalysis], path: str | Path, *, title: str | None = None,
    box: int | None = None, box_heading: str | None = None
) -> Path:
    """Draw measured loops (twist in arcmin against torque in N·m) with the model overlaid.

    One axes for all runs (a campaign's loops on top of each other, the model loop once),
    the ±p % lost-motion band shaded, and one run's metrics in a box (:func:`draw_loops`:
    ``box``, ``box_heading``). Writes a PNG (or whatever matplotlib infers from the suffix)
    and returns its path. No pyplot: safe in a server thread, and the caller's backend is
    untouched.
    """
    if not analyses:
        raise ValueError("nothing to plot")
    path = Path(path)
    fig = Figure(figsize=(7.5, 5.2), dpi=120)
    draw_loops(fig.add_subplot(), analyses, title=title, box=box, box_heading=box_heading)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


def draw_loops(ax: Axes, analyses: Sequence[RunAnalysis], *, title: str | None = None,
               box: int | None = None, box_heading: str | None = None) -> Axes:
    """Draw the loops of :func:`plot_loops` into ``ax`` (torque in N·m on x, twist in arcmin
    centred on the loop on y) and return it. Several runs are named by position
    (:func:`run_name`); the nominal model is drawn once per distinct model, black and dashed
    as its legend entry. The box holds the figures of run ``box`` (default: the only run,
    else the one with the largest lost motion, :func:`worst_run`) under ``box_heading``
    (default for several runs: "worst run: <name>")."""
    if not analyses:
        raise ValueError("nothing to plot")
    colors = mpl.rcParams["axes.prop_cycle"].by_key()["color"]
    several = len(analyses) > 1
    shown = (0 if not several else worst_run(analyses)) if box is None else box
    first = analyses[0]
    band = first.lost_motion_pct / 100.0 * first.rated_torque_Nm
    ax.axvspan(-band, band, color="0.9", zorder=0, label=f"±{first.lost_motion_pct:g} % of rated")
    low = min(float(np.nanmin(a.run.torque_Nm)) for a in analyses)
    high = max(float(np.nanmax(a.run.torque_Nm)) for a in analyses)
    models: list[tuple[np.ndarray, np.ndarray]] = []
    for i, item in enumerate(analyses):
        color = colors[i % len(colors)]
        torque = item.run.torque_Nm
        centre = loop_centre_arcmin(item.twist_arcmin)
        twist = item.twist_arcmin - centre
        label = run_name(item.run.meta, item.run.run_id) if several else "measured"
        ax.plot(torque, twist, color=color, lw=0.9, label=label)
        model = _model_curve(item, low, high)
        if model is not None and not any(
                m[1].shape == model[1].shape and np.allclose(m[1], model[1], atol=1e-3)
                for m in models):
            models.append(model)
    for k, (sweep, model) in enumerate(models):
        ax.plot(sweep, model, color="black", lw=1.0, ls="--", alpha=0.8,
                label="model" if k == 0 else None, gid=MODEL_GID if k == 0 else None,
                zorder=3)
    item = analyses[shown]
    metrics = item.to_dict()
    heading = box_heading if box_heading is not None else (
        f"worst run: {run_name(item.run.meta, item.run.run_id)}" if several else None)
    lines = [heading] if heading else []
    lines += [
        f"lost motion {_fmt(metrics['lost_motion_arcmin'], 'arcmin')}",
        f"backlash {_fmt(metrics['backlash_arcmin'], 'arcmin')}",
        f"stiffness {_fmt(metrics['stiffness_Nm_per_arcmin'], 'N·m/arcmin')}",
    ]
    if metrics.get("model"):
        lines.append(f"model lost motion {_fmt(metrics['model']['lost_motion_arcmin'], 'arcmin')}")
    ax.text(
        0.02,
        0.98,
        "\n".join(lines),
        transform=ax.transAxes,
        va="top",
        ha="left",
        fontsize=8,
        bbox={"boxstyle": "round", "fc": "white", "ec": "0.7"},
        gid=BOX_GID,
    )
    ax.axhline(0, color="0.6", lw=0.5)
    ax.axvline(0, color="0.6", lw=0.5)
    ax.set_xlabel("output torque T (N·m)")
    ax.set_ylabel("output twist (arcmin, centred on the loop)")
    ax.set_title(title or f"Hysteresis loop: {first.run.run_id}")
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(loc="lower right", fontsize=8)
    return ax
