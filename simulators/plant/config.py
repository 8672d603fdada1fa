"""Configuration of the simulated plant: pydantic models read from one TOML file.

Every parameter of every effect lives in one TOML (``simulators/default_plant.toml`` is the
default). Units are in the names: angles at the edges in arcmin/arcsec/deg, lengths of the
gear data in mm/um (as run.json writes them), torques in N*m, times in s.
docs/plant.md describes each table and key.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

DEFAULT_PLANT_TOML = Path(__file__).resolve().parent.parent / "default_plant.toml"

EFFECT_NAMES = (
    "friction",
    "stiffness_nonlinearity",
    "runout",
    "bearing_clearance",
    "thermal_expansion",
    "torque_sensor_offset",
    "shaft_compliance",
    "tooth_spacing_error",
    "kinematic_error",
    "creep",
    "direction_gain",
)
"""Switchable effects: the run-format vocabulary ones, then the out-of-vocabulary ones."""


class PlantConfigError(ValueError):
    """A plant configuration is malformed; the message names the file and the key."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)


class RigConfig(_Strict):
    """The rig around the unit: output inertia, loading drive, encoders, integration step."""

    inertia_kgm2: float = Field(0.02, gt=0)
    drive_time_constant_s: float = Field(0.01, gt=0)
    drive_torque_limit_Nm: float = Field(30.0, gt=0)
    step_s: float = Field(0.001, gt=0, le=0.01)
    output_offset_deg: float = 0.0
    input_speed_deg_per_s: float = Field(360.0, gt=0)
    initial_input_angle_deg: float = 0.0
    start_flank: Literal[-1, 1] = -1
    preload_torque_Nm: float = Field(5.0, ge=0)
    encoder_counts_per_rev: int = Field(8388608, gt=0)
    contact_damping_ratio: float = Field(0.0, ge=0, lt=1)
    """0: the flanks are integrated with the 1-step implicit Euler only (numerically damped:
    no ringing). > 0: an impact on a flank rings at the locked resonance
    ``sqrt(K / inertia) / 2 pi`` with this damping ratio (sub-stepped, model.py)."""
    drive_ripple_Nm: float = Field(0.0, ge=0)
    drive_ripple_Hz: float = Field(100.0, gt=0)
    encoder_eccentricity_arcsec: float = Field(0.0, ge=0)
    """Mounting eccentricity of the output encoder: its reading errs by
    ``E sin(theta_out + phase)`` (arcsec), once per output turn; not the unit's."""
    encoder_eccentricity_phase_deg: float = 0.0
    input_max_speed_rpm: float = Field(3000.0, gt=0)
    """The input motor's speed range (rpm): a faster turn command is refused."""


class MeasurementConfig(_Strict):
    """The measuring system's own artefacts on the torque channel (none by default): a
    first-order sensor lag, an ADC grid, and a torque zero re-tared whenever the drive is
    enabled (the start of each run) with a residual that then random-walks."""

    torque_lag_s: float = Field(0.0, ge=0, le=1)
    torque_adc_bits: int = Field(0, ge=0, le=32)
    torque_adc_full_scale_Nm: float = Field(20.0, gt=0)
    torque_zero_residual_Nm: float = Field(0.0, ge=0)
    torque_zero_walk_Nm_per_sqrt_s: float = Field(0.0, ge=0)


class HousingConfig(_Strict):
    """Housing temperature: first-order response to the ambient/heater setpoint (deg C, s)."""

    initial_C: float = 20.0
    ambient_C: float = 20.0
    time_constant_s: float = Field(300.0, gt=0)


class _Effect(_Strict):
    enabled: bool = False


class FrictionConfig(_Effect):
    """Dahl or LuGre friction between the output and the housing (parallel to the mesh)."""

    model: Literal["dahl", "lugre"] = "dahl"
    coulomb_torque_Nm: float = Field(0.1, ge=0)
    static_torque_Nm: float = Field(0.15, ge=0)
    rest_stiffness_Nm_per_arcmin: float = Field(300.0, gt=0)
    stribeck_velocity_arcmin_per_s: float = Field(5.0, gt=0)
    micro_damping_Nms_per_arcmin: float = Field(0.0, ge=0)
    viscous_Nms_per_arcmin: float = Field(0.0, ge=0)


