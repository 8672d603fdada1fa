"""The geared rotor of seed 004 (Che et al. 2012): Tables 1-3 and the assumptions we add.

The paper gives the shafts' lengths and radii, the discs, bearings and gears (Tables 1-2) but
not the shaft material nor where the bearings, discs and gears sit (its Fig. 1 is a sketch).
:class:`Assumptions` holds what we chose, each with the physical reason in docs/seed004.md:

* steel, E = 206 GPa, rho = 7850 kg/m^3, nu = 0.3 (G = 79.2 GPa);
* each shaft on two bearings at its ends (the paper: zero amplitude at the rigid supports,
  mode shapes of 0.5, 1 and 1.5 waves between them); bearing 1 of Table 1 carries rotor 1 at
  both ends, bearing 2 rotor 2 (the stiffer bearing under the heavier rotor, as disc 1 / disc 2
  belong to rotor 1 / rotor 2);
* disc at one third and gear at two thirds of each shaft (inside the span, asymmetric, as the
  paper says its mode shapes are);
* diametral inertia = polar / 2 for discs and gears (thin discs; the paper gives J_p only);
* mesh stiffness and damping constant at the standard center distance (section 3), eq. (11)
  with the standard equivalent mass.

Critical speeds are in r/min. Table 3 lists five per single rotor and eight for the coupled
rotor, without saying which 1X line they cross: ours are crossings of each rotor's own 1X
line for the single rotors and of the driving rotor's (rotor 1) for the coupled one; the
driven rotor's line and the standstill frequencies are reported beside them.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from analysis.models.seed004_gear_pair import MeshProperties, SpurPair, mesh_properties
from analysis.models.seed004_modes import CriticalSpeed, critical_speeds, standstill_modes
from analysis.models.seed004_rotor import (
    Bearing,
    Disc,
    Rotor,
    SystemMatrices,
    assemble,
    gear_discs,
    geared_rotor,
)
from analysis.models.seed004_shaft import STEEL, Material

# Table 1 (SI).
SHAFT_LENGTH_M = (4.6, 5.5)
SHAFT_RADIUS_M = (0.025, 0.075)
DISC_MASS_KG = (10.4, 432.2)
DISC_POLAR_INERTIA_KGM2 = (0.3, 20.74)
BEARING_STIFFNESS_N_PER_M = (1.02e7, 1.84e8)
BEARING_DAMPING_NS_PER_M = (3000.0, 3000.0)

# Table 3 (r/min).
PAPER_ROTOR1_RPM = (336.18, 1269.10, 2417.10, 3476.72, 5280.77)
PAPER_ROTOR2_RPM = (641.98, 2443.70, 3743.49, 4766.81, 8136.50)
PAPER_COUPLED_RPM = (335.33, 608.93, 1256.19, 1970.05, 2021.06, 2831.76, 3105.401, 3658.01)
PAPER_COUPLED_FAMILIES = {1: (0, 0.5), 2: (1, 0.5), 3: (0, 1.0), 5: (1, 1.0)}
"""Section 3 / Figs. 5-10: coupled order -> (rotor index, waves) of the mode it shows: 1st and
2nd = rotor 1's and rotor 2's first (0.5 wave), 3rd and 5th = their second (1 wave); the 4th is
rotor 1's bending-torsion mode (no wave count given)."""


def paper_pair() -> SpurPair:
    """Table 2: z 38 / 228, m 9 mm, b 0.1 m, 8.2 / 730.6 kg, 0.02 / 115.72 kg m^2, 20 deg,
    addendum 1, azimuth 45 deg."""
    return SpurPair(
        z1=38, z2=228, module_m=0.009, face_width_m=0.1, pressure_angle_deg=20.0,
        addendum_coeff=1.0, mass1_kg=8.2, mass2_kg=730.6, polar_inertia1_kgm2=0.02,
        polar_inertia2_kgm2=115.72, azimuth_deg=45.0,
    )


