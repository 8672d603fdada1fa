"""Seed 003: Monte Carlo of the planetary transmission error (section 2 and 3.3 of the paper).

Random variables (seed 003 section 2.2): eccentricities are Rayleigh (eq. 15) truncated at
``T = 2 sigma_0`` (eq. 16) with a uniform initial phase on [0, 2 pi) (eq. 12); tooth errors
are normal truncated at ``+-1.6 sigma`` with ``T/2 = 1.6 sigma`` (eq. 17).

Per sample the output transmission error ``dtheta(psi)`` (arcsec) is evaluated over one
output revolution on a grid fine enough for the fastest term, and its maximum ``|dtheta|`` is
kept. The evaluation is one matrix product per chunk of samples (phasors of the distinct
frequencies times a sine/cosine basis), so memory stays bounded whatever the sample count.

Three methods of the paper (all results in arcsec):

- :func:`monte_carlo` - random values and phases (Fig. 10: mean 191, std 53, 42..444);
- :func:`max_deviation` - every error at its bound, one common initial phase swept over
  [0, 2 pi) (Fig. 11: mean 539, std 36, 469..598);
- :func:`max_deviation_random_phase` - every error at its bound, random phases (Fig. 12:
  mean 477, std 71, 300..644).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from fractions import Fraction

import numpy as np

from analysis.errors import AnalysisError
from analysis.models.seed003_planetary import (
    ErrorSource,
    PlanetaryTrain,
    error_sources,
    paper_train,
)

RAYLEIGH_TRUNCATION_SIGMA = 2.0
"""Eccentricity bound in units of sigma_0: ``T = 2 sigma_0`` (paper section 2.2)."""
NORMAL_TRUNCATION_SIGMA = 1.6
"""Tooth error bound in units of sigma: ``T/2 = 1.6 sigma`` (eq. 17)."""
SAMPLE_CHUNK = 4096
"""Samples drawn and evaluated together; fixes the random stream for a given seed."""
EVAL_CHUNK = 256
"""Samples whose curves are evaluated together (about 4.6 MB of float32 curves)."""
GRID_ERROR_ARCSEC = 0.25
"""Largest amount by which the computed max |dtheta| may fall short of the true one."""
COARSE_TO_FINE = 4
"""Fine grid points per coarse interval (the coarse step is this many fine steps)."""

PAPER_FIGURES_ARCSEC: dict[str, dict[str, float]] = {
    "monte_carlo": {"mean": 191.0, "std": 53.0, "min": 42.0, "max": 444.0, "q9973": 355.0},
    "max_deviation": {"mean": 539.0, "std": 36.0, "min": 469.0, "max": 598.0},
    "max_deviation_random_phase": {
        "mean": 477.0,
        "std": 71.0,
        "min": 300.0,
        "max": 644.0,
        "q9973": 630.0,
    },
}
"""Seed 003 section 3.3 (Figs. 10-12) for the paper's example, arcsec. ``q9973`` is the upper
end of the paper's interval at confidence 0.9973."""

Progress = Callable[[int], None]
"""Called with the number of samples finished so far."""


@dataclass(frozen=True)
class MaxErrorStats:
    """Statistics of max |dtheta| over one output revolution (arcsec)."""

    mean_arcsec: float
    std_arcsec: float
    min_arcsec: float
    max_arcsec: float
    q9973_arcsec: float
    samples: int

    def as_dict(self) -> dict[str, float | int]:
        """``{mean, std, min, max, q9973, samples}`` in arcsec, as the CLI writes it: each field
        under its name without ``_arcsec``."""
        return {f.name.removesuffix("_arcsec"): getattr(self, f.name) for f in fields(self)}


def stats_of(max_abs_arcsec: np.ndarray) -> MaxErrorStats:
    """Mean, standard deviation (ddof 1), extremes and the 99.73 % quantile (the paper's
    "confidence coefficient 0.9973" upper bound) of per-sample maxima."""
    values = np.asarray(max_abs_arcsec, dtype=float)
    if values.size == 0:
        raise AnalysisError("no samples to take statistics of")
    return MaxErrorStats(
        mean_arcsec=float(values.mean()),
        std_arcsec=float(values.std(ddof=1)) if values.size > 1 else 0.0,
        min_arcsec=float(values.min()),
        max_arcsec=float(values.max()),
        q9973_arcsec=float(np.quantile(values, 0.9973)),
        samples=int(values.size),
    )


