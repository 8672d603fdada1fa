"""The simulated plant's cost: real-time snapshots and offline runs.

* ``plant_realtime_cpu_1kHz``: CPU share of one core (process time / simulated time) of a
  GearPlant asked for a snapshot every 1 ms (a ManualClock moved by 1 ms per call), on a
  slow torque triangle, with friction (Dahl), runout, thermal, shaft compliance and noise on.
  Target: well under 20 %.
* ``plant_realtime_cpu_2kHz_3faces``: the same with three faces calling every 0.5 ms.
* ``simulate_run_5000_samples_*``: wall time of offline.simulate_run for 5,000 samples at
  1 kHz (5 s, 5,000 steps of 1 ms) and at 250 Hz (20 s, 20,000 steps), nominal and with every
  effect on (LuGre friction, stiffening: the slow, iterative paths). Target: well under 0.5 s.
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable, Iterator

from simulators.clock import ManualClock
from simulators.offline import simulate_run
from simulators.plant import GearPlant
from simulators.plant.config import EFFECT_NAMES, PlantConfig, load_plant_config


def _triangle(period_s: float, amplitude_Nm: float = 10.0) -> Callable[[float], float]:
    def profile(t: float) -> float:
        p = (t % period_s) / period_s
        if p < 0.25:
            return 4 * amplitude_Nm * p
        return amplitude_Nm * (2 - 4 * p) if p < 0.75 else amplitude_Nm * (4 * p - 4)

    return profile


def _rig_config() -> PlantConfig:
    config = load_plant_config()
    for name in ("friction", "runout", "thermal_expansion", "shaft_compliance"):
        config = config.with_effect(name)
    return config


def _all_effects() -> PlantConfig:
    config = load_plant_config()
    for name in EFFECT_NAMES:
        config = config.with_effect(name)
    return config.with_effect("friction", model="lugre")


def _realtime_share(interval_s: float, callers: int, seconds: float = 5.0) -> float:
    clock = ManualClock()
    plant = GearPlant(_rig_config(), clock)
    profile = _triangle(4.0)
    ticks = int(seconds / interval_s)
    start = time.process_time()
    for k in range(ticks):
        clock.advance(interval_s)
        if k % 10 == 0:
            plant.command_torque(profile(k * interval_s))
        for _ in range(callers):
            plant.snapshot()
    return (time.process_time() - start) / seconds


def _offline_s(config: PlantConfig, rate_Hz: float, repeats: int = 3) -> float:
    times = []
    duration = 5000 / rate_Hz
    profile = _triangle(duration)
    for _ in range(repeats):
        start = time.perf_counter()
        simulate_run(config, profile, duration_s=duration, sample_rate_Hz=rate_Hz)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def run() -> Iterator[dict]:
    share = _realtime_share(0.001, 1)
    yield {"name": "plant_realtime_cpu_1kHz", "value": round(100 * share, 2), "unit": "%",
           "target": 20.0}
    share = _realtime_share(0.0005, 3)
    yield {"name": "plant_realtime_cpu_2kHz_3faces", "value": round(100 * share, 2),
           "unit": "%", "target": 20.0}
    nominal = load_plant_config().nominal()
    effects = _all_effects()
    for rate in (1000.0, 250.0):
        for label, config in (("nominal", nominal), ("all_effects", effects)):
            seconds = _offline_s(config, rate)
            steps = math.ceil(5000 / rate / config.rig.step_s)
            yield {"name": f"simulate_run_5000_samples_{int(rate)}Hz_{label}",
                   "value": round(seconds, 4), "unit": "s", "target": 0.5,
                   "model_steps": steps}
