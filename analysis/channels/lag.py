"""The lag between a run's torque and twist channels, as ``rig analyse`` reports it per run.

Pure numerics (numpy only): kept out of :mod:`analysis.diagnosis` so that analysing one run
does not load the diagnosis and scipy.stats (about 1.6 s of every ``rig measure`` and
``rig analyse``)."""

from __future__ import annotations

import numpy as np

from analysis.channels.artefacts import best_torque_shift

#: Samples the reversal tracker (:func:`direction_and_reversal`) reads at a time as Python
#: floats: a long run is never held as one list.
DIRECTION_CHUNK = 1 << 16


def direction_and_reversal(t_s: np.ndarray, torque_Nm: np.ndarray, threshold_Nm: float
                           ) -> tuple[np.ndarray, np.ndarray]:
    """Torque direction (+1 rising, -1 falling) with hysteresis ``threshold_Nm`` and the time
    (s) since the last reversal (the running extreme) for every sample."""
    n = int(torque_Nm.size)
    direction = np.empty(n)
    since = np.empty(n)
    d = 1.0
    extreme = float(torque_Nm[0]) if n else 0.0
    t_ext = float(t_s[0]) if n else 0.0
    for a in range(0, n, DIRECTION_CHUNK):
        values = torque_Nm[a:a + DIRECTION_CHUNK].tolist()
        times = t_s[a:a + DIRECTION_CHUNK].tolist()
        dirs = [0.0] * len(values)
        ages = [0.0] * len(values)
        for k, v in enumerate(values):
            if d > 0:
                if v >= extreme:
                    extreme, t_ext = v, times[k]
                elif v < extreme - threshold_Nm:
                    d, extreme, t_ext = -1.0, v, times[k]
            else:
                if v <= extreme:
                    extreme, t_ext = v, times[k]
                elif v > extreme + threshold_Nm:
                    d, extreme, t_ext = 1.0, v, times[k]
            dirs[k] = d
            ages[k] = times[k] - t_ext
        direction[a:a + len(values)] = dirs
        since[a:a + len(values)] = ages
    return direction, since


#: Largest lag between the channels searched (samples).
MAX_LAG_SAMPLES = 10
#: In-sample evidence (chi2 units, like a BIC difference) a lag needs to be corrected.
LAG_EVIDENCE = 10.0


def channel_lag_samples(t: np.ndarray, torque: np.ndarray, twist: np.ndarray,
                        sigma: float) -> int:
    """Lag (samples) of the twist behind the torque channel (negative: ahead): the integer
    shift that best explains the loaded flanks (:func:`analysis.channels.artefacts
    .best_torque_shift`), kept only when it improves them by LAG_EVIDENCE noise-units over no
    shift (a filter or transport delay of one channel; with constant-rate ramps only it looks
    like friction and is not found). ``rig analyse`` reports it per run; the diagnosis
    estimates the lag to a quarter sample (:func:`analysis.channels.artefacts
    .torque_lag_s`)."""
    n = torque.size
    amplitude = float(np.percentile(np.abs(torque), 99.5))
    if n < 200 or amplitude <= 0:
        return 0
    dt = float(np.median(np.diff(t)))
    lmax = min(MAX_LAG_SAMPLES, n // 100)
    direction, _ = direction_and_reversal(t, torque, 0.02 * amplitude)
    tau = best_torque_shift(t, torque, twist, direction, sigma,
                            np.arange(-lmax, lmax + 1) * dt, LAG_EVIDENCE, friction_aware=False)
    return int(round(tau / dt)) if dt > 0 else 0
