"""The figures of a TE curve: peak-to-peak (GB/T 35089 transmission accuracy), ISO 1328-1
F'_i and f'_i, and the two-direction hysteresis (arcsec, arcmin)."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import maximum_filter1d, minimum_filter1d

from analysis.transmission.curve import DirectionCurve


def peak_to_peak_arcsec(curve: DirectionCurve) -> float:
    """GB/T 35089 transmission accuracy of one direction (arcsec): the largest minus the
    smallest TE over every complete output revolution recorded (the resampled grid)."""
    return float(np.ptp(curve.revs_arcsec))


def total_composite_arcsec(curve: DirectionCurve) -> float:
    """ISO 1328-1 F'_i, total single-flank composite deviation (arcsec): the peak-to-peak of
    the revolution-averaged TE over one revolution of the output."""
    return float(np.ptp(curve.mean_arcsec))


def tooth_to_tooth_arcsec(curve: DirectionCurve, output_teeth: int) -> float:
    """ISO 1328-1 f'_i, tooth-to-tooth single-flank composite deviation (arcsec): the largest
    TE change (max - min) within any window of one output tooth pitch ``360 / output_teeth``
    deg, over the revolution-averaged curve (periodic)."""
    n = curve.mean_arcsec.size
    width = max(2, int(round(n / float(output_teeth))) + 1)
    te = curve.mean_arcsec
    # a window of ``width`` grid points spans one pitch; centred filters wrap round
    hi = maximum_filter1d(te, size=width, mode="wrap")
    lo = minimum_filter1d(te, size=width, mode="wrap")
    return float(np.max(hi - lo))


def hysteresis_arcmin(forward: DirectionCurve, reverse: DirectionCurve) -> float:
    """The mean offset between the two directions' TE (arcmin): ``|c_forward - c_reverse| / 60``
    with ``c_d`` each direction's mean over the same output-angle grid (run-format.md). Under
    the brake torque this is the lost motion: free play plus the windup of both flanks."""
    return abs(forward.offset_arcsec - reverse.offset_arcsec) / 60.0