class TransmissionErrorModel:
    """The sources of a train grouped by frequency, ready to evaluate.

    ``window_revs``: output revolutions over which max |dtheta| is taken (1 by default).

    :meth:`max_abs_arcsec` is accurate to ``grid_error_arcsec`` (it never overstates the
    maximum and falls short of it by at most that much). With ``C = sum_k |Z_k| nu_k^2`` a
    bound of ``|dtheta''|`` (arcsec/rad^2), a curve lies at most ``C h^2 / 8`` above the chord
    of an interval of width ``h`` and, at its maximum where the slope is zero, at most
    ``C h^2 / 8`` above the nearest point of a grid of step ``2 h``. So the curve is evaluated on
    a coarse grid, and only the intervals that could hold a higher value than the coarse
    maximum are evaluated again on a fine grid whose step keeps ``C h^2 / 8`` under the
    tolerance.
    """

    def __init__(
        self,
        sources: Sequence[ErrorSource],
        window_revs: float = 1.0,
        grid_error_arcsec: float = GRID_ERROR_ARCSEC,
    ) -> None:
        if not sources:
            raise AnalysisError("the model has no error sources")
        if not (window_revs > 0 and math.isfinite(window_revs)):
            raise AnalysisError(f"window_revs must be positive, got {window_revs}")
        if not (grid_error_arcsec > 0 and math.isfinite(grid_error_arcsec)):
            raise AnalysisError(f"grid_error_arcsec must be positive, got {grid_error_arcsec}")
        self.sources = tuple(sources)
        self.frequencies = np.array(sorted({s.frequency_per_rev for s in self.sources}))
        index = {f: k for k, f in enumerate(self.frequencies)}
        # mixing[s, k] = weight of source s in the phasor of frequency k
        self.mixing = np.zeros((len(self.sources), self.frequencies.size), dtype=complex)
        for row, source in enumerate(self.sources):
            self.mixing[row, index[source.frequency_per_rev]] = source.weight
        self.bounds_um = np.array([s.bound_um for s in self.sources])
        self.has_phase = np.array([s.has_phase for s in self.sources])
        self.grid_error_arcsec = grid_error_arcsec
        amplitudes = np.abs(self.bounds_um[:, None] * self.mixing).sum(axis=0)
        curvature = float(amplitudes @ self.frequencies**2)  # largest C over all draws
        span = 2.0 * math.pi * window_revs
        fine_step = math.sqrt(8.0 * grid_error_arcsec / curvature) if curvature > 0 else span
        n_coarse = max(64, int(math.ceil(span / (COARSE_TO_FINE * fine_step))))
        self.coarse_step_rad = span / n_coarse
        self.psi_rad = np.linspace(0.0, span, n_coarse + 1)
        self._coarse32 = self._basis(self.psi_rad).astype(np.float32)
        n_fine = max(1, int(math.ceil(self.coarse_step_rad / fine_step)) - 1)
        offsets = np.arange(1, n_fine + 1) * (self.coarse_step_rad / (n_fine + 1))
        self._fine32 = self._basis(offsets).astype(np.float32)
        self._rotations = np.exp(1j * np.outer(self.psi_rad[:-1], self.frequencies))

    def _basis(self, psi_rad: np.ndarray) -> np.ndarray:
        """Rows ``cos(nu_k psi)`` then ``sin(nu_k psi)``: ``dtheta = [Im Z, Re Z] @ basis``."""
        angles = np.outer(self.frequencies, psi_rad)
        return np.vstack([np.cos(angles), np.sin(angles)])

    def phasors(self, values_um: np.ndarray, phases_rad: np.ndarray) -> np.ndarray:
        """Complex amplitude per frequency, shape (samples, frequencies), arcsec."""
        rotated = values_um * np.where(self.has_phase, np.exp(1j * phases_rad), 1.0)
        return np.einsum("ns,sk->nk", rotated, self.mixing)

    def transmission_error_arcsec(
        self, values_um: np.ndarray, phases_rad: np.ndarray, psi_rad: np.ndarray
    ) -> np.ndarray:
        """``dtheta(psi)`` at the output (arcsec), shape (samples, len(psi)); eq. (11)."""
        z = self.phasors(np.atleast_2d(values_um), np.atleast_2d(phases_rad))
        return np.hstack([z.imag, z.real]) @ self._basis(np.asarray(psi_rad, dtype=float))

    def max_abs_arcsec(self, values_um: np.ndarray, phases_rad: np.ndarray) -> np.ndarray:
        """max over the window of |dtheta| per sample (arcsec), within ``grid_error_arcsec``.

        Evaluated ``EVAL_CHUNK`` samples at a time in float32 (7 significant digits, far
        below the tolerance), so the curves of one chunk stay in the processor's cache. The
        products use ``np.einsum`` (one thread) rather than ``@``: with 20 inner terms the
        multi-threaded BLAS spends its time waiting on its threads, 3-4 times slower on a
        busy 2-core machine (bench/bench_montecarlo.py).
        """
        z = self.phasors(np.atleast_2d(values_um), np.atleast_2d(phases_rad))
        out = np.empty(z.shape[0])
        for start in range(0, z.shape[0], EVAL_CHUNK):
            out[start : start + EVAL_CHUNK] = self._chunk_max(z[start : start + EVAL_CHUNK])
        return out

    def _chunk_max(self, z: np.ndarray) -> np.ndarray:
        coeffs = np.hstack([z.imag, z.real]).astype(np.float32)
        coarse = np.abs(np.einsum("nk,kt->nt", coeffs, self._coarse32))
        best = coarse.max(axis=1)
        slack = (np.abs(z) @ self.frequencies**2) * self.coarse_step_rad**2 / 8.0
        ends = np.maximum(coarse[:, :-1], coarse[:, 1:])
        rows, cols = np.nonzero(ends + (slack + 1e-4 * best)[:, None] >= best[:, None])
        if rows.size:
            shifted = z[rows] * self._rotations[cols]
            parts = np.hstack([shifted.imag, shifted.real]).astype(np.float32)
            fine = np.abs(np.einsum("nk,kt->nt", parts, self._fine32))
            np.maximum.at(best, rows, fine.max(axis=1))
        return best


