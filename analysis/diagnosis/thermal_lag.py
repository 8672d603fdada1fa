"""The thermal family's lagged member: the play follows the mesh temperature, which lags the
housing sensor by the unit's thermal time constant (issue 31 item 1).

The housing sensor sits outside the mesh; heat reaches the teeth through the housing and the
bearings, so the mesh temperature ``T_m`` follows the sensor's ``T_s`` through a first-order
lag ``tau dT_m/dt = T_s - T_m`` (a lumped thermal capacity behind a conductance, the
single-time-constant model of a gearbox's heating). A play linear in ``T_m`` is then not
linear in ``T_s``: after a temperature step the play still changes while the sensor holds, and
a campaign heated and cooled again shows a loop in play against the sensor's temperature.

The campaign's time axis comes from each run's ``started_at`` (run-format.md) plus the
samples' ``t_s``; between runs the sensor is taken as linear from the last reading of one run
to the first of the next. Units: time s, temperature deg C.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from analysis.diagnosis.data import PreparedRun

#: Time constants tried, as multiples of the median time between run starts (a lag much
#: shorter than that is no lag for the runs; one much longer than the campaign a constant).
LAG_GRID_RUNS = (0.25, 0.5, 1.0, 2.0, 3.0, 5.0, 8.0)


def campaign_times(runs: Sequence[PreparedRun]) -> list[np.ndarray] | None:
    """Each run's block times on one campaign axis (s since the first run's start), or None
    when a run's start is unknown, the runs have no temperature, or two runs overlap in time
    (starts written without the time between runs)."""
    starts = [r.raw.started_s for r in runs]
    if any(s is None for s in starts) or any(r.temperature_C is None for r in runs):
        return None
    t0 = min(starts)  # type: ignore[type-var]
    times = [float(s) - float(t0) + r.t_s for s, r in zip(starts, runs, strict=True)]
    order = np.argsort([t[0] for t in times])
    for a, b in zip(order[:-1], order[1:], strict=False):
        if times[b][0] <= times[a][-1]:
            return None
    return times


def lag_first_order(t_s: np.ndarray, sensor_C: np.ndarray, tau_s: float) -> np.ndarray:
    """``tau dT_m/dt = T_s - T_m`` solved exactly for a sensor linear between its samples
    (``T_m`` soaked at the first reading): over a step ``h`` from ``x0`` to ``x1``,
    ``y1 = x1 + (y0 - x0) e^(-h/tau) - (x1 - x0) (tau / h) (1 - e^(-h/tau))``."""
    t = np.asarray(t_s, dtype=float)
    x = np.asarray(sensor_C, dtype=float)
    y = np.empty_like(x)
    y[0] = x[0]
    for k in range(1, x.size):
        h = t[k] - t[k - 1]
        if h <= 0.0:
            y[k] = y[k - 1]
            continue
        gone = -math.expm1(-h / tau_s)  # 1 - e^(-h/tau), exact for a short step too
        ramp = (x[k] - x[k - 1]) * (tau_s / h) * gone
        y[k] = x[k] + (y[k - 1] - x[k - 1]) * (1.0 - gone) - ramp
    return y


def mesh_temperatures(runs: Sequence[PreparedRun], times: Sequence[np.ndarray], tau_s: float
                      ) -> list[np.ndarray]:
    """Each run's mesh temperature at its blocks (deg C): the sensor's readings of all runs
    in time order through :func:`lag_first_order`."""
    t_all = np.concatenate(list(times))
    x_all = np.concatenate([np.asarray(r.temperature_C, dtype=float) for r in runs])
    order = np.argsort(t_all, kind="stable")
    y = np.empty_like(x_all)
    y[order] = lag_first_order(t_all[order], x_all[order], tau_s)
    out, k = [], 0
    for t in times:
        out.append(y[k:k + t.size])
        k += t.size
    return out


def lag_grid_s(times: Sequence[np.ndarray]) -> np.ndarray:
    """The time constants (s) tried: :data:`LAG_GRID_RUNS` times the median time between run
    starts."""
    starts = np.sort([t[0] for t in times])
    spacing = float(np.median(np.diff(starts))) if starts.size > 1 else 0.0
    if spacing <= 0.0:
        return np.array([])
    return spacing * np.asarray(LAG_GRID_RUNS)


def with_mesh_temperature(runs: Sequence[PreparedRun], times: Sequence[np.ndarray],
                          tau_s: float) -> tuple[PreparedRun, ...]:
    """The runs with their temperature replaced by the mesh temperature of lag ``tau_s``."""
    temps = mesh_temperatures(runs, times, tau_s)
    return tuple(replace(r, temperature_C=m, mean_temperature_C=float(np.mean(m)))
                 for r, m in zip(runs, temps, strict=True))
