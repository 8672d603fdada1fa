"""Offline simulation: a whole run from a torque profile, without a wall clock.

The same engine as GearPlant (simulators/plant/model.py), stepped directly on simulated
time, with the sensors' noise drawn at once and the encoder quantisation applied: the
columns of a run's samples.csv (docs/run-format.md). Used to generate campaigns.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from simulators.plant.config import PlantConfig
from simulators.plant.model import PlantModel


def _commands(profile: Callable[[float], float] | np.ndarray, t_s: np.ndarray) -> np.ndarray:
    if callable(profile):
        values = np.array([float(profile(float(t))) for t in t_s])
    else:
        values = np.asarray(profile, dtype=float).ravel()
        if values.shape != t_s.shape:
            raise ValueError(
                f"torque profile array has {values.size} values; the run has {t_s.size} samples "
                "(one command per sample expected)"
            )
    if not np.all(np.isfinite(values)):
        raise ValueError("torque profile gives a non-finite command (N*m)")
    return values


def quantise_deg(angle_deg: np.ndarray, counts_per_rev: int) -> np.ndarray:
    """An angle (deg) as an encoder of ``counts_per_rev`` counts reads it (nearest count)."""
    step = 360.0 / counts_per_rev
    return np.round(np.asarray(angle_deg) / step) * step


def simulate_run(
    config: PlantConfig,
    torque_profile_Nm: Callable[[float], float] | np.ndarray,
    *,
    duration_s: float,
    sample_rate_Hz: float,
    input_angle_deg: float = 0.0,
    temperature_C: float | None = None,
) -> dict[str, np.ndarray]:
    """Simulate one run and return its columns.

    ``torque_profile_Nm``: the drive command (N*m) as a function of time (s), or one value per
    sample, held over the sample interval. The input is locked at ``input_angle_deg`` from the
    start; ``temperature_C`` holds the housing at that temperature (None: the config's
    housing, drifting to its ambient). The run has ``round(duration_s * sample_rate_Hz)``
    samples at ``t = k / sample_rate_Hz``; the model steps at most rig.step_s.

    Returns ``t_s``, ``torque_Nm`` (the sensor: offset, gain, noise), ``output_angle_deg`` and
    ``input_angle_deg`` (quantised to rig.encoder_counts_per_rev), ``temperature_C``, plus
    the extra columns ``true_torque_Nm`` (flange torque), ``chain_torque_Nm`` (what the
    elastic chain carries: flange torque less the output friction) and ``torque_command_Nm``.
    """
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s must be > 0, got {duration_s!r}")
    if not (math.isfinite(sample_rate_Hz) and sample_rate_Hz > 0):
        raise ValueError(f"sample_rate_Hz must be > 0, got {sample_rate_Hz!r}")
    n = int(round(duration_s * sample_rate_Hz))
    if n < 1:
        raise ValueError(f"{duration_s} s at {sample_rate_Hz} Hz is less than one sample")
    changes: dict[str, dict] = {"rig": {"initial_input_angle_deg": float(input_angle_deg)}}
    if temperature_C is not None:
        changes["housing"] = {"initial_C": float(temperature_C), "ambient_C": float(temperature_C)}
    config = config.with_changes(**changes)

    t_s = np.arange(n) / sample_rate_Hz
    commands = _commands(torque_profile_Nm, t_s)
    model = PlantModel(config)
    interval = 1.0 / sample_rate_Hz
    sub = max(1, math.ceil(interval / config.rig.step_s - 1e-9))
    dt = interval / sub

    out = np.empty(n)
    inp = np.empty(n)
    flange = np.empty(n)
    chain = np.empty(n)
    temp = np.empty(n)
    step = model.step
    for k, command in enumerate(commands.tolist()):  # Python floats: numpy scalars are slow
        model.command_Nm = command
        out[k] = model.output_angle_deg()
        inp[k] = model.input_deg
        flange[k] = model.flange_Nm
        chain[k] = model.chain_Nm
        temp[k] = model.temperature_C
        step(dt, sub)

    fx = config.effects
    torque = flange.copy()
    if fx.direction_gain.enabled:
        gains = np.where(flange >= 0.0, fx.direction_gain.gain_positive,
                         fx.direction_gain.gain_negative)
        torque *= gains
    if fx.torque_sensor_offset.enabled:
        torque += fx.torque_sensor_offset.offset_Nm
    rng = np.random.default_rng(config.noise.seed)
    out = out + rng.standard_normal(n) * (config.noise.twist_arcsec_rms / 3600.0)
    torque = torque + rng.standard_normal(n) * config.noise.torque_Nm_rms
    counts = config.rig.encoder_counts_per_rev
    return {
        "t_s": t_s,
        "torque_Nm": torque,
        "output_angle_deg": quantise_deg(out, counts),
        "input_angle_deg": quantise_deg(inp, counts),
        "temperature_C": temp,
        "true_torque_Nm": flange,
        "chain_torque_Nm": chain,
        "torque_command_Nm": commands,
    }