def draw_values_um(
    sources: Sequence[ErrorSource], n: int, rng: np.random.Generator, at_bound: bool = False
) -> np.ndarray:
    """Error values (um), shape (n, sources), by inverse transform sampling.

    Eccentricities: ``E = sigma_0 sqrt(-2 ln(1 - u (1 - q)))``, the inverse of the truncated
    Rayleigh distribution of eq. (16) with ``q = exp(-2)`` (``T = 2 sigma_0``). Tooth errors:
    the inverse of the truncated normal of eq. (17) on ``[-T/2, T/2]``, ``T/2 = 1.6 sigma``.
    ``at_bound``: every error at its bound (the maximum deviation method; ``f = +T/2``).
    """
    bounds = np.array([s.bound_um for s in sources])
    if at_bound:
        return np.broadcast_to(bounds, (n, bounds.size)).copy()
    has_phase = np.array([s.has_phase for s in sources])
    u = rng.random((n, bounds.size))
    sigma0 = bounds / RAYLEIGH_TRUNCATION_SIGMA
    q = math.exp(-(RAYLEIGH_TRUNCATION_SIGMA**2) / 2.0)
    eccentric = sigma0 * np.sqrt(-2.0 * np.log1p(-u * (1.0 - q)))
    from scipy.special import ndtr, ndtri  # imported here: scipy.special costs a CLI start

    lo = ndtr(-NORMAL_TRUNCATION_SIGMA)
    hi = ndtr(NORMAL_TRUNCATION_SIGMA)
    tooth = (bounds / NORMAL_TRUNCATION_SIGMA) * ndtri(lo + u * (hi - lo))
    return np.where(has_phase, eccentric, tooth)


def draw_phases_rad(n: int, n_sources: int, rng: np.random.Generator) -> np.ndarray:
    """Initial phases uniform on [0, 2 pi) (eq. 12), shape (n, sources)."""
    return rng.uniform(0.0, 2.0 * math.pi, size=(n, n_sources))


