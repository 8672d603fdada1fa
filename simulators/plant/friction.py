"""Friction between the output and the housing: Dahl or LuGre, integrated per step.

Both are written with the bristle force ``B = sigma0 z`` (N*m) as the state. Over a step in
which the output twist moves by ``d`` (rad) at a constant rate, the bristle equation
``dB/dphi = sigma0 (1 - B / L sgn(dphi))`` (Dahl, level ``L = F_c``; LuGre with
``L = g(v) = F_c + (F_s - F_c) exp(-(v / v_s)^2)``) has the exact solution

    B(d) = sgn(d) L - (sgn(d) L - B0) exp(-sigma0 |d| / L),

so the friction torque is a monotone function of the step's end twist: the implicit step of
the plant can solve for it (docs/plant.md). LuGre adds the bristle damping
``sigma1 dz/dt = (sigma1 / sigma0) (B - B0) / dt`` and the viscous term ``sigma2 d / dt``.
References: Dahl (1968) for the rate-independent model; Canudas de Wit et al. (1995) for LuGre.
Torques in N*m, twists in rad, stiffness in N*m/rad, velocities in rad/s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from simulators.plant.config import FrictionConfig
from simulators.plant.geometry import ARCMIN_PER_RAD


def bristle_force(level: float, b0: float, k: float, d: float) -> tuple[float, float]:
    """(B, dB/dd): the bristle force (N*m) after a move ``d`` (rad) from ``b0`` at the level
    ``level`` (N*m), ``k = sigma0 / level`` (1/rad); the exact solution above."""
    if d >= 0.0:
        e = math.exp(-k * d)
        return level - (level - b0) * e, k * (level - b0) * e
    e = math.exp(k * d)
    return -level + (level + b0) * e, k * (level + b0) * e


@dataclass
class Friction:
    """One friction element with its state ``bristle_Nm``; call :meth:`begin_step` once per
    step, then :meth:`torque` as often as the solver needs, then :meth:`commit`."""

    lugre: bool
    coulomb_Nm: float
    static_Nm: float
    sigma0_Nm_per_rad: float
    sigma1_Nms_per_rad: float
    sigma2_Nms_per_rad: float
    stribeck_rad_per_s: float
    bristle_Nm: float = 0.0
    level_Nm: float = 0.0
    rate1: float = 0.0
    rate2: float = 0.0

    @classmethod
    def from_config(cls, cfg: FrictionConfig) -> Friction:
        """Convert the TOML units (arcmin) to rad."""
        return cls(
            lugre=cfg.model == "lugre",
            coulomb_Nm=cfg.coulomb_torque_Nm,
            static_Nm=cfg.static_torque_Nm if cfg.model == "lugre" else cfg.coulomb_torque_Nm,
            sigma0_Nm_per_rad=cfg.rest_stiffness_Nm_per_arcmin * ARCMIN_PER_RAD,
            sigma1_Nms_per_rad=cfg.micro_damping_Nms_per_arcmin * ARCMIN_PER_RAD,
            sigma2_Nms_per_rad=cfg.viscous_Nms_per_arcmin * ARCMIN_PER_RAD,
            stribeck_rad_per_s=cfg.stribeck_velocity_arcmin_per_s / ARCMIN_PER_RAD,
        )

    def quasi_static_level_Nm(self) -> float:
        """The level the bristle force reaches in slow sliding: F_c (Dahl) or F_s (LuGre)."""
        return self.static_Nm

    def begin_step(self, velocity_rad_per_s: float, dt_s: float | None) -> None:
        """Fix the step's level from the previous velocity (LuGre) and the rate terms.

        ``dt_s=None`` is the quasi-static limit: level F_s (LuGre) and no rate terms."""
        if self.lugre and dt_s is not None:
            ratio = velocity_rad_per_s / self.stribeck_rad_per_s
            self.level_Nm = self.coulomb_Nm + (self.static_Nm - self.coulomb_Nm) * math.exp(
                -ratio * ratio
            )
        else:
            self.level_Nm = self.static_Nm
        level = self.level_Nm
        self.bristle_Nm = min(max(self.bristle_Nm, -level), level)
        if dt_s is None or not self.lugre:
            self.rate1 = self.rate2 = 0.0
        else:
            self.rate1 = self.sigma1_Nms_per_rad / (self.sigma0_Nm_per_rad * dt_s)
            self.rate2 = self.sigma2_Nms_per_rad / dt_s

    def torque(self, d_rad: float) -> tuple[float, float, float]:
        """(friction torque, its derivative wrt ``d``, new bristle force) after a move ``d``."""
        level = self.level_Nm
        b0 = self.bristle_Nm
        if level <= 0.0:
            return self.rate2 * d_rad, self.rate2, 0.0
        b, db = bristle_force(level, b0, self.sigma0_Nm_per_rad / level, d_rad)
        r1 = self.rate1
        return (b + r1 * (b - b0) + self.rate2 * d_rad, db * (1.0 + r1) + self.rate2, b)

    def commit(self, bristle_Nm: float) -> None:
        """Accept the step's end state."""
        self.bristle_Nm = bristle_Nm
