"""Plant geometry of a ``planetary`` unit: seed 003's three-stage 2K-H train, one drawn unit.

The train is the paper's (:func:`analysis.models.seed003_planetary.paper_train`, Table 2:
stages I and II z = 12/36/84, stage III 21/31/84, module 1 mm, 20 deg; ratios 8 * 8 * 5 =
320): the stage I sun is the input, the stage III carrier the output, the rings are fixed.
The output turns **with** the input: ``output_angle_deg = offset + input_angle_deg / 320 +
twist`` (the plant's ratio is ``-320`` in its "output turns against the input" convention; the
run's signed ``test.ratio`` is ``+320``).

Transmission error (the TE test). The unit's errors are the paper's error sources
(:func:`analysis.models.seed003_planetary.error_sources`, Table 1 and eqs. 1-3, 7, 11), each
with one value ``v`` (um) and, for the eccentricities, one initial phase ``p`` (eq. 12) taken
from ``[planetary]`` (one unit drawn by :func:`draw_unit`, every value recorded). With the
output carrier angle ``psi = input_angle_deg / 320`` (rad; 0 where the input reads 0, not
moved by the output encoder's offset) the output's kinematic error is seed 003 eq. (11),

    dtheta(psi) = sum_s v_s Im(W_s exp(i (nu_s psi + p_s)))   (arcsec),

``W_s`` (arcsec/um) and ``nu_s`` (cycles per output revolution) the source's weight and
frequency (eqs. 1, 7, 10, 11). It shifts both flanks of the output (the plant's
``pitch_offset``), so the measured TE under a brake torque is ``dtheta`` plus a constant. Tooth
errors ``f`` (pitch, profile, thickness; eqs. 2-3) and the stage III planets' installation
eccentricity (frequency 0) are constants on the line of action in seed 003: they move the whole
curve, which the TE's mean ``c_d`` takes away, and so never change the peak-to-peak.

Loop test (simple, seed 003 has no play or stiffness model). Each stage ``j`` has a
circumferential backlash ``j_t`` (um, ``unit.backlash_um[j]``) on both of its meshes; a planet
between the held sun and the fixed ring lets its carrier turn ``j_t / a_j`` rad (``a_j =
m (z_s + z_p) / 2`` the carrier radius: the planet centre moves by the mean of its two meshes'
backlash). The stages' mesh stiffnesses are seed 004 eq. (8) single pair stiffnesses times
``unit.face_width_mm``, the sun-planet and planet-ring meshes in series per planet, ``n_p =
unit.planets`` planets in parallel: ``K_j = 4 n_p a_j^2 cos^2(alpha) / (1/k_sp + 1/k_pr)``
(N*m/rad). At the output, as eq. (11) adds the stages' angle errors, a stage's play is divided
by its carrier-to-output ratio ``i_jm`` and its compliance by ``i_jm^2``:

    play = sum_j j_t,j / (1000 a_j i_jm)  (rad),   1 / K = sum_j 1 / (K_j i_jm^2).

Plays in um are on the output carrier's radius ``a_III`` (26 mm): ``arcmin = 3437.75 j /
(1000 a_III)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from analysis.models.mesh_stiffness import single_pair_stiffness_N_per_mm_um
from analysis.models.seed003_montecarlo import draw_phases_rad, draw_values_um
from analysis.models.seed003_planetary import ErrorSource, error_sources, paper_train
from simulators.plant.geometry import (
    ARCMIN_PER_RAD,
    MeshGeometry,
    NominalMesh,
    UnitAndEffects,
    UnitView,
)

ARCSEC_PER_RAD = ARCMIN_PER_RAD * 60.0
NOT_MODELLED_EFFECTS = ("runout", "kinematic_error", "tooth_spacing_error")
"""Effects of the involute pair that seed 003's sources already are for a planetary unit."""


def paper_sources() -> tuple[ErrorSource, ...]:
    """Seed 003's error sources of the paper train (Table 1, eqs. 1-3, 7, 11), in order."""
    return error_sources(paper_train())


