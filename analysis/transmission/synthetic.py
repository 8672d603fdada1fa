"""TE samples with a known truth, for the tests, the benchmark and the documentation's example
(no rig, no plant: numerics only).

The input turns forward by ``revolutions`` output revolutions (plus ``margin``), stands, and
turns back; the true output angle is ``input / ratio + (TE(theta_out, theta_in, d) + h_d) / 3600``
with ``h_d = +-hysteresis / 2``; the output encoder reads it through its mounting eccentricity
``E(reading) = A sin(reading + p)`` (arcsec) with the coupling indexed by ``index_deg``; both
encoders quantise to their counts per revolution; white noise is optional.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

TEFunction = Callable[[np.ndarray, np.ndarray, int], np.ndarray]
"""``TE(theta_out_deg, theta_in_deg, direction)`` in arcsec."""


def quantise(angle_deg: np.ndarray, counts_per_rev: float | None) -> np.ndarray:
    """An encoder's reading of ``angle_deg``: the nearest whole count (no quantising for None)."""
    if not counts_per_rev:
        return angle_deg
    step = 360.0 / counts_per_rev
    return np.round(angle_deg / step) * step


@dataclass(frozen=True)
class SyntheticTE:
    """Columns of a TE run (run-format.md) and the truth they were made from."""

    t_s: np.ndarray
    input_angle_deg: np.ndarray
    output_angle_deg: np.ndarray
    direction: np.ndarray
    torque_Nm: np.ndarray


def synthetic_te(te: TEFunction, *, ratio: float = -8.0, revolutions: float = 1.0,
                 margin: float = 0.1, samples_per_output_rev: int = 20_000,
                 hysteresis_arcsec: float = 0.0, output_counts: float | None = 2**23,
                 input_counts: float | None = 2**17, noise_arcsec: float = 0.0,
                 ecc_amplitude_arcsec: float = 0.0, ecc_phase_deg: float = 0.0,
                 index_deg: float = 0.0, output_start_deg: float = 0.0,
                 input_speed_rpm: float = 60.0, brake_torque_Nm: float = 1.0,
                 turn_samples: int = 50, seed: int = 0) -> SyntheticTE:
    """Samples of a forward then reverse TE run (see module doc)."""
    rng = np.random.default_rng(seed)
    span_in = (revolutions + margin) * abs(ratio) * 360.0
    n = int(round((revolutions + margin) * samples_per_output_rev))
    fwd = np.linspace(0.0, span_in, n)
    rest = np.full(turn_samples, span_in)
    rev = fwd[::-1]
    theta_in = np.concatenate([fwd, rest, rev]) + output_start_deg * ratio
    direction = np.concatenate([np.ones(n, int), np.zeros(turn_samples, int),
                                -np.ones(n, int)])
    out_ideal = theta_in / ratio
    true_te = np.zeros_like(theta_in)
    for d in (1, -1):
        m = direction == d
        true_te[m] = te(out_ideal[m], theta_in[m], d) + d * hysteresis_arcsec / 2.0
    rest_m = direction == 0
    true_te[rest_m] = true_te[n - 1]
    out_true = out_ideal + true_te / 3600.0
    reading = out_true + index_deg
    reading = reading + ecc_amplitude_arcsec / 3600.0 * np.sin(
        np.radians(reading) + np.radians(ecc_phase_deg))
    if noise_arcsec:
        reading = reading + rng.normal(0.0, noise_arcsec / 3600.0, reading.size)
    dt = 60.0 / (input_speed_rpm * 360.0) * (span_in / max(n - 1, 1))
    t = np.arange(theta_in.size) * dt
    torque = -np.sign(direction * np.sign(ratio)) * brake_torque_Nm
    return SyntheticTE(t, quantise(theta_in, input_counts), quantise(reading, output_counts),
                       direction, torque.astype(float))
