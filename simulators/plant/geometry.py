"""Geometry of the simulated mesh: the free play over lock angle, temperature and tooth.

The nominal play and mesh stiffness are those of the reference nominal model
(docs/run-format.md: seed 000 eqs. 1-3, 12-14; seed 004 eq. 8). On top of them, the
position- and temperature-dependent play terms of the switchable effects:

* runout: center distance |AB| of seed 000 eq. (4) at the locked eccentric-shaft angle,
  eccentricities |AO1| = F_r,internal / 2 and |BO2| = F_r,external / 2 (eq. 7's de = F_r / 2),
  play change ``-2 tan(alpha) (|AB| - a)`` (eq. 3; a larger center distance closes the play);
* tooth spacing error (seed 003's tooth-frequency errors): per-tooth thickness deviations
  change the play, per-tooth pitch (position) deviations shift both flanks;
* bearing clearance: extra play ``2 tan(alpha) sum(u_r / 2)`` (eq. 3 with eq. 7's de = u_r/2);
* thermal expansion: ``coefficient_um_per_K (T_housing - reference_C)`` of circumferential play.

Plays are circumferential on the ring's reference circle (um) and output angles (arcmin)
through seed 000 eq. (1): ``play_arcmin = 6.876 j_t / (m z_internal)``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, Protocol

import numpy as np

from analysis.models.nominal import NominalModel, reference_nominal_model


class UnitAndEffects(Protocol):
    """What the geometry reads of a :class:`simulators.plant.config.PlantConfig`: the unit
    table and the effects. A protocol, so that the configuration, which builds a geometry to
    check its unit, and the geometry do not import each other."""

    unit: Mapping[str, Any]
    effects: Any

EQ1_FACTOR = 6.876
"""Seed 000 eq. (1) as printed: arcmin = 6.876 j_t(um) / (m z_internal)."""

ARCMIN_PER_RAD = 10800.0 / math.pi


@dataclass(frozen=True)
class NominalMesh:
    """The reference nominal model's numbers for one unit (run-format.md, version 1)."""

    play_um: float
    play_arcmin: float
    mesh_stiffness_N_per_um: float
    stiffness_Nm_per_arcmin: float
    contact_ratio: float
    working_pressure_angle_deg: float

    @classmethod
    def of(cls, model: NominalModel) -> NominalMesh:
        """The numbers of an analysis nominal model (each field from the model's own)."""
        return cls(**{f.name: getattr(model, f.name) for f in fields(cls)})


def reference_nominal(unit: Mapping[str, Any]) -> NominalMesh:
    """The reference nominal model of run-format.md for a run.json ``unit`` mapping.

    Delegates to :func:`analysis.models.nominal.reference_nominal_model` (seed 000 eqs. 1-3
    and 12-14 for the play, seed 004 eq. 8 for the stiffness). The plant needs a finite
    stiffness: ``unit.face_width_mm`` is required."""
    if not isinstance(unit, Mapping):
        raise ValueError(f"unit: expected a table, got {type(unit).__name__}")
    model = reference_nominal_model(unit)
    if not math.isfinite(model.stiffness_Nm_per_arcmin):
        raise ValueError("key unit.face_width_mm: missing (the plant needs the mesh stiffness)")
    return NominalMesh.of(model)


class UnitView:
    """Typed access to the unit mapping; errors name ``unit.<key>``."""

    def __init__(self, unit: Mapping[str, Any]) -> None:
        if not isinstance(unit, Mapping):
            raise ValueError(f"unit: expected a table, got {type(unit).__name__}")
        self.unit = unit

    def num(self, key: str, default: float | None = None) -> float:
        value = self.unit.get(key, default)
        if value is None:
            raise ValueError(f"key unit.{key}: missing (the plant needs it)")
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"key unit.{key}: expected a number, got {value!r}")
        if not (math.isfinite(value) and value >= 0):
            raise ValueError(f"key unit.{key}: expected a finite number >= 0, got {value!r}")
        return float(value)

    def int_(self, key: str) -> int:
        value = self.unit.get(key)
        if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
            raise ValueError(f"key unit.{key}: expected a positive integer, got {value!r}")
        return value

    def nums(self, key: str, default: list[float] | None = None) -> list[float]:
        value = self.unit.get(key, default)
        if isinstance(value, int | float) and not isinstance(value, bool):
            value = [value]
        if not isinstance(value, list | tuple) or not value:
            raise ValueError(f"key unit.{key}: expected a non-empty list of numbers, got {value!r}")
        return [_checked(key, i, v) for i, v in enumerate(value)]