class StiffnessNonlinearityConfig(_Effect):
    """Contact stiffening: extra twist ``soft_twist (1 - exp(-|T| / torque_scale))``."""

    soft_twist_arcmin: float = Field(0.15, ge=0)
    torque_scale_Nm: float = Field(2.0, gt=0)


class RunoutConfig(_Effect):
    """Radial runout (seed 000 eq. 4): None takes the unit's ``runout_*_mm``."""

    internal_mm: float | None = Field(None, ge=0)
    external_mm: float | None = Field(None, ge=0)
    beta_deg: float = 0.0
    internal_phase_deg: float = 0.0


class BearingClearanceConfig(_Effect):
    """Bearing radial clearance: extra play, then a soft stage in series with the mesh."""

    clearance_mm: list[float] | None = None
    soft_stiffness_Nm_per_arcmin: float = Field(5.0, gt=0)
    soft_stage_torque_Nm: float = Field(1.0, ge=0)

    @field_validator("clearance_mm")
    @classmethod
    def _non_negative(cls, value: list[float] | None) -> list[float] | None:
        if value is not None and any(not (v >= 0 and math.isfinite(v)) for v in value):
            raise ValueError("clearances must be finite numbers >= 0 (mm)")
        return value


class ThermalExpansionConfig(_Effect):
    """Circumferential play changing linearly with the housing temperature."""

    coefficient_um_per_K: float = 0.25
    reference_C: float = 20.0


class TorqueSensorOffsetConfig(_Effect):
    """A constant offset on the torque channel (N*m)."""

    offset_Nm: float = 0.15


class ShaftComplianceConfig(_Effect):
    """A linear compliance of shafts and couplings in series with the mesh."""

    stiffness_Nm_per_arcmin: float = Field(60.0, gt=0)


class ToothSpacingErrorConfig(_Effect):
    """Tooth-to-tooth thickness (play) and pitch (flank position) deviations, um on the
    reference circle; random (rms, seed) unless explicit per-tooth lists are given."""

    thickness_error_um_rms: float = Field(2.0, ge=0)
    pitch_error_um_rms: float = Field(3.0, ge=0)
    seed: int = 7
    transition_fraction: float = Field(0.0, ge=0, le=1)
    """Share of each tooth pitch over which the load passes linearly to the next tooth pair
    (the double contact of a contact ratio above 1); 0: a step at the pitch boundary."""
    thickness_internal_um: list[float] | None = None
    thickness_external_um: list[float] | None = None
    pitch_internal_um: list[float] | None = None
    pitch_external_um: list[float] | None = None


class KinematicErrorConfig(_Effect):
    """The unit's kinematic (transmission) error from the eccentricities of seed 000
    eq. (4): the tangential part of the ring's |AO1| and the pinion's |BO2| (um; None takes
    the unit's ``runout_*_mm / 2``, eq. 7's de = F_r / 2), with their phases (deg)."""

    internal_um: float | None = Field(None, ge=0)
    external_um: float | None = Field(None, ge=0)
    internal_phase_deg: float = 0.0
    beta_deg: float = 0.0


class CreepConfig(_Effect):
    """Out of vocabulary: viscoelastic creep (Kelvin element in series) during dwell."""

    stiffness_Nm_per_arcmin: float = Field(400.0, gt=0)
    time_constant_s: float = Field(3.0, gt=0)


class DirectionGainConfig(_Effect):
    """Out of vocabulary: the torque channel's gain depends on the torque's sign."""

    gain_positive: float = Field(1.0, gt=0)
    gain_negative: float = Field(0.97, gt=0)


