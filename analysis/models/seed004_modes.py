"""Natural frequencies, Campbell diagram and critical speeds of a seed 004 rotor model.

* Standstill modes: ``K u = w^2 M u`` (scipy.linalg.eigh; M symmetric positive definite).
* Campbell diagram: the quadratic eigenproblem ``(s^2 M + s (C + Omega G) + K) u = 0`` at each
  spin speed, linearised to first order (scipy.linalg.eig); whirl frequency Im(s) (rad/s).
* Critical speeds: the synchronous eigenproblem. A free motion ``q = Re(u e^{i Omega t})``
  whose frequency equals the spin Omega satisfies ``K u = Omega^2 (M - i G) u`` (undamped;
  ``G`` per rad/s of the excitation line's rotor). Its real positive eigenvalues are the
  crossings of the Campbell curves with the 1X line of that rotor.

Each mode is classified by where its kinetic energy ``u^H M u`` sits (rotor, torsion) and by
its whirl: the lateral orbit of each node splits into a forward and a backward circle,
``(x + i y)/2`` and ``(x - i y)/2`` for complex amplitudes x, y (forward = the node's rotor's
spin sense); the forward fraction is the mass-weighted share of the forward circles.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
import scipy.linalg

from analysis.errors import AnalysisError
from analysis.models.seed004_rotor import SystemMatrices
from analysis.models.seed004_shaft import PHI, X, Y

RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)
TORSION_SHARE = 0.9
"""A mode with at least this share of its kinetic energy in torsion is ``torsion``."""
BENDING_SHARE = 0.1
"""A mode with at most this torsion share is ``bending``; in between, ``bending-torsion``."""
BACKWARD_LIMIT = 0.1
"""Bending whirl with a forward fraction at most this is ``backward`` (not excited by
unbalance); at least ``1 - BACKWARD_LIMIT`` is ``forward``; in between ``elliptic``."""


@dataclass(frozen=True)
class ModeClass:
    """Energy shares of a mode: per rotor, in torsion, and the forward whirl fraction."""

    rotor_shares: tuple[float, ...]
    torsion_share: float
    forward_fraction: float
    kind: str
    dominant_rotor: int


@dataclass(frozen=True)
class CriticalSpeed:
    """One crossing of the 1X line: speed in r/min of the ``reference_rotor``, and its class."""

    speed_rpm: float
    reference_rotor: int
    kind: str
    dominant_rotor: int
    rotor_shares: tuple[float, ...]
    torsion_share: float
    forward_fraction: float
    waves: float
    """Lateral mode shape of the dominant rotor in waves: 0.5 = no node between the ends."""

    def to_dict(self) -> dict:
        return asdict(self)


def classify(system: SystemMatrices, shape: np.ndarray) -> ModeClass:
    """Kinetic energy shares and whirl of one (complex) mode shape."""
    u = np.asarray(shape, dtype=complex)
    m = system.mass
    total = float(np.real(np.conj(u) @ m @ u))
    if total <= 0:
        raise AnalysisError("mode shape has no kinetic energy")
    shares = []
    for rng in system.dof_ranges:
        shares.append(float(np.real(np.conj(u[rng]) @ m[rng, rng] @ u[rng])) / total)
    tors = np.concatenate([system.dofs(r, PHI) for r in range(len(system.dof_ranges))])
    torsion = float(np.real(np.conj(u[tors]) @ m[np.ix_(tors, tors)] @ u[tors])) / total
    f_mat, b_mat = _whirl_energies(system, u[:, None])
    fwd, bwd = float(np.real(f_mat[0, 0])), float(np.real(b_mat[0, 0]))
    forward = fwd / (fwd + bwd) if fwd + bwd > 0 else 0.5
    if torsion >= TORSION_SHARE:
        kind = "torsion"
    elif torsion > BENDING_SHARE:
        kind = "bending-torsion"
    elif forward <= BACKWARD_LIMIT:
        kind = "backward"
    elif forward >= 1.0 - BACKWARD_LIMIT:
        kind = "forward"
    else:
        kind = "elliptic"
    return ModeClass(tuple(shares), torsion, forward, kind, int(np.argmax(shares)))


def wave_count(system: SystemMatrices, shape: np.ndarray, rotor: int,
               floor: float = 1e-3) -> float:
    """Lateral shape of one rotor in waves, as the seed counts them (0.5, 1, 1.5 ...): half
    the number of sign changes along the shaft plus one half, in the plane and at the phase
    of largest motion; nodes below ``floor`` x the largest amplitude are skipped."""
    u = np.asarray(shape, dtype=complex)
    xy = np.vstack([u[system.dofs(rotor, X)], u[system.dofs(rotor, Y)]])
    phases = np.linspace(0.0, np.pi, 73)
    snaps = [np.real(xy * np.exp(1j * p)) for p in phases]
    snap = max(snaps, key=lambda s: float(np.sum(s**2)))
    direction = np.linalg.svd(snap, full_matrices=False)[0][:, 0]
    w = direction @ snap
    w = w[np.abs(w) > floor * np.abs(w).max()] if np.abs(w).max() > 0 else w
    changes = int(np.count_nonzero(np.diff(np.sign(w)) != 0))
    return 0.5 * (changes + 1)


def standstill_modes(system: SystemMatrices, min_rpm: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Natural frequencies (r/min, ascending) and mode shapes (columns) at zero speed,
    undamped, ``K u = w^2 M u``; rigid-body modes (w = 0) are left out, and so is anything
    below ``min_rpm``."""
    rpm, shapes = _synchronous(system.stiffness, system.mass.astype(complex))
    order = np.argsort(rpm)
    rpm, shapes = rpm[order], np.real_if_close(shapes[:, order], tol=1e6)
    keep = rpm >= min_rpm
    return rpm[keep], shapes[:, keep]


