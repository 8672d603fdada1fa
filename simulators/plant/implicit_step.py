"""The scalar root of one implicit step of the plant: the chain's compliance and the solve.

The step's end twist ``phi`` (rad) solves ``mass (phi - phi_pred) + F_f(phi) + G(phi) - T_d
= 0`` (``mass`` = J / dt^2 in N*m/rad, 0 for the quasi-static limit). The left side
is monotone in ``phi``, so safeguarded Newton (:func:`newton`) finds the unique root. The solve
goes in named steps (:func:`solve_step`): without friction in closed form
(:func:`solve_frictionless`); with friction either in the free play (:func:`root_in_play`),
on a linear flank (:func:`root_on_linear_flank`) or on a stiffening flank with the flank torque
as the unknown (:func:`flank_torque`). docs/plant.md has the mechanics.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

from simulators.plant.friction import Friction

_MAX_ITER = 80

StepResult = tuple[float, float, float, float]
"""(end twist phi rad, chain torque G N*m, friction torque N*m, new bristle force N*m)."""


@dataclass(frozen=True)
class Compliance:
    """The series compliance beyond the play, ``h(tau)`` (rad) for flank torque tau (N*m).

    ``h = tau c_lin + d_s (1 - exp(-tau / t_s)) + min(tau, t_b) c_b``: linear (mesh, shaft,
    [creep when quasi-static]), contact stiffening, bearing clearance's soft stage."""

    c_lin: float
    soft_rad: float = 0.0
    soft_scale_Nm: float = 1.0
    bearing_c: float = 0.0
    bearing_torque_Nm: float = 0.0
    stages: tuple[tuple[float, float], ...] = ()
    """Multi-flank contact (cycloid, seed 002): beyond flank torque ``tau_j`` (N*m) another
    flank takes load and the compliance falls by ``d_j`` (rad/(N*m)):
    ``h -= sum_j d_j (tau - tau_j)+`` (simulators/plant/cycloid.py)."""

    def __call__(self, tau: float) -> tuple[float, float]:
        """(h, dh/dtau) at flank torque ``tau`` >= 0."""
        h = tau * self.c_lin
        dh = self.c_lin
        for t_j, d_j in self.stages:
            if tau > t_j:
                h -= d_j * (tau - t_j)
                dh -= d_j
        if self.soft_rad:
            e = math.exp(-tau / self.soft_scale_Nm)
            h += self.soft_rad * (1.0 - e)
            dh += self.soft_rad / self.soft_scale_Nm * e
        if self.bearing_c:
            if tau < self.bearing_torque_Nm:
                h += tau * self.bearing_c
                dh += self.bearing_c
            else:
                h += self.bearing_torque_Nm * self.bearing_c
        return h, dh

    def invert(self, mass: float, q: float) -> float:
        """The flank torque tau >= 0 with ``mass h(tau) + tau = q`` (q >= 0)."""
        if q <= 0.0:
            return 0.0
        c, cb, tb = self.c_lin, self.bearing_c, self.bearing_torque_Nm
        if not self.soft_rad and not self.stages:
            if cb:
                tau = q / (mass * (c + cb) + 1.0)
                if tau <= tb:
                    return tau
                return (q - mass * cb * tb) / (mass * c + 1.0)
            return q / (mass * c + 1.0)

        def residual(tau: float) -> tuple[float, float]:
            h, dh = self(tau)
            return mass * h + tau - q, mass * dh + 1.0

        return newton(residual, 0.0, q, q / (mass * c + 1.0), 1e-13 * (1.0 + q))


def newton(fn, lo: float, hi: float, x0: float, tol: float) -> float:
    """Root of an increasing ``fn(x) -> (f, df)`` in [lo, hi] (f(lo) <= 0 <= f(hi)).

    Newton steps while they stay in the bracket and at least halve the previous step;
    bisection otherwise (so kinks, e.g. friction reversing, cannot make it cycle)."""
    x = min(max(x0, lo), hi)
    last_step = math.inf
    for _ in range(_MAX_ITER):
        f, df = fn(x)
        if f == 0.0:
            return x
        if f > 0.0:
            hi = x
        else:
            lo = x
        x_new = x - f / df if df > 0.0 else lo - 1.0
        if not (lo <= x_new <= hi and abs(x_new - x) <= 0.5 * last_step):
            x_new = 0.5 * (lo + hi)
        last_step = abs(x_new - x)
        if last_step <= tol or hi - lo <= tol:
            return x_new
        x = x_new
    return x


