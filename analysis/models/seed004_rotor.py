"""Rotor-bearing and geared-rotor models of seed 004 (Che et al. 2012), sections 1-2.

A rotor is a shaft cut into finite elements (:mod:`seed004_shaft`, eqs. 1-4), rigid discs
(eqs. 5-7: mass m on x and y, diametral inertia J_d on the tilts, polar inertia J_p on the
torsion and in the gyroscopic matrix) and bearings (stiffness and damping on x and y of a node).
Two rotors joined by the spur pair element of eqs. (12)-(15) (:mod:`seed004_gear_pair`) make
the geared rotor. The gears are discs of their rotors (the seed's M_G and the J_p Omega terms
of its C_G); the pair element adds the mesh.

All matrices are SI: ``M q'' + (C + Omega G) q' + K q = 0``, q the nodal coordinates
``[x, y, theta_x, theta_y, phi]`` (m, rad) of every node of rotor 1, then of rotor 2, and
Omega (rad/s) the spin of the *reference* rotor (rotor 1, the driving one): G already carries
each rotor's speed ratio (rotor 2 turns at ``-z1/z2`` times rotor 1's speed).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from analysis.errors import AnalysisError
from analysis.models.seed004_gear_pair import (
    MeshProperties,
    SpurPair,
    gear_pair_element,
    mesh_properties,
)
from analysis.models.seed004_shaft import (
    DOF_PER_NODE,
    PHI,
    STEEL,
    THETA_X,
    THETA_Y,
    Material,
    Section,
    X,
    Y,
    shaft_element,
)


@dataclass(frozen=True)
class Disc:
    """Rigid disc (or gear body) at ``position_m`` along the shaft: mass (kg), polar and
    diametral inertia (kg m^2). Seed 004 eqs. (5)-(7)."""

    name: str
    position_m: float
    mass_kg: float
    polar_inertia_kgm2: float
    diametral_inertia_kgm2: float


@dataclass(frozen=True)
class Bearing:
    """Linear bearing at ``position_m``: stiffness (N/m) and damping (N s/m) in x and y."""

    name: str
    position_m: float
    stiffness_xx_N_per_m: float
    stiffness_yy_N_per_m: float
    damping_xx_Ns_per_m: float = 0.0
    damping_yy_Ns_per_m: float = 0.0


@dataclass(frozen=True)
class Rotor:
    """A uniform solid shaft (length, radius in m) with discs and bearings, cut into
    ``elements`` equal Timoshenko elements (more nodes are added at discs and bearings)."""

    name: str
    length_m: float
    radius_m: float
    discs: tuple[Disc, ...]
    bearings: tuple[Bearing, ...]
    material: Material = STEEL
    elements: int = 24
    shear: bool = True

    def __post_init__(self) -> None:
        if not self.length_m > 0:
            raise AnalysisError(f"{self.name}: shaft length must be > 0 m, got {self.length_m}")
        if self.elements < 1:
            raise AnalysisError(f"{self.name}: needs at least one element")
        for item in (*self.discs, *self.bearings):
            if not 0.0 <= item.position_m <= self.length_m:
                raise AnalysisError(
                    f"{self.name}: {item.name} at {item.position_m} m is off the shaft "
                    f"(0 .. {self.length_m} m)"
                )
        if len(self.bearings) < 2:
            raise AnalysisError(f"{self.name}: needs two bearings or more, has "
                                f"{len(self.bearings)}")

    def node_positions_m(self) -> np.ndarray:
        """Node coordinates (m): the equal mesh plus every disc and bearing position."""
        grid = np.linspace(0.0, self.length_m, self.elements + 1)
        extra = [item.position_m for item in (*self.discs, *self.bearings)]
        nodes = np.unique(np.concatenate([grid, extra]))
        keep = np.concatenate([[True], np.diff(nodes) > 1e-9 * self.length_m])
        return nodes[keep]

    def node_of(self, position_m: float) -> int:
        """Index of the node at ``position_m`` (m)."""
        nodes = self.node_positions_m()
        index = int(np.argmin(np.abs(nodes - position_m)))
        if abs(nodes[index] - position_m) > 1e-6 * self.length_m:
            raise AnalysisError(f"{self.name}: no node at {position_m} m")
        return index


@dataclass(frozen=True)
class SystemMatrices:
    """Assembled model. ``gyroscopic`` is per rad/s of the reference rotor's spin (rotor 0);
    ``spin_ratios[i]`` is rotor i's spin over the reference's; ``dof_ranges[i]`` the slice of
    rotor i's coordinates; ``nodes_m[i]`` its node positions."""

    mass: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    gyroscopic: np.ndarray
    rotor_names: tuple[str, ...]
    spin_ratios: tuple[float, ...]
    dof_ranges: tuple[slice, ...]
    nodes_m: tuple[np.ndarray, ...]
    mesh: MeshProperties | None = field(default=None)

    @property
    def size(self) -> int:
        return self.mass.shape[0]

    def dofs(self, rotor: int, kind: int) -> np.ndarray:
        """Global indices of coordinate ``kind`` (X, Y, THETA_X, THETA_Y, PHI) of a rotor."""
        rng = self.dof_ranges[rotor]
        return np.arange(rng.start + kind, rng.stop, DOF_PER_NODE)