def campbell(
    system: SystemMatrices, speeds_rpm: np.ndarray, *, damped: bool = False, max_rpm: float = 1e4
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Whirl frequencies (r/min, ascending, below ``max_rpm``) and their forward fractions at
    each spin speed of the reference rotor (r/min)."""
    n = system.size
    eye, zero = np.eye(n), np.zeros((n, n))
    b = np.block([[eye, zero], [zero, system.mass]])
    out = []
    for speed in np.atleast_1d(speeds_rpm):
        omega = float(speed) / RPM_PER_RAD_S
        c = omega * system.gyroscopic + (system.damping if damped else 0.0)
        a = np.block([[zero, eye], [-system.stiffness, -c]])
        s, vecs = scipy.linalg.eig(a, b)
        freq = np.imag(s) * RPM_PER_RAD_S
        keep = np.isfinite(freq) & (freq > 1.0) & (freq < max_rpm)
        order = np.argsort(freq[keep])
        shapes = vecs[:n, keep][:, order]
        fwd = np.array([classify(system, shapes[:, j]).forward_fraction
                        for j in range(shapes.shape[1])])
        out.append((freq[keep][order], fwd))
    return out


def _synchronous(k: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Real positive roots Omega (r/min) and shapes of ``K u = Omega^2 B u``, B Hermitian.

    K is positive semi-definite: its null space (free rotation of the shaft line) is removed
    by seeking u B-orthogonal to it (exact for every root Omega != 0); on that subspace K is
    positive definite and ``B u = (1 / Omega^2) K u`` is a Hermitian-definite problem."""
    null = scipy.linalg.null_space(k, rcond=1e-12)
    z = scipy.linalg.null_space((b @ null).conj().T) if null.size else np.eye(k.shape[0])
    mu, y = scipy.linalg.eigh(z.conj().T @ b @ z, z.conj().T @ k @ z)
    keep = mu > 0
    return np.sqrt(1.0 / mu[keep]) * RPM_PER_RAD_S, z @ y[:, keep]


def _whirl_energies(system: SystemMatrices, shapes: np.ndarray) -> tuple[np.ndarray, ...]:
    """Forward and backward lateral kinetic-energy matrices ``V^H W V`` of a set of shapes."""
    fwd = np.zeros((shapes.shape[1],) * 2, dtype=complex)
    bwd = np.zeros_like(fwd)
    for r, ratio in enumerate(system.spin_ratios):
        ix, iy = system.dofs(r, X), system.dofs(r, Y)
        mxx = system.mass[np.ix_(ix, ix)]
        plus = (shapes[ix] + 1j * shapes[iy]) / 2.0
        minus = (shapes[ix] - 1j * shapes[iy]) / 2.0
        if ratio < 0:
            plus, minus = minus, plus
        fwd += plus.conj().T @ mxx @ plus
        bwd += minus.conj().T @ mxx @ minus
    return fwd, bwd


def _circular_whirls(
    system: SystemMatrices, rpm: np.ndarray, shapes: np.ndarray, rel_tol: float = 1e-7
) -> np.ndarray:
    """Within each set of equal roots (an axisymmetric rotor's planar pair), the basis that
    separates forward from backward whirl (extremes of the forward fraction)."""
    out = shapes.copy()
    start = 0
    while start < rpm.size:
        stop = start + 1
        while stop < rpm.size and rpm[stop] - rpm[start] <= rel_tol * rpm[start]:
            stop += 1
        if stop - start > 1:
            v = shapes[:, start:stop]
            fwd, bwd = _whirl_energies(system, v)
            total = fwd + bwd
            if np.linalg.matrix_rank(total, tol=1e-12 * np.abs(total).max()) == stop - start:
                y = scipy.linalg.eigh(fwd, total)[1]
                out[:, start:stop] = v @ y
        start = stop
    return out


def critical_speeds(
    system: SystemMatrices,
    reference_rotor: int = 0,
    *,
    max_rpm: float = 1e4,
    include_backward: bool = False,
) -> list[CriticalSpeed]:
    """Critical speeds (r/min of ``reference_rotor``) from the synchronous eigenproblem:
    crossings of every whirl frequency with that rotor's 1X line, ascending. Nearly pure
    backward whirls (not excited by unbalance) are left out unless asked for."""
    ratio = system.spin_ratios[reference_rotor]
    if ratio == 0:
        raise AnalysisError("the reference rotor does not spin")
    g = system.gyroscopic / abs(ratio)
    rpm, shapes = _synchronous(system.stiffness, system.mass - 1j * g)
    order = np.argsort(rpm)
    rpm, shapes = rpm[order], _circular_whirls(system, rpm[order], shapes[:, order])
    result = []
    for j in range(rpm.size):
        if not 1.0 <= rpm[j] <= max_rpm:
            continue
        cls = classify(system, shapes[:, j])
        if cls.kind == "backward" and not include_backward:
            continue
        result.append(CriticalSpeed(
            speed_rpm=float(rpm[j]), reference_rotor=reference_rotor, kind=cls.kind,
            dominant_rotor=cls.dominant_rotor, rotor_shares=cls.rotor_shares,
            torsion_share=cls.torsion_share, forward_fraction=cls.forward_fraction,
            waves=wave_count(system, shapes[:, j], cls.dominant_rotor),
        ))
    return result


def campbell_crossings_rpm(
    system: SystemMatrices, speeds_rpm: np.ndarray, *, min_forward: float = BACKWARD_LIMIT
) -> np.ndarray:
    """Spin speeds (r/min) where a whirl frequency that is not nearly pure backward crosses
    the 1X line, by linear interpolation between grid speeds, tracking the frequencies by their
    order (fine grids near veering). A check on :func:`critical_speeds`."""
    speeds = np.asarray(speeds_rpm, dtype=float)
    diagram = campbell(system, speeds, max_rpm=speeds[-1] * 2)
    count = min(f.size for f, _ in diagram)
    freqs = np.array([f[:count] for f, _ in diagram])
    fwd = np.array([w[:count] for _, w in diagram])
    gap = freqs - speeds[:, None]
    crossings = []
    for j in range(count):
        for i in np.nonzero(np.sign(gap[:-1, j]) != np.sign(gap[1:, j]))[0]:
            if max(fwd[i, j], fwd[i + 1, j]) <= min_forward:
                continue
            t = gap[i, j] / (gap[i, j] - gap[i + 1, j])
            crossings.append(speeds[i] + t * (speeds[i + 1] - speeds[i]))
    return np.sort(np.array(crossings))
