"""Other functional forms and sensor artifacts for generated campaigns (outside the plant).

The plant (simulators/plant/model.py) has one law per effect. A validation that only ever saw
those laws would test self-recognition, so the generator (rig/validate/__init__.py) adds, on the
plant's output columns, other forms a lab's data may hold: a Hertzian power-law stiffening, a
smooth clearance take-up, loading profiles other than steps, a delayed torque channel, the
ringing of an impact at the play crossing, a coarse encoder. Each function names the equation
it follows. Units: torque N*m, angle deg (columns) or arcmin/arcsec (effect sizes), time s.
"""

from __future__ import annotations

import math

import numpy as np


def sine_profile(rated_Nm: float, n: int, periods: float = 1.5) -> np.ndarray:
    """Sinusoidal loading ``T(t) = T_rated sin(2 pi periods k / n)`` (N*m), one value per
    sample: 0 -> +T -> -T -> +T -> 0 over 1.5 periods (a GB/T-style continuous cycle)."""
    k = np.arange(n)
    return rated_Nm * np.sin(2.0 * math.pi * periods * k / max(n - 1, 1))


def ramp_profile(rated_Nm: float, n: int) -> np.ndarray:
    """Constant-rate triangular loading (N*m): 0 -> +T -> -T -> +T -> 0 at one torque rate
    ``dT/dt = 6 T_rated / duration`` (the path is 6 T_rated long), no dwell."""
    u = np.linspace(0.0, 6.0, n)
    knots = np.array([0.0, 1.0, 3.0, 5.0, 6.0])
    return rated_Nm * np.interp(u, knots, [0.0, 1.0, -1.0, 1.0, 0.0])


def power_law_twist_arcmin(flange_Nm: np.ndarray, rated_Nm: float, twist_at_rated_arcmin: float,
                           exponent: float) -> np.ndarray:
    """Hertzian contact hardening: extra flank twist ``sign(T) d (|T| / T_rated)^p`` (arcmin),
    concave for p < 1 like a Hertzian contact (deflection ~ load^(2/3), Johnson, Contact
    Mechanics, eq. 4.23); never saturates. Applied to the flange torque, which is zero inside
    the play, so the term is continuous."""
    t = np.asarray(flange_Nm, dtype=float)
    return np.sign(t) * twist_at_rated_arcmin * (np.abs(t) / rated_Nm) ** exponent


def smooth_takeup_twist_arcmin(flange_Nm: np.ndarray, clearance_arcmin: float,
                               knee_Nm: float) -> np.ndarray:
    """A bearing clearance taken up smoothly: extra twist ``sign(T) c tanh(|T| / T_k)``
    (arcmin), ``c`` the clearance seen at the output, ``T_k`` the take-up torque; above a few
    T_k the clearance is closed and the nominal slope is left (a saturating take-up, unlike
    a Hertzian hardening)."""
    t = np.asarray(flange_Nm, dtype=float)
    return np.sign(t) * clearance_arcmin * np.tanh(np.abs(t) / knee_Nm)


def delayed(t_s: np.ndarray, values: np.ndarray, lag_s: float) -> np.ndarray:
    """A channel that lags by ``lag_s`` (s): ``x(t - lag)``, linearly interpolated, held at
    the first value before the start (a sensor / acquisition delay between channels)."""
    return np.interp(np.asarray(t_s) - lag_s, t_s, values)


def impact_ringing_arcsec(t_s: np.ndarray, flange_Nm: np.ndarray, amplitude_arcsec: float,
                          frequency_Hz: float, decay_s: float, contact_Nm: float = 1e-9
                          ) -> np.ndarray:
    """Ringing after each impact at the play crossing (arcsec): at every sample where the
    flange torque leaves zero (contact after a float), a damped oscillation
    ``s A exp(-t/tau) sin(2 pi f t)`` of the output (the impulse response of the
    output inertia on the mesh spring), ``s`` the flank's sign."""
    t = np.asarray(t_s, dtype=float)
    f = np.asarray(flange_Nm, dtype=float)
    touching = np.abs(f) > contact_Nm
    onsets = np.flatnonzero(touching[1:] & ~touching[:-1]) + 1
    out = np.zeros_like(t)
    for k in onsets:
        dt = t[k:] - t[k]
        ring = np.exp(-dt / decay_s) * np.sin(2.0 * math.pi * frequency_Hz * dt)
        out[k:] += math.copysign(amplitude_arcsec, f[k]) * ring
    return out