def _rotor_matrices(rotor: Rotor) -> tuple[np.ndarray, ...]:
    nodes = rotor.node_positions_m()
    n = DOF_PER_NODE * nodes.size
    m, k, c, g = (np.zeros((n, n)) for _ in range(4))
    section = Section(rotor.radius_m)
    for e, length in enumerate(np.diff(nodes)):
        el = shaft_element(float(length), section, rotor.material, shear=rotor.shear)
        idx = slice(DOF_PER_NODE * e, DOF_PER_NODE * (e + 2))
        m[idx, idx] += el.mass
        k[idx, idx] += el.stiffness
        g[idx, idx] += el.gyroscopic
    for disc in rotor.discs:
        base = DOF_PER_NODE * rotor.node_of(disc.position_m)
        for dof, value in ((X, disc.mass_kg), (Y, disc.mass_kg),
                           (THETA_X, disc.diametral_inertia_kgm2),
                           (THETA_Y, disc.diametral_inertia_kgm2),
                           (PHI, disc.polar_inertia_kgm2)):
            m[base + dof, base + dof] += value
        g[base + THETA_X, base + THETA_Y] += disc.polar_inertia_kgm2
        g[base + THETA_Y, base + THETA_X] -= disc.polar_inertia_kgm2
    for brg in rotor.bearings:
        base = DOF_PER_NODE * rotor.node_of(brg.position_m)
        for dof, stiffness, damping in ((X, brg.stiffness_xx_N_per_m, brg.damping_xx_Ns_per_m),
                                        (Y, brg.stiffness_yy_N_per_m, brg.damping_yy_Ns_per_m)):
            k[base + dof, base + dof] += stiffness
            c[base + dof, base + dof] += damping
    return m, k, c, g, nodes


def assemble(rotors: Sequence[Rotor], spin_ratios: Sequence[float] | None = None) -> SystemMatrices:
    """Uncoupled rotors side by side (block diagonal), each spinning at its ratio."""
    ratios = tuple(spin_ratios) if spin_ratios is not None else (1.0,) * len(rotors)
    if len(ratios) != len(rotors):
        raise AnalysisError("one spin ratio per rotor")
    parts = [_rotor_matrices(r) for r in rotors]
    n = sum(p[0].shape[0] for p in parts)
    m, k, c, g = (np.zeros((n, n)) for _ in range(4))
    ranges, start = [], 0
    for (pm, pk, pc, pg, _), ratio in zip(parts, ratios, strict=True):
        sl = slice(start, start + pm.shape[0])
        m[sl, sl], k[sl, sl], c[sl, sl], g[sl, sl] = pm, pk, pc, ratio * pg
        ranges.append(sl)
        start = sl.stop
    return SystemMatrices(
        mass=m, stiffness=k, damping=c, gyroscopic=g,
        rotor_names=tuple(r.name for r in rotors), spin_ratios=ratios,
        dof_ranges=tuple(ranges), nodes_m=tuple(p[4] for p in parts),
    )


def geared_rotor(
    rotor1: Rotor,
    rotor2: Rotor,
    pair: SpurPair,
    gear1_position_m: float,
    gear2_position_m: float,
    *,
    mesh: MeshProperties | None = None,
    azimuth_deg: float | None = None,
) -> SystemMatrices:
    """Seed 004 section 3: the two rotors coupled by the pair element of eq. (15) at the gear
    nodes. Rotor 2 spins at ``-z1/z2`` times rotor 1. The rotors must already carry their gears
    as discs (see :func:`gear_discs`)."""
    mesh = mesh if mesh is not None else mesh_properties(pair)
    system = assemble((rotor1, rotor2), (1.0, pair.speed_ratio))
    k_g, c_g = gear_pair_element(pair, mesh, azimuth_deg=azimuth_deg)
    n1 = DOF_PER_NODE * rotor1.node_of(gear1_position_m)
    n2 = system.dof_ranges[1].start + DOF_PER_NODE * rotor2.node_of(gear2_position_m)
    idx = np.r_[n1:n1 + DOF_PER_NODE, n2:n2 + DOF_PER_NODE]
    k, c = system.stiffness.copy(), system.damping.copy()
    k[np.ix_(idx, idx)] += k_g
    c[np.ix_(idx, idx)] += c_g
    return SystemMatrices(
        mass=system.mass, stiffness=k, damping=c, gyroscopic=system.gyroscopic,
        rotor_names=system.rotor_names, spin_ratios=system.spin_ratios,
        dof_ranges=system.dof_ranges, nodes_m=system.nodes_m, mesh=mesh,
    )


def gear_discs(pair: SpurPair, gear1_position_m: float, gear2_position_m: float,
               diametral_fraction: float = 0.5) -> tuple[Disc, Disc]:
    """The two gear bodies as discs (Table 2 masses and polar inertias); the seed gives no
    diametral inertia: ``J_d = diametral_fraction * J_p`` (0.5 = thin disc)."""
    return (
        Disc("gear 1", gear1_position_m, pair.mass1_kg, pair.polar_inertia1_kgm2,
             diametral_fraction * pair.polar_inertia1_kgm2),
        Disc("gear 2", gear2_position_m, pair.mass2_kg, pair.polar_inertia2_kgm2,
             diametral_fraction * pair.polar_inertia2_kgm2),
    )
