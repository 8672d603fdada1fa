"""Decisions calibrated by the campaign's own residual structure (issue 20, point 2).

Pure numerics. The question behind every decision of the diagnosis is "could the null model
with this campaign's own measuring errors have produced evidence this strong by chance?". The
errors of a real rig are not white: drive ripple aliased by the sampling, a torque zero that
wanders, vibration after impacts, quantisation held over many samples. So the chance
distribution is not a textbook one; it is made from the campaign itself:

1. **Null residuals.** The null model (free play and stiffness, run offsets, the measuring
   system's nuisance: :mod:`analysis.channels.artefacts`) is fitted by weighted least
   squares. What any candidate or the lack-of-fit test could hold is projected out of its
   standardised residuals (:func:`pure_error`): the rest is the measuring errors alone.
   Residuals are winsorised at HUBER_C robust sigmas of those errors (an impact sample that
   survived the transient rule must not decide alone).
2. **Moving-block bootstrap** (Kuensch 1989) of the measuring errors, run by run, in time
   order: blocks as long as twice their integrated autocorrelation time, so each replicate
   keeps their correlation (ripple, a wandering zero, vibration) and distribution but has no
   alignment with torque, flank, position or temperature, which is what an effect has.
3. **Evidence of a candidate** is the squared norm of the residuals' projection on the
   candidate's own columns (made orthogonal to the null's), maximised over a grid of its
   nonlinear parameter: a score statistic, the chi-square gain of adding the candidate.
   For friction and a sensor offset, which move the flank switches, the column is the
   change of the null prediction when the parameter is switched on.
4. **Tail.** The bootstrap replicates' statistics give each candidate's chance distribution;
   it is matched by a scaled chi-square ``a chi2_nu`` (Satterthwaite: same mean and variance)
   so that small probabilities are read from a smooth tail, not counted out of B replicates.
5. **Several candidates at once.** The probability that *any* candidate reaches its evidence
   by chance: with ``k_eff`` effectively independent tests, ``1 - (1 - p)^k_eff``; ``k_eff``
   is read from the replicates' smallest p-values (their mean is ``1 / (k_eff + 1)`` for
   independent tests), between 1 and the number of candidates. That is each candidate's
   ``false_alarm_probability``; an effect is called at level ``alpha``.

An omnibus lack-of-fit statistic (the residual's structure by torque band, flank and branch,
and a play of its own for each run) is calibrated the same way: a systematic gap that no
candidate of the vocabulary holds is ``unexplained`` only when the omnibus says so.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

#: Bootstrap replicates: enough for the mean and variance of each chance distribution.
REPLICATES = 199
#: Residuals are winsorised at this many robust sigmas (the fit's Huber constant).
HUBER_C = 2.5
#: Torque bands of the omnibus lack-of-fit statistic (share of each run's amplitude).
BANDS = (0.0, 0.05, 0.1, 0.2, 0.35, 0.5, 0.7, 0.85, 1.01)


@dataclass(frozen=True)
class Calibrated:
    """Evidence of one candidate and its chance distribution under the null."""

    statistic: float
    p_value: float  # one test alone
    false_alarm_probability: float  # any of the candidates by chance
    scale: float
    dof: float

    def to_dict(self, replicates: int | None = None) -> dict[str, float]:
        """The evidence as the report states it; with ``replicates``, the false-alarm
        probability floored at the calibration's resolution (:func:`floored`)."""
        fap = self.false_alarm_probability
        return {"statistic": self.statistic, "p_value": self.p_value,
                "false_alarm_probability": fap if replicates is None
                else floored(fap, replicates),
                "null_scale": self.scale, "null_dof": self.dof}


def resolution(replicates: int) -> float:
    """The smallest false-alarm probability a calibration on ``replicates`` bootstrap draws
    can state, ``1 / (replicates + 1)``: the scaled chi-square tail is matched to the draws'
    mean and variance, so a probability below the draws' own reach is the tail's
    extrapolation, not something the draws observed. A report never states less."""
    return 1.0 / (max(int(replicates), 0) + 1.0)


def floored(p: float | None, replicates: int) -> float | None:
    """A false-alarm probability as the report states it: at least :func:`resolution`
    (``None`` and NaN pass unchanged). The decisions compare the unfloored value with
    ``alpha``; at the default ``alpha`` (0.01) and ``REPLICATES`` (199, resolution 0.005)
    the two give the same decisions."""
    if p is None or not math.isfinite(p):
        return p
    return max(float(p), resolution(replicates))