def _checked(key: str, index: int, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"key unit.{key}[{index}]: expected a finite number, got {value!r}")
    return float(value)


def _tooth_table(explicit: list[float] | None, count: int, rms: float,
                 rng: np.random.Generator, name: str) -> np.ndarray:
    if explicit is not None:
        if len(explicit) != count:
            raise ValueError(
                f"key effects.tooth_spacing_error.{name}: expected {count} values (one per "
                f"tooth), got {len(explicit)}"
            )
        return np.asarray(explicit, dtype=float)
    values = rng.standard_normal(count) * rms
    return values - values.mean()


@dataclass(frozen=True)
class MeshGeometry:
    """Everything position/temperature dependent about the free play, from a PlantConfig."""

    nominal: NominalMesh
    z_internal: int
    z_external: int
    module_mm: float
    tan_alpha: float
    eccentric_distance_mm: float
    runout_on: bool
    ecc_internal_mm: float
    ecc_external_mm: float
    beta_rad: float
    internal_phase_rad: float
    spacing_on: bool
    thickness_internal_um: np.ndarray
    thickness_external_um: np.ndarray
    pitch_internal_um: np.ndarray
    pitch_external_um: np.ndarray
    bearing_play_um: float
    thermal_um_per_K: float
    thermal_reference_C: float
    runout_sign: float = -1.0
    """Sign of the play change with the center distance: -1 for an internal pair (seed 000
    eq. 3: a larger center distance closes the play), +1 for an external one."""
    kind: str = "internal_involute"
    spacing_transition: float = 0.0
    kinematic_on: bool = False
    kinematic_internal_um: float = 0.0
    kinematic_external_um: float = 0.0
    kinematic_internal_phase_rad: float = 0.0
    kinematic_beta_rad: float = 0.0

    @property
    def ratio(self) -> float:
        """Input turns per output turn, ``z_external / (z_internal - z_external)``; the output
        turns opposite to the input."""
        return self.z_external / (self.z_internal - self.z_external)

    @property
    def mesh_stiffening(self) -> tuple[tuple[float, float], ...]:
        """Flank torques (N*m) where more flanks take load and the compliance (rad/(N*m)) each
        takes off the mesh's; none for the involute pair (one linear stiffness)."""
        return ()

    def base_play_um(self, input_angle_deg: float) -> float:
        """The unit's own play (um) at the lock angle before the switchable effects: the
        reference nominal model's, the same at every angle for the involute pair."""
        return self.nominal.play_um

    def kind_truth(self, input_angle_deg: float) -> dict[str, Any]:
        """Kind-specific true values at the lock angle (none for the involute pair)."""
        return {}

    @classmethod
    def from_config(cls, config: UnitAndEffects) -> MeshGeometry:
        """Build from the unit table and the effects (raises ValueError naming the key)."""
        unit = config.unit
        nominal = reference_nominal(unit)
        u = UnitView(unit)
        z1, z2 = u.int_("z_internal"), u.int_("z_external")
        alpha = math.radians(u.num("pressure_angle_deg", 20.0))
        m = u.num("module_mm")
        a = u.num("center_distance_mm", m * (z1 - z2) / 2.0)
        return cls.build(config, nominal, z1, z2, m, math.tan(alpha), a)

    @classmethod
    def build(cls, config: UnitAndEffects, nominal: NominalMesh, z1: int, z2: int, m: float,
              tan_alpha: float, a: float, **extra: Any) -> MeshGeometry:
        """The geometry with the switchable effects' tables (runout, tooth spacing, bearing,
        thermal) for tooth counts z1 (``*_internal`` tables) and z2 (``*_external``), module
        ``m`` (mm), play sensitivity ``tan_alpha`` (2 tan_alpha um of play per um of center
        distance) and center distance ``a`` (mm); ``extra``: a subclass's own fields."""
        u = UnitView(config.unit)
        fx = config.effects

        ro = fx.runout
        f_int = ro.internal_mm if ro.internal_mm is not None else (
            u.num("runout_internal_mm") if ro.enabled else 0.0)
        f_ext = ro.external_mm if ro.external_mm is not None else (
            u.num("runout_external_mm") if ro.enabled else 0.0)

        sp = fx.tooth_spacing_error
        rng = np.random.default_rng(sp.seed)
        thick_int = _tooth_table(sp.thickness_internal_um, z1, sp.thickness_error_um_rms, rng,
                                 "thickness_internal_um")
        thick_ext = _tooth_table(sp.thickness_external_um, z2, sp.thickness_error_um_rms, rng,
                                 "thickness_external_um")
        pitch_int = _tooth_table(sp.pitch_internal_um, z1, sp.pitch_error_um_rms, rng,
                                 "pitch_internal_um")
        pitch_ext = _tooth_table(sp.pitch_external_um, z2, sp.pitch_error_um_rms, rng,
                                 "pitch_external_um")

        bc = fx.bearing_clearance
        bearing_um = 0.0
        if bc.enabled:
            clearances = bc.clearance_mm if bc.clearance_mm is not None else u.nums(
                "bearing_clearance_mm")
            bearing_um = 1000.0 * 2.0 * tan_alpha * sum(c / 2.0 for c in clearances)

        th = fx.thermal_expansion
        ke = fx.kinematic_error
        ke_int = ke.internal_um if ke.internal_um is not None else (
            1000.0 * u.num("runout_internal_mm") / 2.0 if ke.enabled else 0.0)
        ke_ext = ke.external_um if ke.external_um is not None else (
            1000.0 * u.num("runout_external_mm") / 2.0 if ke.enabled else 0.0)
        return cls(
            nominal=nominal, z_internal=z1, z_external=z2, module_mm=m,
            tan_alpha=tan_alpha, eccentric_distance_mm=a,
            runout_on=ro.enabled, ecc_internal_mm=f_int / 2.0, ecc_external_mm=f_ext / 2.0,
            beta_rad=math.radians(ro.beta_deg),
            internal_phase_rad=math.radians(ro.internal_phase_deg),
            spacing_on=sp.enabled, thickness_internal_um=thick_int,
            thickness_external_um=thick_ext, pitch_internal_um=pitch_int,
            pitch_external_um=pitch_ext, bearing_play_um=bearing_um,
            thermal_um_per_K=th.coefficient_um_per_K if th.enabled else 0.0,
            thermal_reference_C=th.reference_C, **extra,
            spacing_transition=sp.transition_fraction if sp.enabled else 0.0,
            kinematic_on=ke.enabled, kinematic_internal_um=ke_int,
            kinematic_external_um=ke_ext,
            kinematic_internal_phase_rad=math.radians(ke.internal_phase_deg),
            kinematic_beta_rad=math.radians(ke.beta_deg),
        )

    def arcmin_from_um(self, j_t_um: float) -> float:
        """Seed 000 eq. (1): circumferential play (um) -> output angle (arcmin)."""
        return EQ1_FACTOR * j_t_um / (self.module_mm * self.z_internal)

    def center_distance_mm(self, input_angle_deg: float) -> float:
        """Seed 000 eq. (4), |AB| (mm) at eccentric-shaft angle theta, with |O1O2| = a.

        Generalised by a phase ``internal_phase`` of the ring's eccentricity AO1 (eq. 4 as
        printed has it along x, phase 0)."""
        theta = math.radians(input_angle_deg)
        phase = (self.z_internal - self.z_external) * theta / self.z_external + self.beta_rad
        a = self.eccentric_distance_mm
        x = (a * math.cos(theta) + self.ecc_external_mm * math.cos(phase)
             + self.ecc_internal_mm * math.cos(self.internal_phase_rad))
        y = (a * math.sin(theta) + self.ecc_external_mm * math.sin(phase)
             + self.ecc_internal_mm * math.sin(self.internal_phase_rad))
        return math.hypot(x, y)

    def runout_play_um(self, input_angle_deg: float) -> float:
        """Play change from runout (um): ``-2 tan(alpha) (|AB| - a)``, seed 000 eq. (3)."""
        if not self.runout_on:
            return 0.0
        delta_a_mm = self.center_distance_mm(input_angle_deg) - self.eccentric_distance_mm
        delta_a_um = 1000.0 * delta_a_mm
        return self.runout_sign * 2.0 * self.tan_alpha * delta_a_um

    def tooth_pair(self, input_angle_deg: float) -> tuple[int, int, int]:
        """(mesh index n, ring tooth, pinion tooth) in contact at the eccentric-shaft angle.

        The contact point turns with the eccentric: one tooth pair per 360 / z_internal deg."""
        n = math.floor(input_angle_deg * self.z_internal / 360.0 + 1e-9)
        return n, n % self.z_internal, n % self.z_external

    def _handover(self, input_angle_deg: float) -> tuple[int, int, int, int, float]:
        """(ring tooth, pinion tooth, next ring tooth, next pinion tooth, weight of the next
        pair): over the last ``spacing_transition`` of each tooth pitch the load passes
        linearly to the next pair (0: a step at the pitch boundary)."""
        n, i, j = self.tooth_pair(input_angle_deg)
        w = 0.0
        tr = self.spacing_transition
        if tr > 0.0:
            frac = input_angle_deg * self.z_internal / 360.0 + 1e-9 - n
            w = min(max((frac - (1.0 - tr)) / tr, 0.0), 1.0)
        return i, j, (n + 1) % self.z_internal, (n + 1) % self.z_external, w

    def spacing_play_um(self, input_angle_deg: float) -> float:
        """Play change (um) of the tooth pair in mesh: sum of the two thickness deviations."""
        if not self.spacing_on:
            return 0.0
        i, j, i2, j2, w = self._handover(input_angle_deg)
        value = self.thickness_internal_um[i] + self.thickness_external_um[j]
        if w:
            value += w * (self.thickness_internal_um[i2] + self.thickness_external_um[j2]
                          - value)
        return float(value)

    def pitch_offset_um(self, input_angle_deg: float) -> float:
        """Shift of both flanks (um on the reference circle) of the tooth pair in mesh."""
        if not self.spacing_on:
            return 0.0
        i, j, i2, j2, w = self._handover(input_angle_deg)
        value = self.pitch_internal_um[i] - self.pitch_external_um[j]
        if w:
            value += w * (self.pitch_internal_um[i2] - self.pitch_external_um[j2] - value)
        return float(value)

    def kinematic_error_um(self, input_angle_deg: float) -> float:
        """The unit's kinematic error from its eccentricities (um on the ring's reference
        circle; eq. 1 makes it an output angle): the tangential part, across the crank line,
        of seed 000 eq. (4)'s vectors |AO1| (ring, fixed, phase ``internal_phase``) and
        |BO2| (pinion, spinning with the output), where eq. (4)'s radial part is the
        runout's play (eqs. 3, 7)::

            e_t = |AO1| sin(phase_int - theta) + |BO2| sin(psi + beta - theta),
            psi = -(Z1 - Z2) theta / Z2   (the pinion spins against the crank, as the
                                           paper's text says; eq. 4 prints +)

        With the output angle ``theta_out = -theta / ratio`` the ring's term is
        ``|AO1| sin(ratio theta_out + phase_int)``: once per input turn, order ``ratio`` (8)
        per output revolution; the pinion's ``|BO2| sin((ratio + 1) theta_out + beta)``:
        once per turn of the pinion against the crank, order ``ratio + 1`` (9), the same
        kinematics as the tooth pair in mesh (:meth:`tooth_pair`)."""
        if not self.kinematic_on:
            return 0.0
        theta = math.radians(input_angle_deg)
        psi = -(self.z_internal - self.z_external) * theta / self.z_external
        return (self.kinematic_internal_um * math.sin(self.kinematic_internal_phase_rad - theta)
                + self.kinematic_external_um * math.sin(psi + self.kinematic_beta_rad - theta))

    def thermal_play_um(self, temperature_C: float) -> float:
        """Play change (um) from the housing temperature (linear)."""
        return self.thermal_um_per_K * (temperature_C - self.thermal_reference_C)

    def mesh_play_um(self, input_angle_deg: float, temperature_C: float) -> float:
        """Circumferential play of the mesh (um, >= 0): nominal + runout + spacing + thermal.

        A negative sum (interference) is clamped at zero: the mesh is then preloaded."""
        total = (self.base_play_um(input_angle_deg) + self.runout_play_um(input_angle_deg)
                 + self.spacing_play_um(input_angle_deg) + self.thermal_play_um(temperature_C))
        return max(total, 0.0)

    def worst_case_runout_play_um(self) -> float:
        """Seed 000 Table 3's worst-case runout term ``2 tan(a) (F_r1 + F_r2) / 2`` (um)."""
        return 2.0 * self.tan_alpha * 1000.0 * (self.ecc_internal_mm + self.ecc_external_mm)