def check_sample_count(n_samples: int) -> None:
    """Raise :class:`AnalysisError` unless ``n_samples`` is an integer >= 2."""
    if isinstance(n_samples, bool) or not isinstance(n_samples, int | np.integer):
        raise AnalysisError(f"the sample count must be an integer, got {n_samples!r}")
    if n_samples < 2:
        raise AnalysisError(f"the sample count must be at least 2, got {n_samples}")


def _sampled_maxima(
    model: TransmissionErrorModel,
    n_samples: int,
    seed: int,
    values_at_bound: bool,
    progress: Progress | None,
) -> np.ndarray:
    check_sample_count(n_samples)
    rng = np.random.default_rng(seed)
    maxima = np.empty(n_samples)
    for start in range(0, n_samples, SAMPLE_CHUNK):
        n = min(SAMPLE_CHUNK, n_samples - start)
        values = draw_values_um(model.sources, n, rng, at_bound=values_at_bound)
        phases = draw_phases_rad(n, len(model.sources), rng)
        maxima[start : start + n] = model.max_abs_arcsec(values, phases)
        if progress is not None:
            progress(start + n)
    return maxima


def monte_carlo(
    train: PlanetaryTrain | None = None,
    n_samples: int = 50_000,
    seed: int = 0,
    progress: Progress | None = None,
    window_revs: float = 1.0,
) -> MaxErrorStats:
    """Random values (eqs. 15-17) and phases (eq. 12): the paper's Fig. 10 statistics."""
    return _sampled_stats(train, n_samples, seed, False, progress, window_revs)


def max_deviation_random_phase(
    train: PlanetaryTrain | None = None,
    n_samples: int = 50_000,
    seed: int = 0,
    progress: Progress | None = None,
    window_revs: float = 1.0,
) -> MaxErrorStats:
    """Every error at its bound, random phases: the paper's Fig. 12 statistics."""
    return _sampled_stats(train, n_samples, seed, True, progress, window_revs)


def _sampled_stats(train: PlanetaryTrain | None, n_samples: int, seed: int, at_bound: bool,
                   progress: Progress | None, window_revs: float) -> MaxErrorStats:
    """Statistics of the sampled maxima of ``train`` (default: the paper's), arcsec."""
    model = TransmissionErrorModel(error_sources(train or paper_train()), window_revs)
    return stats_of(_sampled_maxima(model, n_samples, seed, at_bound, progress))


def max_deviation(
    train: PlanetaryTrain | None = None, n_phases: int = 360, window_revs: float = 1.0
) -> MaxErrorStats:
    """Every error at its bound and one common initial phase, swept over ``n_phases`` equal
    steps of [0, 2 pi): the paper's "maximum deviation method" (Fig. 11)."""
    check_sample_count(n_phases)
    model = TransmissionErrorModel(error_sources(train or paper_train()), window_revs)
    values = draw_values_um(model.sources, n_phases, np.random.default_rng(0), at_bound=True)
    common = np.arange(n_phases) * (2.0 * math.pi / n_phases)
    phases = np.repeat(common[:, None], len(model.sources), axis=1)
    return stats_of(model.max_abs_arcsec(values, phases))


@dataclass(frozen=True)
class SourceInfluence:
    """How much one error source matters at the output (arcsec)."""

    name: str
    description: str
    frequency_per_rev: float
    sensitivity_arcsec_per_um: float
    amplitude_at_bound_arcsec: float
    mean_amplitude_arcsec: float
    mean_reduction_arcsec: float

    def as_dict(self) -> dict[str, float | str]:
        """Every field under its own name, but ``name`` under ``source``."""
        return {("source" if f.name == "name" else f.name): getattr(self, f.name)
                for f in fields(self)}