@dataclass(frozen=True)
class Assumptions:
    """What the paper leaves out (see the module docstring and docs/seed004.md)."""

    material: Material = STEEL
    disc_at: float = 1.0 / 3.0
    """Disc position as a fraction of its shaft's length."""
    gear_at: float = 2.0 / 3.0
    """Gear position as a fraction of its shaft's length."""
    bearings_at: tuple[float, float] = (0.0, 1.0)
    """Bearing positions as fractions of the shaft length."""
    bearing_per_rotor: bool = True
    """Table 1's bearing 1 under rotor 1 (both ends), bearing 2 under rotor 2; False: each
    rotor has bearing 1 at its first and bearing 2 at its second end."""
    diametral_fraction: float = 0.5
    elements: int = 24
    shear: bool = True
    mesh_stiffness_N_per_m: float | None = None
    """None: eq. (8) with b in mm (3.06e9 N/m); a number overrides it (sensitivity)."""
    azimuth_deg: float | None = None
    """None: Table 2's 45 deg."""
    anisotropy: float = 1.0
    """k_yy / k_xx of every bearing (Table 1 gives one stiffness: 1.0)."""

    def to_dict(self) -> dict:
        d = asdict(self)
        d["material"] = asdict(self.material)
        return d


def _bearing(name: str, pos: float, k: float, c: float, anisotropy: float) -> Bearing:
    return Bearing(name, pos, k, k * anisotropy, c, c)


def paper_rotors(a: Assumptions = Assumptions()) -> tuple[Rotor, Rotor]:
    """Rotors 1 and 2 of Table 1 with their discs, gears (Table 2) and bearings, as assumed."""
    pair = paper_pair()
    rotors = []
    for i in range(2):
        length = SHAFT_LENGTH_M[i]
        gear = gear_discs(pair, a.gear_at * SHAFT_LENGTH_M[0], a.gear_at * SHAFT_LENGTH_M[1],
                          a.diametral_fraction)[i]
        disc = Disc(f"disc {i + 1}", a.disc_at * length, DISC_MASS_KG[i],
                    DISC_POLAR_INERTIA_KGM2[i], a.diametral_fraction * DISC_POLAR_INERTIA_KGM2[i])
        bearings = tuple(
            _bearing(
                f"bearing {(i if a.bearing_per_rotor else end) + 1} ({end + 1})",
                frac * length,
                BEARING_STIFFNESS_N_PER_M[i if a.bearing_per_rotor else end],
                BEARING_DAMPING_NS_PER_M[i if a.bearing_per_rotor else end],
                a.anisotropy,
            )
            for end, frac in enumerate(a.bearings_at)
        )
        rotors.append(Rotor(
            name=f"rotor {i + 1}", length_m=length, radius_m=SHAFT_RADIUS_M[i],
            discs=(disc, gear), bearings=bearings, material=a.material,
            elements=a.elements, shear=a.shear,
        ))
    return rotors[0], rotors[1]


def paper_mesh(a: Assumptions = Assumptions()) -> MeshProperties:
    """Eqs. (8)-(11) for Table 2's pair (k_m overridden if the assumptions say so)."""
    mesh = mesh_properties(paper_pair())
    if a.mesh_stiffness_N_per_m is not None:
        mesh = replace(mesh, mesh_stiffness_N_per_m=a.mesh_stiffness_N_per_m)
    return mesh


def single_rotor(index: int, a: Assumptions = Assumptions()) -> SystemMatrices:
    """Rotor 1 (index 0) or rotor 2 (index 1) alone, its gear a plain disc."""
    return assemble([paper_rotors(a)[index]])


def coupled_rotor(a: Assumptions = Assumptions()) -> SystemMatrices:
    """Both rotors joined by the mesh of eq. (15) at the gears."""
    r1, r2 = paper_rotors(a)
    return geared_rotor(
        r1, r2, paper_pair(), a.gear_at * SHAFT_LENGTH_M[0], a.gear_at * SHAFT_LENGTH_M[1],
        mesh=paper_mesh(a), azimuth_deg=a.azimuth_deg,
    )


