"""Seed 003: geometric transmission error model of a multi-stage 2K-H planetary train.

Wang Chaobing et al., "Influence of error's randomness on transmission accuracy of planetary
gear", J. Chongqing Univ. 35(9), 2012 (seed 003). This module turns the paper's model into a
list of :class:`ErrorSource` terms; :mod:`analysis.models.seed003_montecarlo` samples them.

The model, in the paper's equations:

- every eccentricity projects onto the external (w) or internal (n) line of action as a
  sinusoid of the member's speed relative to the carrier (Table 1, eq. 1); tooth errors
  (pitch, profile, thickness) add a constant ``f`` per gear (eqs. 2-3);
- a stage's carrier angle error is ``k_w e_w + k_n e_n`` (eqs. 4-10) with
  ``k_w = 1 / (1000 r_bs i_sc)`` and ``k_n = -i^c_sp / (1000 r_bp i_sc)`` rad/um,
  ``i^c_sp = -z_p / z_s`` (sun to planet with the carrier held), ``i_sc = 1 + z_I / z_s``;
- stages add at the output divided by the ratio from their carrier to the output (eq. 11).

Time is the output carrier angle ``psi`` (rad): one output revolution is ``psi`` in
[0, 2 pi). A source of frequency ``nu`` (cycles per output revolution), weight ``W``
(complex, arcsec/um), value ``v`` (um) and initial phase ``p`` (rad) contributes
``v * Im(W * exp(i (nu psi + p)))`` arcsec to the output transmission error.

The ambiguities of the printed paper are choices of :class:`PaperReading`; docs/seed003.md
says which one is the default and why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

from analysis.errors import AnalysisError

ARCSEC_PER_RAD = 180.0 * 3600.0 / math.pi
"""Seconds of arc in one radian (206264.8...)."""

Kind = Literal["E", "A", "f"]
"""E: machining eccentricity, A: installation eccentricity, f: tooth (pitch/profile/thickness)
error on the line of action (Table 1 and eqs. 2-3)."""

Member = Literal["s", "p", "I", "c"]
"""s: sun, p: planet, I: ring (内齿圈), c: carrier."""

MEMBER_NAMES = {"s": "sun", "p": "planet", "I": "ring", "c": "carrier"}
KIND_NAMES = {
    "E": "machining eccentricity",
    "A": "installation eccentricity",
    "f": "tooth error",
}


@dataclass(frozen=True)
class Stage:
    """One 2K-H stage: sun input, carrier output, ring fixed (paper Fig. 2).

    Tolerances are in um and keyed by ``(kind, member)``; a key that is absent means the
    error is not modelled (a floating member has no installation eccentricity, the ring is
    the reference). ``("E", m)`` and ``("A", m)`` are the bounds ``T`` of eq. (16); ``("f", m)``
    is the half tolerance ``T/2`` of eq. (17), the column ``T/2(f)`` of Table 2.
    """

    name: str
    z_sun: int
    z_planet: int
    z_ring: int
    tolerances_um: dict[tuple[str, str], float]
    module_mm: float = 1.0
    pressure_angle_ext_deg: float = 20.0
    pressure_angle_int_deg: float = 20.0

    def __post_init__(self) -> None:
        for label, z in (("z_sun", self.z_sun), ("z_planet", self.z_planet)):
            if z <= 0:
                raise AnalysisError(f"stage {self.name}: {label} must be positive, got {z}")
        if self.z_ring <= self.z_sun:
            raise AnalysisError(
                f"stage {self.name}: z_ring must exceed z_sun, got {self.z_ring} <= {self.z_sun}"
            )
        for key, value in self.tolerances_um.items():
            if key[0] not in KIND_NAMES or key[1] not in MEMBER_NAMES:
                raise AnalysisError(f"stage {self.name}: unknown tolerance key {key}")
            if not (value >= 0.0 and math.isfinite(value)):
                raise AnalysisError(f"stage {self.name}: tolerance {key} must be >= 0, got {value}")

    def base_radius_mm(self, z: int) -> float:
        """Base circle radius ``r_b = m z cos(alpha) / 2`` (mm), Table 2 column r_b."""
        return self.module_mm * z * math.cos(math.radians(self.pressure_angle_ext_deg)) / 2.0

    @property
    def ratio(self) -> float:
        """Sun-to-carrier ratio ``i_sc = 1 + z_I / z_s`` with the ring fixed."""
        return 1.0 + self.z_ring / self.z_sun


@dataclass(frozen=True)
class PaperReading:
    """How the ambiguous places of the printed paper are read (docs/seed003.md, section 3).

    - ``table1_signs``: ``"printed"`` uses Table 1 as printed; ``"consistent"`` derives every
      sign from one convention (a member's centre displacement ``c`` gives ``+c.u`` for the
      planet and ``-c.u`` for sun and ring), which flips the planet's machining eccentricity on
      the external mesh and the ring's eccentricities.
    - ``planet_speed``: ``"kinematic"`` uses ``w_p - w_c = -(z_s/z_p)(w_s - w_c)`` (ring
      fixed); ``"printed"`` uses the paper's value ``w_p = -(z_s/z_p) w_s`` (-20 pi/3 rad/s).
    - ``stage3_planet_row``: Table 2 row "III p: 31 14.565 16 8" has two values for three
      columns. ``"E_f"`` reads T(E) = 16, T/2(f) = 8 and no installation tolerance;
      ``"E_A"`` reads T(E) = 16, T(A) = 8 and no tooth error; ``"E_A_f10"`` reads
      T(E) = 16, T(A) = 8 and takes T/2(f) = 10 um, the value Table 2 gives every other gear
      of 20-50 mm diameter (stage III sun, stage I and II planets).
    """

    table1_signs: Literal["printed", "consistent"] = "printed"
    planet_speed: Literal["kinematic", "printed"] = "kinematic"
    stage3_planet_row: Literal["E_f", "E_A", "E_A_f10"] = "E_A_f10"


DEFAULT_READING = PaperReading()


@dataclass(frozen=True)
class PlanetaryTrain:
    """Stages from input (first) to output (last), each stage's carrier driving the next sun."""

    stages: tuple[Stage, ...]
    reading: PaperReading = field(default=DEFAULT_READING)

    def __post_init__(self) -> None:
        if not self.stages:
            raise AnalysisError("a planetary train needs at least one stage")

    @property
    def total_ratio(self) -> float:
        """Input sun to output carrier ratio (320 for the paper's example)."""
        return math.prod(stage.ratio for stage in self.stages)

    def carrier_to_output_ratio(self, index: int) -> float:
        """``i_jm`` of eq. (11): ratio from stage ``index``'s carrier to the output carrier."""
        return math.prod(stage.ratio for stage in self.stages[index + 1 :])


