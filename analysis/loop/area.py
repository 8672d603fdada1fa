"""Energy of one hysteresis cycle: the closed integral of torque over twist."""

from __future__ import annotations

import numpy as np

from analysis.loop.numeric import dot

#: Radians per arcminute.
RAD_PER_ARCMIN = np.pi / 10800.0


def loop_area_J(
    torque_Nm: np.ndarray,
    twist_arcmin: np.ndarray,
    path: list[slice],
    *,
    twist_sigma_arcmin: float,
    torque_sigma_Nm: float,
) -> tuple[float, float]:
    """Closed integral ``∮ T dθ`` (J, θ in rad) along ``path`` and its standard uncertainty.

    ``path`` lists sample slices in path order (unloading pass, then loading pass); the path
    is closed by a straight line from its last sample back to its first. The integral is
    the trapezoid rule on the polygon of samples,
    ``A = Σ ½ (T_i + T_i+1) (θ_i+1 - θ_i)``, which is linear in each θ_i and so unbiased under
    white twist noise. It is positive for a loop run clockwise in the (twist, torque) plane
    (loading branch on the left), i.e. the energy dissipated per cycle.

    Uncertainty, first order in independent noise of each sample:
    ``u² = σθ² Σ (½ (T_i-1 - T_i+1))² + σT² Σ (½ (θ_i+1 - θ_i-1))²``, plus the sampling
    error of steps the samples do not resolve: where the twist moves by more than six noise
    standard deviations between two samples (a play crossed between samples), the true path
    may pass anywhere between them and the trapezoid is off by up to ``½ |ΔT Δθ|``; these
    bounds are summed and taken as a uniform distribution (divided by sqrt(3)).
    """
    T = np.concatenate([torque_Nm[s] for s in path])
    th = np.concatenate([twist_arcmin[s] for s in path])
    th -= th.mean()  # the zero of the twist is arbitrary; keeps the sums well conditioned
    th *= RAD_PER_ARCMIN
    # closed path: pad with the last sample before and the first after
    Tc = np.concatenate((T[-1:], T, T[:1]))
    thc = np.concatenate((th[-1:], th, th[:1]))
    dT = np.diff(Tc[1:])  # T_i+1 - T_i, i = 0..N-1 (closing step last)
    d_th = np.diff(thc[1:])
    area = 0.5 * dot(Tc[1:-1] + Tc[2:], d_th)
    g_th = Tc[:-2] - Tc[2:]  # 2 dA/dθ_i
    g_T = thc[2:] - thc[:-2]  # 2 dA/dT_i
    sigma_th = twist_sigma_arcmin * RAD_PER_ARCMIN
    u2 = 0.25 * (sigma_th**2 * dot(g_th, g_th) + torque_sigma_Nm**2 * dot(g_T, g_T))
    big = np.abs(d_th) > 6.0 * sigma_th
    bound = 0.5 * dot(np.abs(dT[big]), np.abs(d_th[big]))
    u2 += bound**2 / 3.0
    return area, float(np.sqrt(u2))