@dataclass(frozen=True)
class Table3:
    """Our critical speeds (r/min) beside Table 3's."""

    rotor1: list[CriticalSpeed]
    rotor2: list[CriticalSpeed]
    coupled: list[CriticalSpeed]
    """Crossings of rotor 1's (the driving rotor's) 1X line."""
    coupled_rotor2_line: list[CriticalSpeed]
    """Crossings of rotor 2's 1X line, in rotor 2's r/min."""
    coupled_standstill_rpm: np.ndarray
    assumptions: Assumptions
    mesh: MeshProperties
    rows: list[tuple[str, float, float]] = field(default_factory=list)
    """(label, paper r/min, ours r/min) for every Table 3 value, n-th beside n-th."""
    family_rows: list[tuple[str, float, float]] = field(default_factory=list)
    """(label, paper, ours) pairing the coupled modes the paper describes with our first mode
    of the same rotor and wave count."""

    def to_dict(self) -> dict:
        def crit(items: list[CriticalSpeed]) -> list[dict]:
            return [c.to_dict() for c in items]

        return {
            "format": "seed004-critical-speeds/1",
            "assumptions": self.assumptions.to_dict(),
            "mesh": self.mesh.to_dict(),
            "rotor1": crit(self.rotor1),
            "rotor2": crit(self.rotor2),
            "coupled": crit(self.coupled),
            "coupled_rotor2_line": crit(self.coupled_rotor2_line),
            "coupled_standstill_rpm": [float(x) for x in self.coupled_standstill_rpm],
            "table3": [
                _row(label, paper, ours) for label, paper, ours in self.rows
            ],
            "table3_by_mode_family": [
                _row(label, paper, ours) for label, paper, ours in self.family_rows
            ],
        }


def _row(label: str, paper: float, ours: float) -> dict:
    if math.isnan(ours):  # fewer modes than the paper lists below max_rpm
        return {"label": label, "paper_rpm": paper, "ours_rpm": None}
    return {"label": label, "paper_rpm": paper, "ours_rpm": ours,
            "difference_rpm": ours - paper, "difference_pct": 100 * (ours - paper) / paper}


def first_of_family(items: list[CriticalSpeed], rotor: int, waves: float) -> CriticalSpeed | None:
    """The lowest lateral (not pure torsion) critical speed of ``rotor`` with ``waves``."""
    for item in items:
        if item.kind != "torsion" and item.dominant_rotor == rotor and item.waves == waves:
            return item
    return None


def table3(a: Assumptions = Assumptions(), max_rpm: float = 1e4) -> Table3:
    """Critical speeds of rotor 1, rotor 2 and the coupled rotor, paired order by order with
    Table 3 (the n-th of ours beside the paper's n-th)."""
    r1 = critical_speeds(single_rotor(0, a), max_rpm=max_rpm)
    r2 = critical_speeds(single_rotor(1, a), max_rpm=max_rpm)
    system = coupled_rotor(a)
    coupled = critical_speeds(system, 0, max_rpm=max_rpm)
    coupled_2 = critical_speeds(system, 1, max_rpm=max_rpm)
    standstill = standstill_modes(system)[0]
    rows = []
    for label, paper, ours in (("rotor 1", PAPER_ROTOR1_RPM, r1),
                               ("rotor 2", PAPER_ROTOR2_RPM, r2),
                               ("coupled", PAPER_COUPLED_RPM, coupled)):
        for n, value in enumerate(paper):
            mine = ours[n].speed_rpm if n < len(ours) else float("nan")
            rows.append((f"{label} order {n + 1}", value, mine))
    families = []
    for order, (rotor, waves) in PAPER_COUPLED_FAMILIES.items():
        match = first_of_family(coupled, rotor, waves)
        families.append((f"coupled order {order} = rotor {rotor + 1}, {waves:g} wave",
                         PAPER_COUPLED_RPM[order - 1],
                         match.speed_rpm if match is not None else float("nan")))
    return Table3(r1, r2, coupled, coupled_2, standstill[standstill < max_rpm], a,
                  paper_mesh(a), rows, families)
