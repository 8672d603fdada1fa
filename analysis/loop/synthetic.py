"""Synthetic torque profiles and closed-form loop models, for tests, benchmarks and demos.

Torque in N·m, twist in arcmin, stiffness in N·m/arcmin. Each model's metrics are known
in closed form (see :mod:`analysis.loop` for the definitions):

* :func:`dead_zone_twist`, the reference nominal loop of the run format
  (``twist = s play/2 + T/K``, flank ``s`` kept while the torque is exactly zero):
  lost motion ``play + 2 p T_r / K``, backlash ``play``, stiffness ``K``, loop area 0.
* :func:`friction_twist`, Coulomb friction ``T_f`` on a spring ``K`` (a play operator of
  half-width ``T_f/K`` on ``T/K``): a parallelogram loop with backlash ``2 T_f / K``,
  lost motion ``2 p T_r / K`` and area ``4 T_f (T_m - T_f) / K`` (K in N·m/rad).
* :func:`three_segment_twist`, a Harmonic-Drive-style piecewise-linear spring
  (K1 below T1, K2 to T2, K3 above), no hysteresis.
"""

from __future__ import annotations

import numpy as np


def triangle_profile(
    peak_Nm: float, n_quarter: int, cycles: int = 1, *, phase: float = 0.0
) -> np.ndarray:
    """Constant-rate ramps 0 -> +peak -> -peak -> ... -> 0, ``n_quarter`` steps per quarter.

    ``phase`` (0..1) shifts the sampling grid by that fraction of a step, so that with
    0.5 no sample falls on exactly zero torque. Ends back at (about) zero torque.
    """
    n = 4 * n_quarter * cycles
    k = np.arange(n + 1, dtype=float) + phase
    u = (k / n_quarter) % 4.0  # position in quarters within a cycle
    tri = np.where(u < 1, u, np.where(u < 3, 2.0 - u, u - 4.0))
    return peak_Nm * tri


def step_dwell_profile(
    peak_Nm: float, step_Nm: float, dwell: int, cycles: int = 1
) -> np.ndarray:
    """Equal torque steps with ``dwell`` samples per level: 0 -> +peak -> -peak -> ... -> 0."""
    m = int(round(peak_Nm / step_Nm))
    up = np.arange(0, m + 1)
    levels = [up[:-1], m - np.arange(0, 2 * m)]
    for _ in range(cycles - 1):
        levels += [-m + np.arange(0, 2 * m), m - np.arange(0, 2 * m)]
    levels.append(-m + np.arange(0, m + 1))
    return np.repeat(np.concatenate(levels) * step_Nm, dwell)


def flank(torque_Nm: np.ndarray, start: int = -1) -> np.ndarray:
    """Flank sign: +1 once the torque turns positive, -1 once negative, kept at exactly 0."""
    s = np.sign(np.asarray(torque_Nm, dtype=float))
    idx = np.where(s != 0, np.arange(s.size), -1)
    np.maximum.accumulate(idx, out=idx)
    out = np.where(idx >= 0, s[np.maximum(idx, 0)], float(start))
    return out


def dead_zone_twist(
    torque_Nm: np.ndarray, play_arcmin: float, stiffness_Nm_per_arcmin: float, start: int = -1
) -> np.ndarray:
    """Free play plus a linear spring: ``s play/2 + T/K`` (run format reference model)."""
    T = np.asarray(torque_Nm, dtype=float)
    return flank(T, start) * (0.5 * play_arcmin) + T / stiffness_Nm_per_arcmin


def friction_twist(
    torque_Nm: np.ndarray, friction_Nm: float, stiffness_Nm_per_arcmin: float
) -> np.ndarray:
    """Coulomb friction on a spring: the play operator of half-width ``T_f/K`` on ``T/K``.

    Starts on the loading branch (as after a preload to -T and back), i.e. at ``(T0-T_f)/K``.
    A sequential recursion: meant for test-sized records.
    """
    x = np.asarray(torque_Nm, dtype=float) / stiffness_Nm_per_arcmin
    r = friction_Nm / stiffness_Nm_per_arcmin
    out = np.empty_like(x)
    y = x[0] - r
    for i, xi in enumerate(x.tolist()):
        y = min(max(y, xi - r), xi + r)
        out[i] = y
    return out


def three_segment_twist(
    torque_Nm: np.ndarray, T1_Nm: float, T2_Nm: float, K1: float, K2: float, K3: float
) -> np.ndarray:
    """Odd piecewise-linear spring: slope 1/K1 below T1, 1/K2 to T2, 1/K3 above (arcmin)."""
    T = np.asarray(torque_Nm, dtype=float)
    a = np.abs(T)
    th = np.minimum(a, T1_Nm) / K1
    th += np.clip(a - T1_Nm, 0.0, T2_Nm - T1_Nm) / K2
    th += np.maximum(a - T2_Nm, 0.0) / K3
    return np.sign(T) * th