@dataclass(frozen=True)
class ErrorSource:
    """One random error and the sinusoid it adds to the output transmission error.

    ``weight`` (arcsec/um, complex): the term is ``v * Im(weight * exp(i (nu psi + p)))``.
    ``frequency_per_rev`` ``nu``: cycles per output revolution (0 for a constant term).
    ``bound_um``: ``T`` for eccentricities (Rayleigh truncated at ``T = 2 sigma_0``, eq. 16),
    ``T/2`` for tooth errors (normal truncated at ``+-1.6 sigma``, eq. 17).
    ``has_phase``: eccentricities carry a uniform initial phase (eq. 12); tooth errors do not.
    """

    name: str
    description: str
    stage: str
    kind: str
    member: str
    frequency_per_rev: float
    weight: complex
    bound_um: float
    has_phase: bool

    @property
    def sensitivity_arcsec_per_um(self) -> float:
        """Amplitude of this source's term per um of error (arcsec/um)."""
        return abs(self.weight)


def paper_train(reading: PaperReading = DEFAULT_READING) -> PlanetaryTrain:
    """The paper's example: three 2K-H stages in series, module 1 mm, 20 deg (Table 2).

    Stage I and II carriers and planets and stage II and III suns float, so they have no
    installation eccentricity; the ring is the reference (section 3.1). Table 2 prints
    installation tolerances for the stage III carrier (15 um) and, under the default reading,
    the stage III planets (8 um); the stage I sun's is not printed and is left out.
    """
    sun_12 = {("E", "s"): 13.0, ("E", "p"): 16.0, ("E", "I"): 21.0}
    tooth_12 = {("f", "s"): 8.0, ("f", "p"): 10.0, ("f", "I"): 13.0}
    stage3 = {
        ("E", "s"): 16.0,
        ("E", "p"): 16.0,
        ("E", "I"): 21.0,
        ("A", "c"): 15.0,
        ("f", "s"): 10.0,
        ("f", "p"): 8.0,
        ("f", "I"): 13.0,
    }
    if reading.stage3_planet_row == "E_A":
        stage3[("A", "p")] = 8.0
        del stage3[("f", "p")]
    elif reading.stage3_planet_row == "E_A_f10":
        stage3[("A", "p")] = 8.0
        stage3[("f", "p")] = 10.0
    stages = (
        Stage("I", 12, 36, 84, {**sun_12, **tooth_12}),
        Stage("II", 12, 36, 84, {**sun_12, **tooth_12}),
        Stage("III", 21, 31, 84, stage3),
    )
    return PlanetaryTrain(stages, reading)