def draw_unit(seed: int, scale: float = 1.0) -> dict[str, dict[str, float]]:
    """One unit of the paper train drawn as seed 003's Monte Carlo draws a sample: values by
    eqs. (15)-(17) (Rayleigh truncated at T for eccentricities, normal truncated at +-T/2 for
    tooth errors) and phases by eq. (12), from ``numpy.random.default_rng(seed)``; every value
    times ``scale`` (``scale > 1``: a unit made outside the tolerances). Returns the
    ``[planetary]`` tables ``errors_um`` (um) and ``phases_deg`` (deg, eccentricities only)."""
    sources = paper_sources()
    rng = np.random.default_rng(seed)
    values = draw_values_um(sources, 1, rng)[0] * float(scale)
    phases = np.degrees(draw_phases_rad(1, len(sources), rng)[0])
    return {"errors_um": {s.name: round(float(v), 3) for s, v in zip(sources, values,
                                                                        strict=True)},
            "phases_deg": {s.name: round(float(p), 2) for s, p in zip(sources, phases,
                                                                       strict=True)
                           if s.has_phase}}


@dataclass(frozen=True)
class PlanetaryGeometry(MeshGeometry):
    """Seed 003's paper train on the rig, one unit (see the module docstring)."""

    train_ratio: float = 320.0
    r_ref_mm: float = 26.0
    source_names: tuple[str, ...] = ()
    frequencies: np.ndarray | None = None
    phasors: np.ndarray | None = None
    """Per source ``v W exp(i p)`` (arcsec; ``v W`` for a tooth error)."""
    injected: dict[str, Any] | None = None

    @classmethod
    def from_config(cls, config: UnitAndEffects) -> PlanetaryGeometry:
        """Build from a PlantConfig with a ``kind = "planetary"`` unit and its ``[planetary]``
        table (ValueError names the key)."""
        u = UnitView(config.unit)
        train = paper_train()
        stages = train.stages
        ratio = u.num("ratio", train.total_ratio)
        if abs(ratio - train.total_ratio) > 1e-9:
            raise ValueError(f"key unit.ratio: the seed 003 paper train is "
                             f"{train.total_ratio:g}, got {ratio:g}")
        face = u.num("face_width_mm")
        if face <= 0:
            raise ValueError("key unit.face_width_mm: expected > 0")
        planets = u.int_("planets") if "planets" in config.unit else 3
        backlash = u.nums("backlash_um")
        if len(backlash) != len(stages) or any(b < 0 for b in backlash):
            raise ValueError(f"key unit.backlash_um: expected {len(stages)} values >= 0 (um, "
                             f"stages {', '.join(s.name for s in stages)}), got {backlash}")
        for name in NOT_MODELLED_EFFECTS:
            if getattr(config.effects, name).enabled:
                raise ValueError(f"key effects.{name}.enabled: not for a planetary unit (its "
                                 "eccentricities and tooth errors are the [planetary] table)")
        play_rad, compliance = 0.0, 0.0
        for index, (stage, j_t) in enumerate(zip(stages, backlash, strict=True)):
            i_jm = train.carrier_to_output_ratio(index)
            a_mm = stage.module_mm * (stage.z_sun + stage.z_planet) / 2.0
            cos_a = math.cos(math.radians(stage.pressure_angle_ext_deg))
            k_sp = face * single_pair_stiffness_N_per_mm_um(stage.z_planet, stage.z_sun) * 1e6
            k_pr = face * single_pair_stiffness_N_per_mm_um(stage.z_ring, stage.z_planet) * 1e6
            k_stage = 4.0 * planets * (a_mm / 1000.0) ** 2 * cos_a**2 / (1.0 / k_sp + 1.0 / k_pr)
            play_rad += j_t / (1000.0 * a_mm * i_jm)
            compliance += 1.0 / (k_stage * i_jm**2)
        last = stages[-1]
        r_ref = last.module_mm * (last.z_sun + last.z_planet) / 2.0
        k_mesh = face * single_pair_stiffness_N_per_mm_um(last.z_ring, last.z_planet)
        nominal = NominalMesh(
            play_um=play_rad * 1000.0 * r_ref, play_arcmin=play_rad * ARCMIN_PER_RAD,
            mesh_stiffness_N_per_um=k_mesh,
            stiffness_Nm_per_arcmin=1.0 / (compliance * ARCMIN_PER_RAD),
            contact_ratio=1.0, working_pressure_angle_deg=last.pressure_angle_ext_deg)
        names, freqs, phasors, table = _unit_sources(config)
        injected = {
            "train": "seed 003 paper train (Table 2), analysis.models.seed003_planetary",
            "ratio": train.total_ratio, "sources": table,
            "backlash_um": backlash, "planets": planets, "face_width_mm": face,
            "psi": "output carrier angle = input_angle_deg / ratio (rad)",
        }
        return cls.build(
            config, nominal, last.z_ring, last.z_planet, last.module_mm,
            math.tan(math.radians(last.pressure_angle_ext_deg)), r_ref, kind="planetary",
            train_ratio=train.total_ratio, r_ref_mm=r_ref, source_names=names,
            frequencies=freqs, phasors=phasors, injected=injected)

    # -- overrides -----------------------------------------------------------------------
    @property
    def ratio(self) -> float:
        """``-320``: input turns per output turn, negative as the output turns with the input
        (GearPlant's ``output = offset - input / ratio``)."""
        return -self.train_ratio

    def arcmin_from_um(self, j_t_um: float) -> float:
        """Circumferential play (um on the output carrier radius) -> output angle (arcmin)."""
        return ARCMIN_PER_RAD * j_t_um / (1000.0 * self.r_ref_mm)

    def te_arcsec(self, input_angle_deg: np.ndarray | float) -> np.ndarray:
        """Seed 003 eq. (11) at the output (arcsec): ``sum_s Im(Z_s exp(i nu_s psi))`` with
        ``Z_s = v_s W_s exp(i p_s)`` and ``psi = input_angle_deg / 320`` (rad)."""
        psi = np.radians(np.asarray(input_angle_deg, dtype=float)) / self.train_ratio
        assert self.frequencies is not None and self.phasors is not None
        rot = np.exp(1j * np.multiply.outer(psi, self.frequencies))
        return (rot * self.phasors).imag.sum(axis=-1)

    def pitch_offset_um(self, input_angle_deg: float) -> float:
        """Both flanks shifted by the train's kinematic error (:meth:`te_arcsec`), as um on
        the output carrier radius."""
        te = float(self.te_arcsec(input_angle_deg))
        return te / ARCSEC_PER_RAD * 1000.0 * self.r_ref_mm

    def order_lines(self, output_offset_deg: float = 0.0) -> list[dict[str, Any]]:
        """The TE's lines by frequency (the sources of one frequency summed):
        ``A cos(nu theta_out + phase)`` with ``theta_out`` the output encoder's angle (rad,
        ``psi + offset``), as :mod:`analysis.transmission.orders` fits them; frequency 0 left
        out (a constant)."""
        assert self.frequencies is not None and self.phasors is not None
        lines: dict[float, complex] = {}
        for f, z in zip(self.frequencies, self.phasors, strict=True):
            if f:
                # Im(Z e^{i f psi}) with f < 0 is Im(-conj(Z) e^{i |f| psi})
                key, zz = (float(f), complex(z)) if f > 0 else (float(-f), -complex(z).conjugate())
                lines[key] = lines.get(key, 0j) + zz
        out = []
        for f, z in sorted(lines.items()):
            phase = math.degrees(math.atan2(z.imag, z.real)) - 90.0 - f * output_offset_deg
            out.append({"frequency_per_output_rev": f, "amplitude_arcsec": abs(z),
                        "phase_deg": (phase + 180.0) % 360.0 - 180.0})
        return out

    def kind_truth(self, input_angle_deg: float) -> dict[str, Any]:
        return {
            "kind": "planetary",
            "output_carrier_angle_deg": input_angle_deg / self.train_ratio,
            "te_arcsec": float(self.te_arcsec(input_angle_deg)),
            "pitch_radius_output_mm": self.r_ref_mm,
            "injected": dict(self.injected or {}),
        }