def block_length(z: np.ndarray) -> int:
    """Moving-block length (points) for a residual series: twice its integrated
    autocorrelation time ``1 + 2 sum rho_k`` over the lags before the autocorrelation first
    falls inside ``2 / sqrt(n)``; between 1 and n / 4."""
    n = z.size
    if n < 8:
        return 1
    x = z - z.mean()
    var = float(x @ x)
    if var <= 0:
        return 1
    f = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(f * np.conj(f))[: n // 4] / var
    band = 2.0 / math.sqrt(n)
    tau = 1.0
    for k in range(1, acf.size):
        if acf[k] < band:
            break
        tau += 2.0 * float(acf[k])
    return int(min(max(1, math.ceil(2.0 * tau)), max(1, n // 4)))


def bootstrap(z_runs: Sequence[np.ndarray], replicates: int, rng: np.random.Generator
              ) -> np.ndarray:
    """Circular moving-block bootstrap of each run's residual series (time order); returns
    (points, replicates) with the runs stacked as in ``z_runs``."""
    out = []
    for z in z_runs:
        n = z.size
        if n == 0:
            out.append(np.zeros((0, replicates)))
            continue
        length = block_length(z)
        k = math.ceil(n / length)
        starts = rng.integers(0, n, size=(replicates, k))
        idx = ((starts[:, :, None] + np.arange(length)) % n).reshape(replicates, -1)[:, :n]
        out.append(z[idx].T)
    return np.vstack(out)


def orthonormal(Z: np.ndarray, Qb: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the columns of ``Z`` with the span of ``Qb`` (orthonormal) taken
    out; columns that vanish there are dropped."""
    if Z.ndim == 1:
        Z = Z[:, None]
    Zp = Z - Qb @ (Qb.T @ Z)
    if Zp.size == 0:
        return np.zeros((Z.shape[0], 0))
    if Zp.shape[1] == 1:  # one column keeps its sign (a one-sided test reads it)
        norm = float(np.linalg.norm(Zp))
        scale = float(np.linalg.norm(Z))
        return Zp / norm if norm > 1e-9 * max(scale, 1e-300) else np.zeros((Z.shape[0], 0))
    U, s, _ = np.linalg.svd(Zp, full_matrices=False)
    top = float(s.max()) if s.size else 0.0
    return U[:, s > 1e-9 * max(top, 1e-300)] if top > 0 else np.zeros((Z.shape[0], 0))


def winsorise(e: np.ndarray) -> np.ndarray:
    """Residuals clipped at HUBER_C robust sigmas (MAD)."""
    s = 1.4826 * float(np.median(np.abs(e - np.median(e))))
    if s <= 0:
        return e
    return np.clip(e, -HUBER_C * s, HUBER_C * s)


def score(blocks: Sequence[np.ndarray], V: np.ndarray, one_sided: bool = False) -> np.ndarray:
    """max over blocks of ||Q' v||^2 for each column v of V (or the vector V). ``one_sided``:
    single-column blocks count only a positive projection (a parameter bounded at zero: a
    friction, a stiffening or a soft stage, which cannot take the other sign)."""
    vec = V.ndim == 1
    V2 = V[:, None] if vec else V
    best = np.zeros(V2.shape[1])
    for Q in blocks:
        if Q.shape[1]:
            proj = Q.T @ V2
            if one_sided and Q.shape[1] == 1:
                proj = np.maximum(proj, 0.0)
            best = np.maximum(best, np.sum(proj**2, axis=0))
    return best[0] if vec else best


def scaled_chi2(samples: np.ndarray) -> tuple[float, float]:
    """(a, nu) of ``a chi2_nu`` with the samples' mean and variance (Satterthwaite)."""
    m = float(np.mean(samples))
    v = float(np.var(samples, ddof=1)) if samples.size > 1 else 0.0
    if m <= 0 or v <= 0:
        return max(m, 1e-12), 1.0
    return v / (2.0 * m), max(2.0 * m * m / v, 0.1)


def pure_error(e: np.ndarray, blocks: dict[str, list[np.ndarray]]) -> np.ndarray:
    """The null residual with everything any candidate or the lack-of-fit test could hold
    projected out, rescaled for the dimensions removed: what is left is the measuring
    errors alone, in time order, whatever effect the data hold. Its bootstrap replicates are
    the chance evidence; resampling the null residual itself would either count a real
    effect as noise (short blocks) or carry its alignment with the loading into every
    replicate (long blocks over a periodic loading)."""
    cols = [Q for v in blocks.values() for Q in v if Q.shape[1]]
    if not cols:
        return e
    U, sv, _ = np.linalg.svd(np.hstack(cols), full_matrices=False)
    U = U[:, sv > 1e-9 * float(sv.max())]
    left = e - U @ (U.T @ e)
    dof = e.size - U.shape[1]
    return left * math.sqrt(e.size / dof) if dof > 0 else left


def calibrate(blocks: dict[str, list[np.ndarray]], e: np.ndarray, z_runs_index: list[slice],
              replicates: int = REPLICATES, seed: int = 0, apart: Sequence[str] = (),
              one_sided: Sequence[str] = ()) -> dict[str, Calibrated]:
    """Calibrated evidence of each named family of column blocks (already orthonormal and
    orthogonal to the null's columns) on the null residual ``e`` (weighted, points stacked
    by run, ``z_runs_index`` the runs' slices). See the module docstring. Names in ``apart``
    are calibrated alone (not counted among the candidates tested together); names in
    ``one_sided`` have single-column blocks whose parameter cannot change sign."""
    rng = np.random.default_rng(seed)
    pure = pure_error(e, blocks)
    scale = 1.4826 * float(np.median(np.abs(pure - np.median(pure))))
    clip = HUBER_C * scale if scale > 0 else math.inf
    ew = np.clip(e, -clip, clip)
    E = bootstrap([np.clip(pure[s], -clip, clip) for s in z_runs_index], replicates, rng)
    names = [k for k, v in blocks.items() if any(Q.shape[1] for Q in v)]
    if not names:
        return {}
    obs = {k: float(score(blocks[k], ew, k in one_sided)) for k in names}
    boot = {k: score(blocks[k], E, k in one_sided) for k in names}
    fits = {k: scaled_chi2(boot[k]) for k in names}
    p_obs = {k: float(chi2.sf(obs[k] / fits[k][0], fits[k][1])) for k in names}
    family = [k for k in names if k not in apart]
    out: dict[str, Calibrated] = {}
    for k in names:
        if k not in family:
            out[k] = Calibrated(obs[k], p_obs[k], p_obs[k], fits[k][0], fits[k][1])
    if not family:
        return out
    names = family
    # effectively independent tests, from the replicates' smallest p-values
    p_rep = np.vstack([chi2.sf(boot[k] / fits[k][0], fits[k][1]) for k in names])
    m = float(np.mean(np.min(p_rep, axis=0)))
    k_eff = min(float(len(names)), max(1.0, 1.0 / max(m, 1e-12) - 1.0))
    for k in names:
        p = p_obs[k]
        fap = float(-np.expm1(k_eff * np.log1p(-min(p, 1.0 - 1e-16))))
        out[k] = Calibrated(obs[k], p, fap, fits[k][0], fits[k][1])
    return out


def omnibus_blocks(torque: np.ndarray, flank: np.ndarray, branch: np.ndarray,
                   amplitude: np.ndarray, run_index: np.ndarray, n_runs: int,
                   weight: np.ndarray, Qb: np.ndarray) -> list[np.ndarray]:
    """Columns of the omnibus lack-of-fit test: a twist of its own in each torque band on each
    flank, a branch split in each band, and a free play of its own for each run."""
    rel = np.abs(torque) / np.maximum(amplitude, 1e-12)
    cols = []
    for lo, hi in zip(BANDS[:-1], BANDS[1:], strict=True):
        band = ((rel >= lo) & (rel < hi)).astype(float)
        cols += [band * (flank > 0), band * (flank < 0), band * branch]
    for i in range(n_runs):
        cols.append((run_index == i) * flank / 2.0)
    Z = np.column_stack(cols) * weight[:, None]
    return [orthonormal(Z, Qb)]


def null_basis(X_base: np.ndarray, run_index: np.ndarray, n_runs: int, weight: np.ndarray
               ) -> np.ndarray:
    """Orthonormal basis of the weighted null columns with one offset per run (a run index
    of -1: a point in no run's offset)."""
    ind = (run_index[:, None] == np.arange(n_runs)[None, :]).astype(float)
    Xw = np.column_stack([X_base, ind]) * weight[:, None]
    U, s, _ = np.linalg.svd(Xw, full_matrices=False)
    return U[:, s > 1e-9 * float(s.max())]


def blocks_of(column_sets: Sequence[np.ndarray], weight: np.ndarray, Qb: np.ndarray
              ) -> list[np.ndarray]:
    """Each unweighted column set (points x k) weighted and made orthonormal against the
    null."""
    return [orthonormal(Z * weight[:, None] if Z.ndim == 2 else (Z * weight)[:, None], Qb)
            for Z in column_sets]


ColumnsOf = Callable[[str], list[np.ndarray]]