def _phasor(angle_rad: float) -> complex:
    return complex(math.cos(angle_rad), math.sin(angle_rad))


def stage_coefficients_arcsec_per_um(stage: Stage) -> tuple[float, float]:
    """``(k_w, k_n)`` of eq. (10) for the stage's own carrier (arcsec per um on the line).

    Eq. (7): ``k_w = 1/(1000 r_bs i_sc)``, ``k_n = -i^c_sp/(1000 r_bp i_sc)`` rad/um with
    ``i^c_sp = -z_p/z_s``; converted to arcsec.
    """
    i_sp_carrier_held = -stage.z_planet / stage.z_sun
    r_bs = stage.base_radius_mm(stage.z_sun)
    r_bp = stage.base_radius_mm(stage.z_planet)
    k_w = 1.0 / (1000.0 * r_bs * stage.ratio)
    k_n = -i_sp_carrier_held / (1000.0 * r_bp * stage.ratio)
    return k_w * ARCSEC_PER_RAD, k_n * ARCSEC_PER_RAD


def error_sources(train: PlanetaryTrain) -> tuple[ErrorSource, ...]:
    """All error terms of the train at its output (Table 1, eqs. 2-3, 7 and 11).

    Phase ``phi_i = 0`` (first planet; the paper takes the planets as load sharing equally).
    """
    reading = train.reading
    flip = -1.0 if reading.table1_signs == "consistent" else 1.0
    sources: list[ErrorSource] = []
    carrier_speed = 1.0  # output carrier: one cycle per output revolution
    speeds: list[float] = []
    for stage in reversed(train.stages):
        speeds.append(carrier_speed)
        carrier_speed *= stage.ratio
    speeds.reverse()
    for index, stage in enumerate(train.stages):
        w_c = speeds[index]
        w_s = w_c * stage.ratio
        if reading.planet_speed == "kinematic":
            w_p_rel = -(stage.z_sun / stage.z_planet) * (w_s - w_c)
        else:
            w_p_rel = -(stage.z_sun / stage.z_planet) * w_s - w_c
        k_w, k_n = stage_coefficients_arcsec_per_um(stage)
        scale = 1.0 / train.carrier_to_output_ratio(index)
        k_w *= scale
        k_n *= scale
        a_w = math.radians(stage.pressure_angle_ext_deg)
        a_n = math.radians(stage.pressure_angle_int_deg)
        ext, internal = _phasor(a_w), _phasor(-a_n)
        # (kind, member) -> (frequency, weight) from Table 1 with phi_i = 0.
        table: dict[tuple[str, str], tuple[float, complex]] = {
            ("E", "s"): (w_s - w_c, -k_w * ext),
            ("E", "p"): (w_p_rel, flip * -k_w * ext + k_n * internal),
            ("E", "I"): (-w_c, flip * k_n * internal),
            ("A", "s"): (-w_c, -k_w * ext),
            ("A", "p"): (0.0, k_w * ext + k_n * internal),
            ("A", "c"): (-w_c, k_w * ext + k_n * internal),
            ("A", "I"): (-w_c, flip * k_n * internal),
            # Tooth errors have no phase: Im(1j * k) = k, a constant on the line (eqs. 2-3).
            ("f", "s"): (0.0, 1j * k_w),
            ("f", "p"): (0.0, 1j * (k_w + k_n)),
            ("f", "I"): (0.0, 1j * k_n),
        }
        for (kind, member), bound in sorted(stage.tolerances_um.items()):
            if (kind, member) not in table:
                raise AnalysisError(
                    f"stage {stage.name}: the model has no term for {KIND_NAMES[kind]} of the "
                    f"{MEMBER_NAMES[member]} (Table 1 includes the carrier's machining "
                    "eccentricity in the planet pin errors)"
                )
            frequency, weight = table[(kind, member)]
            sources.append(
                ErrorSource(
                    name=f"{kind}_{member}_{stage.name}",
                    description=(
                        f"stage {stage.name} {MEMBER_NAMES[member]} {KIND_NAMES[kind]}"
                    ),
                    stage=stage.name,
                    kind=kind,
                    member=member,
                    frequency_per_rev=frequency,
                    weight=weight,
                    bound_um=bound,
                    has_phase=kind != "f",
                )
            )
    return tuple(sources)