def solve_frictionless(phi0: float, drive_Nm: float, mass: float, phi_pred: float,
                       centre: float, half_play: float, compliance: Compliance) -> StepResult:
    """The step without friction: in the free play, or the closed-form flank torque
    (:meth:`Compliance.invert`). ``phi0`` (rad) is where a quasi-static step at zero drive
    stays."""
    upper, lower = centre + half_play, centre - half_play
    if mass > 0.0:
        phi = phi_pred + drive_Nm / mass
        if lower <= phi <= upper:
            return phi, 0.0, 0.0, 0.0
        side = 1.0 if phi > upper else -1.0
    elif drive_Nm == 0.0:
        return min(max(phi0, lower), upper), 0.0, 0.0, 0.0
    else:
        side = 1.0 if drive_Nm > 0.0 else -1.0
    base = centre + side * half_play
    tau = compliance.invert(mass, side * (drive_Nm - mass * (base - phi_pred)))
    return base + side * compliance(tau)[0], side * tau, 0.0, 0.0


class FrictionStep(NamedTuple):
    """The knowns of one step with output friction (N*m, rad) and the friction's step state
    (its level, bristle force at the start, ``k = sigma0 / level`` and rate terms)."""

    drive_Nm: float
    mass: float
    phi_pred: float
    phi0: float
    level: float
    b0: float
    k: float
    r1: float
    r2: float

    @classmethod
    def of(cls, friction: Friction, drive_Nm: float, mass: float, phi_pred: float,
           phi0: float) -> FrictionStep:
        """The step of ``friction`` after its begin_step, from the twist ``phi0`` (rad)."""
        level = friction.level_Nm
        return cls(drive_Nm, mass, phi_pred, phi0, level, friction.bristle_Nm,
                   friction.sigma0_Nm_per_rad / level if level > 0.0 else 0.0,
                   friction.rate1, friction.rate2)

    def residual(self) -> Callable[[float], tuple[float, float, float]]:
        """``free(phi)``: (residual without the chain, its derivative, bristle force)."""
        drive_Nm, mass, phi_pred, phi0, level, b0, k, r1, r2 = self
        exp = math.exp

        def free(phi: float) -> tuple[float, float, float]:
            # the bristle force (friction.bristle_force) inlined: the solver's hot loop
            d = phi - phi0
            if k == 0.0:
                b, db = 0.0, 0.0
            elif d >= 0.0:
                e = exp(-k * d)
                b = level - (level - b0) * e
                db = k * (level - b0) * e
            else:
                e = exp(k * d)
                b = -level + (level + b0) * e
                db = k * (level + b0) * e
            return (mass * (phi - phi_pred) + b + r1 * (b - b0) + r2 * d - drive_Nm,
                    mass + db * (1.0 + r1) + r2, b)

        return free


def root_in_play(free: Callable[[float], tuple[float, float, float]], lower: float,
                 upper: float, slope: float, known: float, f_max: float,
                 phi_pred: float) -> float:
    """The end twist (rad) inside the free play [lower, upper], bracketed by
    ``|friction| <= f_max`` where the step's linear part has a slope."""
    lo, hi = lower, upper
    if slope > 0.0:
        margin = 0.01 * f_max / slope + 1e-18
        lo = max(lo, (known - f_max) / slope - margin)
        hi = min(hi, (known + f_max) / slope + margin)
    return newton(lambda x: free(x)[:2], lo, hi, phi_pred, 1e-16)


def root_on_linear_flank(free: Callable[[float], tuple[float, float, float]], base: float,
                         side: float, stiff: float, slope: float, known: float, f_max: float,
                         phi_pred: float) -> float:
    """The end twist (rad) on a linear flank: ``G = (phi - base) stiff`` (N*m/rad), solved
    directly for ``phi`` on the ``side`` of ``base``."""
    known_c = known + base * stiff
    margin = 0.01 * f_max / (slope + stiff) + 1e-18
    lo = (known_c - f_max) / (slope + stiff) - margin
    hi = (known_c + f_max) / (slope + stiff) + margin
    if side > 0.0:
        lo, hi = max(lo, base), max(hi, base)
    else:
        lo, hi = min(lo, base), min(hi, base)

    def flank(x: float) -> tuple[float, float]:
        r, dr, _ = free(x)
        return r + (x - base) * stiff, dr + stiff

    return newton(flank, lo, hi, phi_pred, 1e-16)