def _unit_sources(config: UnitAndEffects) -> tuple[tuple[str, ...], np.ndarray, np.ndarray,
                                                    dict[str, dict[str, Any]]]:
    """Names, frequencies (per output rev), phasors ``v W e^{ip}`` (arcsec) and the recorded
    table (value, phase, bound, frequency, weight) of the unit's ``[planetary]`` errors."""
    sources = paper_sources()
    known = {s.name: s for s in sources}
    pl = config.planetary  # type: ignore[attr-defined]
    for table, values in (("errors_um", pl.errors_um), ("phases_deg", pl.phases_deg)):
        for name in values:
            if name not in known:
                raise ValueError(f"key planetary.{table}.{name}: no such seed 003 source "
                                 f"(known: {', '.join(known)})")
    for name in pl.phases_deg:
        if not known[name].has_phase:
            raise ValueError(f"key planetary.phases_deg.{name}: a tooth error has no phase "
                             "(seed 003 eqs. 2-3)")
    names, freqs, phasors, table = [], [], [], {}
    for s in sources:
        v = float(pl.errors_um.get(s.name, 0.0))
        if s.has_phase and v < 0:
            raise ValueError(f"key planetary.errors_um.{s.name}: an eccentricity is a "
                             f"magnitude >= 0 um, got {v}")
        p = float(pl.phases_deg.get(s.name, 0.0)) if s.has_phase else None
        z = v * s.weight * (complex(math.cos(math.radians(p)), math.sin(math.radians(p)))
                            if p is not None else 1.0)
        names.append(s.name)
        freqs.append(s.frequency_per_rev)
        phasors.append(z)
        table[s.name] = {"value_um": v, "phase_deg": p, "bound_um": s.bound_um,
                         "times_bound": v / s.bound_um if s.bound_um else None,
                         "frequency_per_output_rev": s.frequency_per_rev,
                         "weight_arcsec_per_um": [s.weight.real, s.weight.imag],
                         "description": s.description}
    return tuple(names), np.array(freqs), np.array(phasors), table