class EffectsConfig(_Strict):
    """Every switchable effect; each has ``enabled`` and its physical parameters."""

    friction: FrictionConfig = FrictionConfig()
    stiffness_nonlinearity: StiffnessNonlinearityConfig = StiffnessNonlinearityConfig()
    runout: RunoutConfig = RunoutConfig()
    bearing_clearance: BearingClearanceConfig = BearingClearanceConfig()
    thermal_expansion: ThermalExpansionConfig = ThermalExpansionConfig()
    torque_sensor_offset: TorqueSensorOffsetConfig = TorqueSensorOffsetConfig()
    shaft_compliance: ShaftComplianceConfig = ShaftComplianceConfig()
    tooth_spacing_error: ToothSpacingErrorConfig = ToothSpacingErrorConfig()
    kinematic_error: KinematicErrorConfig = KinematicErrorConfig()
    creep: CreepConfig = CreepConfig()
    direction_gain: DirectionGainConfig = DirectionGainConfig()

    def enabled_names(self) -> list[str]:
        """Names of the effects switched on, in EFFECT_NAMES order."""
        return [name for name in EFFECT_NAMES if getattr(self, name).enabled]


class CycloidConfig(_Strict):
    """A ``cycloid`` unit (seed 002) as made and assembled, against its design in ``[unit]``:
    every value here is a deviation the plant injects (0: as designed)."""

    eccentricity_error_um: float = 0.0
    """Crank eccentricity minus the design e (um): the center distance O1O2 of eq. (6)."""
    shift_error_mm: float = 0.0
    """As-made offset (shift, 移距) modification minus the unit's Delta1 (mm), eqs. (9)-(10)."""
    rotation_error_mm: float = 0.0
    """As-made rotation (转角) modification minus the unit's Delta2 (mm), eqs. (11)-(12)."""
    equidistant_modification_mm: float = Field(0.0, ge=0)
    """Equidistant (等距) modification of gear 1 (mm): each flank ground back this far along
    its normal (the third modification seed 002 names)."""
    mesh_phases: int = Field(6, ge=2, le=64)
    """Mesh phases over one tooth pitch of gear 2 the assembled pair is solved at."""


class BeveloidConfig(_Strict):
    """A ``beveloid`` unit (seed 001) as installed: seed 001 eq. (8)'s installation errors of
    the gear (0: the standard installation)."""

    axial_shift_error_mm: float = 0.0
    """dz of eq. (8): the gear's axial position error (mm), + towards the pinion's thick end."""
    center_distance_error_mm: float = 0.0
    """dx of eq. (8): center distance error along the line of centres (mm)."""
    lateral_offset_mm: float = 0.0
    """dy of eq. (8): offset of the gear axis across the line of centres (mm)."""
    shaft_angle_horizontal_deg: float = 0.0
    """dl_h of eq. (8): gear axis turned about the line of centres (crossed axes), deg."""
    shaft_angle_vertical_deg: float = 0.0
    """dl_v of eq. (8): gear axis turned in the plane of the axes (intersecting), deg."""
    te_points_per_cycle: int = Field(8, ge=4, le=24)
    """Points per mesh cycle of the eq. (11) transmission error (TCA)."""


class PlanetaryConfig(_Strict):
    """A ``planetary`` unit (seed 003's paper train) as made: one unit's error values and
    initial phases by seed 003 source name (``E_s_I``: machining eccentricity of the stage I
    sun, ``A_c_III``, ``f_p_II``, ...; :func:`analysis.models.seed003_planetary.error_sources`).
    A source left out is 0. ``simulators.plant.planetary.draw_unit`` draws a unit."""

    errors_um: dict[str, float] = Field(default_factory=dict)
    """Eccentricities (E, A: magnitudes >= 0) and tooth errors (f: signed), um."""
    phases_deg: dict[str, float] = Field(default_factory=dict)
    """Initial phases of the eccentricities (eq. 12), deg; tooth errors have none."""


class NoiseConfig(_Strict):
    """Sensor noise: Gaussian, seeded (same seed and calls -> same numbers)."""

    twist_arcsec_rms: float = Field(0.3, ge=0)
    torque_Nm_rms: float = Field(0.005, ge=0)
    seed: int = 1