def flank_torque(step: FrictionStep, base: float, side: float, compliance: Compliance,
                 f_max: float, chain_prev_Nm: float) -> float:
    """The flank torque tau >= 0 (N*m) on a stiffening flank (the general compliance), from
    a predictor along the compliance's tangent at the previous chain torque."""
    drive_Nm, phi_pred = step.drive_Nm, step.phi_pred
    free = step.residual()
    c_lin, soft, scale = compliance.c_lin, compliance.soft_rad, compliance.soft_scale_Nm
    c_b, t_b = compliance.bearing_c, compliance.bearing_torque_Nm
    stages = compliance.stages
    exp = math.exp

    def contact(tau: float) -> tuple[float, float]:
        # compliance(tau) inlined (this is the hot loop of the slow paths), then free(phi)
        h, dh = tau * c_lin, c_lin
        if soft:
            e = exp(-tau / scale)
            h += soft * (1.0 - e)
            dh += soft / scale * e
        if c_b:
            if tau < t_b:
                h += tau * c_b
                dh += c_b
            else:
                h += t_b * c_b
        for t_j, d_j in stages:
            if tau > t_j:
                h -= d_j * (tau - t_j)
                dh -= d_j
        r, dr, _ = free(base + side * h)
        return side * r + tau, dr * dh + 1.0

    hi = 2.0 * abs(drive_Nm) + 4.0 * f_max + 1.0
    while contact(hi)[0] < 0.0:
        hi *= 2.0
    # predictor: the previous flank torque moved along the compliance's tangent
    tau_prev = side * chain_prev_Nm if side * chain_prev_Nm > 0.0 else 0.0
    h_prev, dh_prev = compliance(tau_prev)
    guess = tau_prev + (side * (phi_pred - base) - h_prev) / dh_prev
    return newton(contact, 0.0, hi, min(max(guess, 0.0), hi), 1e-12 * (1.0 + hi))


def solve_step(friction: Friction | None, phi0: float, chain_prev_Nm: float, drive_Nm: float,
               mass: float, phi_pred: float, centre: float, half_play: float,
               compliance: Compliance) -> StepResult:
    """End twist of a step: root of ``mass (phi - phi_pred) + F_f + G - drive = 0``.

    ``phi0`` (rad) and ``chain_prev_Nm`` are the twist and chain torque at the step's start;
    ``friction`` must have had begin_step. The free play is ``centre +- half_play`` (rad)."""
    if friction is None:
        return solve_frictionless(phi0, drive_Nm, mass, phi_pred, centre, half_play,
                                  compliance)
    step = FrictionStep.of(friction, drive_Nm, mass, phi_pred, phi0)
    free = step.residual()
    f_max = step.level * (1.0 + 2.0 * step.r1)

    def result(phi: float, chain: float) -> StepResult:
        r, _, b = free(phi)
        return phi, chain, r + drive_Nm - mass * (phi - phi_pred), b

    # bounds of the root from |friction| <= f_max (the chain adds the slope 1 / c_lin)
    slope = mass + step.r2
    known = mass * phi_pred + step.r2 * phi0 + drive_Nm
    upper, lower = centre + half_play, centre - half_play
    r_up = free(upper)[0]
    r_low = r_up if half_play == 0.0 or r_up < 0.0 else free(lower)[0]
    if r_up >= 0.0 and r_low <= 0.0:  # in the free play
        if half_play == 0.0:
            return result(centre, 0.0)
        return result(root_in_play(free, lower, upper, slope, known, f_max, phi_pred), 0.0)
    side = 1.0 if r_up < 0.0 else -1.0
    base = centre + side * half_play
    if not compliance.soft_rad and not compliance.bearing_c and not compliance.stages:
        stiff = 1.0 / compliance.c_lin
        phi = root_on_linear_flank(free, base, side, stiff, slope, known, f_max, phi_pred)
        return result(phi, (phi - base) * stiff)
    tau = flank_torque(step, base, side, compliance, f_max, chain_prev_Nm)
    return result(base + side * compliance(tau)[0], side * tau)