def center_distance_change_mm(play_change_um: float, pressure_angle_deg: float) -> float:
    """The center-distance change (mm) that changes the circumferential play by
    ``play_change_um``: ``dj = -2 tan(alpha) da`` (seed 000 eq. (3))."""
    return -play_change_um / 1000.0 / (2.0 * math.tan(math.radians(pressure_angle_deg)))


def reversal_points(precycles: int = 0, first_sign: int = 1) -> list[float]:
    """The loading's reversal points (fractions of rated): ``0, s, -s, s, 0`` (s the first
    direction's sign) with ``precycles`` full cycles ``s, -s`` inserted before the last one."""
    s = 1.0 if first_sign >= 0 else -1.0
    return [0.0, s, -s] + [s, -s] * int(precycles) + [s, 0.0]


def path_profile(loading: str, rated_Nm: float, n: int, precycles: int = 0,
                 first_sign: int = 1, steps_per_quarter: int = 8,
                 ramp_share: float = 0.6) -> np.ndarray:
    """Commanded torque (N*m), one value per sample, through :func:`reversal_points`:

    - ``stepped``: equal steps of ``T_rated / steps_per_quarter`` plus a step at +-3 % of
      rated (the lost-motion points), each a ramp over ``ramp_share`` of the step, then a
      dwell;
    - ``ramp``: constant rate (triangular, no dwell);
    - ``sine``: ``s T_rated sin(2 pi (1.5 + precycles) k / (n - 1))``."""
    points = reversal_points(precycles, first_sign)
    if loading == "sine":
        k = np.arange(n)
        return (points[1] * rated_Nm
                * np.sin(2.0 * math.pi * (1.5 + precycles) * k / max(n - 1, 1)))
    if loading == "ramp":
        lengths = np.abs(np.diff(points))
        knots = np.concatenate(([0.0], np.cumsum(lengths)))
        u = np.linspace(0.0, knots[-1], n)
        return rated_Nm * np.interp(u, knots, points)
    if loading != "stepped":
        raise ValueError(f"unknown loading {loading!r}; known: stepped, ramp, sine")
    q = np.unique(np.append(np.linspace(0.0, 1.0, steps_per_quarter + 1), 0.03))
    grid = np.unique(np.concatenate((-q, q)))
    levels = [points[0]]
    for a, b in zip(points[:-1], points[1:], strict=True):
        inner = grid[(grid > min(a, b)) & (grid < max(a, b))]
        levels += list(inner if b > a else inner[::-1]) + [b]
    lv = np.asarray(levels) * rated_Nm
    per = n / (lv.size - 1)
    k = np.arange(n) / per
    i = np.minimum(k.astype(int), lv.size - 2)
    frac = np.clip((k - i) / ramp_share, 0.0, 1.0)
    return lv[i] + (lv[i + 1] - lv[i]) * frac


def thermal_lag_C(sensor_C: list[float], lag_runs: float) -> list[float]:
    """The mesh temperature (deg C) at each run when it follows the housing sensor's
    ``sensor_C`` through a first-order lag ``tau dT_m/dt = T_s - T_m`` with ``tau`` in units
    of the time between runs (``lag_runs``), the sensor held at each run's value since the
    run before and the mesh soaked at the first run's temperature:
    ``T_m,k = T_s,k + (T_m,k-1 - T_s,k) exp(-1 / lag_runs)``."""
    decay = math.exp(-1.0 / lag_runs)
    mesh = [float(sensor_C[0])]
    for t in sensor_C[1:]:
        mesh.append(float(t + (mesh[-1] - t) * decay))
    return mesh


def parallel_spring_torque_Nm(angle_deg: np.ndarray, stiffness_Nm_per_arcmin: float
                              ) -> np.ndarray:
    """The torque (N*m) a spring in parallel with the gear adds to the measured torque at
    the output angle ``angle_deg``: ``k_p (theta - theta_0)``, its neutral angle ``theta_0``
    in the middle of the run's travel (the middle of the free play in a symmetric loop). The
    recorded (torque, twist) pairs of a quasi-static loop are then those of the gear and the
    spring together: a slope ``k_p`` inside the play that no gear effect gives."""
    theta = np.asarray(angle_deg, dtype=float) * 60.0
    theta0 = 0.5 * (float(theta.max()) + float(theta.min()))
    return stiffness_Nm_per_arcmin * (theta - theta0)


def drifting_zero_Nm(t_s: np.ndarray, drift_Nm: float) -> np.ndarray:
    """A torque zero drifting linearly by ``drift_Nm`` (N*m) from the run's first sample to
    its last (a sensor warming between tares)."""
    t = np.asarray(t_s, dtype=float)
    span = float(t[-1] - t[0]) if t.size > 1 else 1.0
    return drift_Nm * (t - t[0]) / (span or 1.0)