def sensitivity_ranking(
    train: PlanetaryTrain | None = None, n_samples: int = SAMPLE_CHUNK, seed: int = 0
) -> tuple[SourceInfluence, ...]:
    """Rank the sources by how much the Monte Carlo mean of max |dtheta| drops when the
    source is removed (common random numbers: the same draws with that one value zeroed).

    Also gives each source's term amplitude per um, at its bound, and its mean amplitude
    over the draws (``|W| * E|v|``).
    """
    check_sample_count(n_samples)
    sources = error_sources(train or paper_train())
    model = TransmissionErrorModel(sources)
    rng = np.random.default_rng(seed)
    values = draw_values_um(sources, n_samples, rng)
    phases = draw_phases_rad(n_samples, len(sources), rng)
    base = float(model.max_abs_arcsec(values, phases).mean())
    ranking = []
    for column, source in enumerate(sources):
        without = values.copy()
        without[:, column] = 0.0
        reduced = float(model.max_abs_arcsec(without, phases).mean())
        sensitivity = source.sensitivity_arcsec_per_um
        ranking.append(
            SourceInfluence(
                name=source.name,
                description=source.description,
                frequency_per_rev=source.frequency_per_rev,
                sensitivity_arcsec_per_um=sensitivity,
                amplitude_at_bound_arcsec=sensitivity * source.bound_um,
                mean_amplitude_arcsec=sensitivity * float(np.abs(values[:, column]).mean()),
                mean_reduction_arcsec=base - reduced,
            )
        )
    ranking.sort(key=lambda item: item.mean_reduction_arcsec, reverse=True)
    return tuple(ranking)


@dataclass(frozen=True)
class Spectrum:
    """Mean amplitude spectrum of dtheta (arcsec) over sampled trains, without its mean.

    ``dominant_sources``: the sources at the highest line, largest mean amplitude first.
    """

    frequency_per_rev: np.ndarray
    amplitude_arcsec: np.ndarray
    dominant_frequency_per_rev: float
    dominant_amplitude_arcsec: float
    dominant_sources: tuple[str, ...]


def _common_period_revs(frequencies: np.ndarray, max_revs: int = 10_000) -> int:
    """Smallest whole number of output revolutions over which every line is periodic."""
    period = 1
    for f in frequencies:
        denominator = Fraction(float(abs(f))).limit_denominator(1000).denominator
        period = period * denominator // math.gcd(period, denominator)
    if period > max_revs:
        raise AnalysisError(f"the lines share no period under {max_revs} output revolutions")
    return period


def spectrum(
    train: PlanetaryTrain | None = None, n_samples: int = 32, seed: int = 0
) -> Spectrum:
    """FFT of ``dtheta(psi)`` over the lines' common period, averaged over ``n_samples``
    Monte Carlo trains (the paper's Fig. 13 analysis). Frequencies in cycles per output
    revolution; the mean (constant tooth errors and pin offsets) is left out."""
    check_sample_count(n_samples)
    sources = error_sources(train or paper_train())
    model = TransmissionErrorModel(sources)
    revs = _common_period_revs(model.frequencies)
    fastest = float(np.abs(model.frequencies).max())
    per_rev = 1 << max(6, math.ceil(math.log2(4.0 * fastest)))
    psi = np.arange(revs * per_rev) * (2.0 * math.pi / per_rev)
    rng = np.random.default_rng(seed)
    values = draw_values_um(sources, n_samples, rng)
    phases = draw_phases_rad(n_samples, len(sources), rng)
    total = np.zeros(psi.size // 2 + 1)
    for start in range(0, n_samples, 8):
        curves = model.transmission_error_arcsec(
            values[start : start + 8], phases[start : start + 8], psi
        )
        total += np.abs(np.fft.rfft(curves, axis=1)).sum(axis=0)
    amplitude = total / n_samples * (2.0 / psi.size)
    amplitude[0] = 0.0
    frequency = np.fft.rfftfreq(psi.size, d=1.0 / per_rev)
    peak = int(np.argmax(amplitude))
    at_peak = [
        (float(np.abs(values[:, k]).mean()) * s.sensitivity_arcsec_per_um, s.name)
        for k, s in enumerate(sources)
        if abs(abs(s.frequency_per_rev) - frequency[peak]) < 0.5 / revs
    ]
    at_peak.sort(reverse=True)
    return Spectrum(
        frequency_per_rev=frequency,
        amplitude_arcsec=amplitude,
        dominant_frequency_per_rev=float(frequency[peak]),
        dominant_amplitude_arcsec=float(amplitude[peak]),
        dominant_sources=tuple(name for _, name in at_peak),
    )
