"""Plot helpers of the Python API: draw into the caller's matplotlib axes, or a new figure.

The drawings are those of the reports (:func:`rig.reports.loop_plots.draw_loops`,
:func:`rig.reports.certificate.plots.draw_positions`); pyplot is only used to make a new figure when
no axes are given, so the caller's backend (a notebook's inline one) is respected.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.axes import Axes

__all__ = ["axes_or_new", "draw_positions_table"]


def axes_or_new(ax: Axes | None, figsize: tuple[float, float] = (7.5, 5.2)) -> Axes:
    """``ax``, or the axes of a new pyplot figure (``figsize`` in inches)."""
    if ax is not None:
        return ax
    import matplotlib.pyplot as plt

    _, new = plt.subplots(figsize=figsize)
    return new


def _value(x: Any) -> float | None:
    return None if x is None or (isinstance(x, float) and math.isnan(x)) else float(x)


def draw_positions_table(ax: Axes | None, results: pd.DataFrame, *,
                         batch: dict[str, Any] | None = None,
                         model_arcmin: float | None = None,
                         title: str | None = None) -> Axes:
    """Lost motion (arcmin, with its uncertainty) against the input angle (deg) of a results
    table (:mod:`rig.results.table`), with the nominal model, the batch band and the limit."""
    from rig.reports.certificate.plots import draw_positions

    points = []
    for row in results.to_dict("records"):
        angle, value = _value(row.get("input_angle_deg")), _value(row.get("lost_motion_arcmin"))
        if angle is not None and value is not None:
            points.append({"input_angle_deg": angle, "lost_motion_arcmin": value,
                           "uncertainty": _value(row.get("lost_motion_arcmin_u"))})
    if not points:
        raise ValueError("no run with an input angle (test.input_angle_deg) and a lost motion")
    if model_arcmin is None and "model_lost_motion_arcmin" in results:
        models = [m for m in map(_value, results["model_lost_motion_arcmin"]) if m is not None]
        model_arcmin = models[0] if models else None
    limits = [v for v in map(_value, results.get("lost_motion_arcmin_max", [])) if v is not None]
    ax = axes_or_new(ax, (6.0, 4.0))
    draw_positions(ax, points, model_arcmin, batch, limits[0] if limits else None)
    if title:
        ax.set_title(title)
    return ax