class PlantConfig(_Strict):
    """Everything the plant needs: the unit (run.json ``unit``), the rig, housing, effects,
    noise. ``source`` names where it came from (for error messages)."""

    unit: dict[str, Any]
    rig: RigConfig = RigConfig()
    housing: HousingConfig = HousingConfig()
    effects: EffectsConfig = EffectsConfig()
    noise: NoiseConfig = NoiseConfig()
    measurement: MeasurementConfig = MeasurementConfig()
    cycloid: CycloidConfig = CycloidConfig()
    beveloid: BeveloidConfig = BeveloidConfig()
    planetary: PlanetaryConfig = PlanetaryConfig()
    source: str = "<memory>"

    def nominal(self) -> PlantConfig:
        """A copy with every effect off and no noise: the reference nominal loop only."""
        effects = self.effects.model_copy(
            update={name: getattr(self.effects, name).model_copy(update={"enabled": False})
                    for name in EFFECT_NAMES}
        )
        noise = self.noise.model_copy(update={"twist_arcsec_rms": 0.0, "torque_Nm_rms": 0.0})
        return self.model_copy(update={
            "effects": effects, "noise": noise,
            "cycloid": CycloidConfig(mesh_phases=self.cycloid.mesh_phases),
            "beveloid": BeveloidConfig(te_points_per_cycle=self.beveloid.te_points_per_cycle),
            "planetary": PlanetaryConfig()})

    def with_effect(self, name: str, enabled: bool = True, **params: Any) -> PlantConfig:
        """A copy with effect ``name`` switched (and any of its parameters replaced)."""
        if name not in EFFECT_NAMES:
            raise PlantConfigError(
                f"{self.source}: no effect named {name!r}; known: {', '.join(EFFECT_NAMES)}"
            )
        current = getattr(self.effects, name)
        try:
            updated = type(current).model_validate(
                {**current.model_dump(), **params, "enabled": enabled}
            )
        except ValidationError as exc:
            raise PlantConfigError(_describe(exc, self.source, prefix=f"effects.{name}")) from exc
        return self.model_copy(
            update={"effects": self.effects.model_copy(update={name: updated})}
        )

    def with_changes(self, **sections: dict[str, Any]) -> PlantConfig:
        """A copy with keys of ``rig``/``housing``/``noise``/``measurement``/``unit``/
        ``cycloid``/``beveloid``/``planetary`` replaced, validated."""
        data = self.model_dump()
        for section, values in sections.items():
            if section not in ("rig", "housing", "noise", "unit", "measurement", "cycloid",
                               "beveloid", "planetary"):
                raise PlantConfigError(f"{self.source}: cannot change section {section!r}")
            data[section] = {**data[section], **values}
        return plant_config_from_mapping(data, self.source)


def _describe(exc: ValidationError, source: str, prefix: str = "") -> str:
    lines = []
    for err in exc.errors():
        key = ".".join(str(p) for p in err["loc"])
        if prefix:
            key = f"{prefix}.{key}" if key else prefix
        got = err.get("input")
        lines.append(f"{source}: key {key}: {err['msg']} (got {got!r})")
    return "\n".join(lines)


def plant_config_from_mapping(data: dict[str, Any], source: str = "<memory>") -> PlantConfig:
    """Validate a mapping (a parsed TOML) into a PlantConfig; errors name ``source`` and key."""
    if "unit" not in data:
        raise PlantConfigError(f"{source}: key unit: missing (the run.json unit table)")
    try:
        config = PlantConfig.model_validate({**data, "source": source})
    except ValidationError as exc:
        raise PlantConfigError(_describe(exc, source)) from exc
    # The unit table is checked by the geometry (it names unit.<key> on error).
    from simulators.plant.kinds import geometry_for

    try:
        geometry_for(config)
    except ValueError as exc:
        raise PlantConfigError(f"{source}: {exc}") from exc
    return config


def load_plant_config(path: str | Path | None = None) -> PlantConfig:
    """Read and validate a plant TOML; ``None`` reads simulators/default_plant.toml.

    Raises PlantConfigError naming the file and the line/column (syntax) or key (values).
    """
    file = Path(path) if path is not None else DEFAULT_PLANT_TOML
    try:
        text = file.read_text(encoding="utf-8")
    except OSError as exc:
        raise PlantConfigError(f"{file}: cannot read plant config ({exc.strerror})") from exc
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise PlantConfigError(f"{file}: TOML syntax error: {exc}") from exc
    return plant_config_from_mapping(data, str(file))