def planetary_true_transmission_error(geo: PlanetaryGeometry, *, play_rad: float,
                                      elastic_rad: float, start_input_deg: float,
                                      output_offset_deg: float, brake_torque_Nm: float,
                                      points_per_output_rev: int = 8192,
                                      output_window_deg: tuple[float, float] | None = None,
                                      ) -> dict[str, Any]:
    """Quasi-static truth of a TE run of a planetary unit (the planetary branch of
    :meth:`simulators.plant.GearPlant.true_transmission_error`).

    The output turns with the input, so a forward turn (input +) meets a brake torque pushing
    the output negative: it rides the ``-1`` flank, twist ``dtheta(psi) - (play / 2 + h(T))``;
    reverse rides ``+1``. ``dtheta`` is seed 003 eq. (11) (:meth:`PlanetaryGeometry.te_arcsec`).
    Over one output revolution from ``start_input_deg`` (forward up, reverse down), or over the
    absolute output angles ``output_window_deg = (lo, hi)`` (deg of the output encoder, e.g. the
    revolution a TE analysis used: its curves' ``span_deg``). Same keys as the seed 000
    truth; ``te_orders`` are the seed 003 lines by frequency (:meth:`order_lines`), ``injected``
    every source's value and phase."""
    i = geo.train_ratio
    n = int(points_per_output_rev)
    if n < 16:
        raise ValueError(f"points_per_output_rev must be >= 16, got {points_per_output_rev!r}")
    flank = play_rad / 2.0 + elastic_rad
    out: dict[str, Any] = {}
    means = {}
    for name, d in (("forward", 1.0), ("reverse", -1.0)):
        if output_window_deg is not None:
            lo, hi = (float(v) for v in output_window_deg)
            if not hi > lo:
                raise ValueError(f"output_window_deg must be (lo, hi) with hi > lo, got "
                                 f"{output_window_deg!r}")
            theta = (lo - output_offset_deg + (hi - lo) * np.arange(n) / n) * i
            if d < 0:
                theta = theta[::-1]
        else:
            theta = start_input_deg + d * 360.0 * i * np.arange(n) / n
        te = geo.te_arcsec(theta) - d * flank * ARCSEC_PER_RAD
        means[name] = float(te.mean())
        te = te - te.mean()
        out[name] = {"input_angle_deg": theta, "output_angle_deg": output_offset_deg + theta / i,
                     "te_arcsec": te, "pp_arcsec": float(np.ptp(te))}
    out["te_pp_forward_arcsec"] = out["forward"]["pp_arcsec"]
    out["te_pp_reverse_arcsec"] = out["reverse"]["pp_arcsec"]
    out["te_pp_arcsec"] = max(out["te_pp_forward_arcsec"], out["te_pp_reverse_arcsec"])
    out["te_hysteresis_arcmin"] = abs(means["forward"] - means["reverse"]) / 60.0
    out["te_orders"] = geo.order_lines(output_offset_deg)
    out["injected"] = {**(geo.injected or {}), "brake_torque_Nm": abs(brake_torque_Nm),
                       "play_arcmin": play_rad * ARCMIN_PER_RAD,
                       "elastic_twist_arcmin": elastic_rad * ARCMIN_PER_RAD}
    return out
