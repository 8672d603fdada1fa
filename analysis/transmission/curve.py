"""Transmission error curves of a TE run, per direction (docs/run-format.md, "A transmission
error run").

TE (arcsec) is ``3600 (output_angle_deg - input_angle_deg / ratio - c_d)`` (ISO 1328-1
single-flank composite: the driven member's angular deviation from its ideal position), with
``c_d`` the mean of direction ``d``. The samples of each direction are averaged into a uniform
grid of the output angle (bins of ``360 / n_grid`` deg, aligned on the absolute output angle so
both directions share the grid), empty bins filled by linear interpolation; the grid over all
complete revolutions is then folded modulo 360 deg into one revolution's mean curve.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis.errors import AnalysisError

ARCSEC_PER_DEG = 3600.0
DIRECTIONS = {1: "forward", -1: "reverse"}
"""The ``direction`` column's codes and their names (0: stopping / turning round, not used)."""


def te_arcsec(output_angle_deg: np.ndarray, input_angle_deg: np.ndarray, ratio: float
              ) -> np.ndarray:
    """Uncentred TE (arcsec): ``3600 (output - input / ratio)``; run-format.md's definition
    before the mean ``c_d`` is taken away. ``ratio`` is the signed reduction ratio ``i``."""
    if not ratio or not np.isfinite(ratio):
        raise AnalysisError(f"test.ratio must be a finite non-zero number, got {ratio!r}")
    out = np.asarray(output_angle_deg, dtype=float)
    inp = np.asarray(input_angle_deg, dtype=float)
    return ARCSEC_PER_DEG * (out - inp / float(ratio))


@dataclass(frozen=True)
class DirectionCurve:
    """One direction's TE on the output-angle grid.

    ``grid_deg``: the grid over one revolution (``0 .. 360 - step``, deg);
    ``mean_arcsec``: the revolution-averaged TE at ``grid_deg`` (centred: zero mean);
    ``revs_arcsec``: each complete revolution's TE (revolutions x grid, centred by the same
    ``c_d``); ``offset_arcsec``: ``c_d`` (the uncentred mean, for the hysteresis);
    ``residual_std_arcsec``: the noise of one sample (arcsec; a run's analysis: from the
    samples' and the bins' pseudo-residuals, :func:`analysis.transmission.evaluate.noise_std`;
    the plain binned curve below: the spread of the samples about their bin means);
    ``samples_per_bin``: mean count of samples per bin; ``revolutions``: complete revolutions.
    """

    direction: int
    grid_deg: np.ndarray
    mean_arcsec: np.ndarray
    revs_arcsec: np.ndarray
    offset_arcsec: float
    residual_std_arcsec: float
    samples_per_bin: float
    revolutions: int
    n_samples: int
    span_deg: tuple[float, float] = (-np.inf, np.inf)
    """The output angles (deg, absolute) of the complete revolutions used."""

    @property
    def name(self) -> str:
        return DIRECTIONS[self.direction]


def _fill_empty(values: np.ndarray, filled: np.ndarray) -> np.ndarray:
    """Linear interpolation of the bins without samples from their neighbours."""
    if filled.all():
        return values
    idx = np.arange(values.size)
    out = values.copy()
    out[~filled] = np.interp(idx[~filled], idx[filled], values[filled])
    return out


def direction_curve(output_angle_deg: np.ndarray, te_raw_arcsec: np.ndarray, direction: int,
                    n_grid: int) -> DirectionCurve:
    """Resample one direction's samples onto the grid of ``n_grid`` bins per output revolution.

    Bins are ``floor(theta / step)`` of the absolute output angle ``theta`` (deg), so bin ``k``
    of every revolution is the same output position. Only complete revolutions count: the
    first ``revolutions * n_grid`` consecutive bins from the first full bin.
    """
    theta = np.asarray(output_angle_deg, dtype=float)
    te = np.asarray(te_raw_arcsec, dtype=float)
    ok = np.isfinite(theta) & np.isfinite(te)
    theta, te = theta[ok], te[ok]
    if theta.size < 2:
        raise AnalysisError(f"{DIRECTIONS[direction]}: fewer than 2 finite samples")
    step = 360.0 / n_grid
    bins = np.floor(theta / step).astype(np.int64)
    first, last = int(bins.min()), int(bins.max())
    span = last - first + 1
    revolutions = span // n_grid
    if revolutions < 1:
        raise AnalysisError(
            f"{DIRECTIONS[direction]}: the output turned {np.ptp(theta):.1f} deg; a TE run needs "
            "at least one full output revolution in each direction")
    # start where the whole revolutions fit, centred in the recorded span
    start = first + (span - revolutions * n_grid) // 2
    rel = bins - start
    keep = (rel >= 0) & (rel < revolutions * n_grid)
    rel, te_k = rel[keep], te[keep]
    counts = np.bincount(rel, minlength=revolutions * n_grid).astype(float)
    sums = np.bincount(rel, weights=te_k, minlength=revolutions * n_grid)
    filled = counts > 0
    if filled.sum() < 2:
        raise AnalysisError(f"{DIRECTIONS[direction]}: too few samples for the output grid")
    means = np.zeros_like(sums)
    means[filled] = sums[filled] / counts[filled]
    residual = te_k - means[rel]
    dof = max(int(te_k.size - filled.sum()), 1)
    residual_std = float(np.sqrt(np.sum(residual**2) / dof)) if te_k.size > filled.sum() else 0.0
    seq = _fill_empty(means, filled)
    offset = float(seq.mean())
    revs = (seq - offset).reshape(revolutions, n_grid)
    # rotate so column j is the absolute output angle j * step (mod 360)
    shift = int(start % n_grid)
    revs = np.roll(revs, shift, axis=1)
    grid = np.arange(n_grid) * step
    return DirectionCurve(
        direction=direction, grid_deg=grid, mean_arcsec=revs.mean(axis=0), revs_arcsec=revs,
        offset_arcsec=offset, residual_std_arcsec=residual_std,
        samples_per_bin=float(counts[filled].mean()), revolutions=int(revolutions),
        n_samples=int(te_k.size),
        span_deg=(start * step, (start + revolutions * n_grid) * step))


def grid_size(mesh_order_per_output_rev: float | None, samples_per_rev: float) -> int:
    """Bins per output revolution: at least 8 per mesh cycle and 360 in all, at most one per
    two samples (so bins hold samples), a multiple of 360 for round angles."""
    want = max(360.0, 8.0 * abs(mesh_order_per_output_rev or 0.0))
    want = min(want, max(360.0, samples_per_rev / 2.0))
    return int(np.ceil(want / 360.0) * 360)
