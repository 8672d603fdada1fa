"""Proof on withheld effects: campaigns from our own generator, diagnosed blind.

The generator (this module) makes each case a campaign of one unit (varied unit data) with
the time-domain plant (simulators/) and one effect switched on, none (null cases), or one
outside the vocabulary (creep, direction-dependent torque gain, a parallel spring). Widened
(issue 10) so that it is not one simulator's forms:

- more than one functional form per effect (:data:`FORMS`): friction Coulomb, Dahl or
  Stribeck-like (LuGre); stiffening exponential (still hardening at rated) or a Hertzian
  power law; runout once (eq. 4 eccentricities) or twice per revolution; bearing clearance as
  a two-stage stiffness or a smooth take-up; thermal play linear or quadratic in temperature;
  torque offset on the reading, or with the drive regulating on the offset reading; tooth
  spacing as tooth-to-tooth thickness and pitch scatter or a smooth thickness pattern of
  order 2-4 around each gear; and (issue 31 item 8) the forms a real unit shows that the
  candidates do not fit exactly: runout with an ovality on top (orders 1 and 2 of a crank
  turn), a thermal play that follows the mesh temperature lagging the housing sensor, a
  torque offset that also drifts during each run, a stiffness only 3-8 % below the model's,
  and out of the vocabulary a spring in parallel with the gear;
- loading profiles (:data:`LOADINGS`): stepped with dwells, constant-rate ramps, sinusoid;
- sensor artifacts: a coarse encoder (2^19..2^23 counts per revolution), a lag of the torque
  channel behind the angles, ringing after the impact at the play crossing
  (simulators/offline_forms.py).

With ``artifacts`` (issue 20, the default of ``rig validate-diagnosis``) every case is instead
measured through a real rig's measuring system (simulators/offline_rig.py): impacts with
bounces at the play crossing (a contact oscillator), the torque sensor's first-order lag on an
ADC grid, the drive's integral torque loop, a re-tared zero that random-walks, drive torque
ripple, a small Coulomb friction in every unit, encoders of 2^19..2^23 counts, 100-1000 Hz
sampling with timestamp jitter and dropped rows, loading with pre-cycles and runs that start
loading the negative flank. None of them is an effect of the unit. Their sizes are drawn from
a stream of their own (``default_rng([seed, index, ARTIFACT_STREAM])``), so a case's effect is
the same with and without them.

The case's label and true parameters are kept in :class:`Case` and written to run.json only
under ``generator`` (never read by the diagnosis); the diagnosis sees the campaign through
:func:`rig.results.diagnose.run_input` exactly as ``rig diagnose`` does. :func:`make_case` with
``widened=False`` draws the stepped plant-form cases of before (single-case tests use them).

Expected verdict: the effect itself, except ``shaft_compliance``, which one loop cannot tell
from the mesh stiffness (``ambiguous`` naming it also counts), and the out-of-vocabulary
kinds (``unexplained`` or ``ambiguous``). The same grading as for labelled folders
(:mod:`rig.validate.labels`) gives the per-generator summary (:func:`graded_validation`).
"""

from __future__ import annotations

import json
import math
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np

from rig.core.json_files import finite_for_json
from rig.results.diagnose import diagnose_campaign
from rig.runformat import Campaign, Run
from rig.validate.labels import Label
from simulators.offline import quantise_deg, simulate_run
from simulators.offline_forms import (
    center_distance_change_mm,
    delayed,
    drifting_zero_Nm,
    impact_ringing_arcsec,
    parallel_spring_torque_Nm,
    path_profile,
    power_law_twist_arcmin,
    ramp_profile,
    sine_profile,
    smooth_takeup_twist_arcmin,
    thermal_lag_C,
)
from simulators.offline_rig import RigArtifacts, draw_artifacts, measure_run
from simulators.plant.config import PlantConfig, load_plant_config
from simulators.plant.geometry import reference_nominal

IN_VOCABULARY = ("friction", "stiffness_nonlinearity", "runout", "bearing_clearance",
                 "thermal_expansion", "torque_sensor_offset", "shaft_compliance",
                 "tooth_spacing_error")
OUT_OF_VOCABULARY = ("creep", "direction_gain", "parallel_spring")
KINDS = (*IN_VOCABULARY, "none", *OUT_OF_VOCABULARY)
#: Functional forms the widened generator draws for each kind (the first is the plant's own).
FORMS: dict[str, tuple[str, ...]] = {
    "friction": ("coulomb", "dahl", "stribeck"),
    "stiffness_nonlinearity": ("exponential", "hertz"),
    "runout": ("1x", "2x", "ovality"),
    "bearing_clearance": ("two_stage", "smooth"),
    "thermal_expansion": ("linear", "quadratic", "lagged"),
    "torque_sensor_offset": ("reading", "regulated", "drifting"),
    "shaft_compliance": ("linear", "mild"),
    "tooth_spacing_error": ("thickness_pitch", "harmonic"),
    "none": ("-",), "creep": ("-",), "direction_gain": ("-",), "parallel_spring": ("-",),
}
#: Loading profiles: stepped with dwells, constant-rate ramps, sinusoid.
LOADINGS = ("stepped", "ramp", "sine")
#: Coarse encoders the widened generator draws from (counts per revolution).
COARSE_COUNTS = tuple(2 ** k for k in range(19, 24))

#: Inspected unit data the validation units are drawn around (seed 000 Table 2 pairs 1 and 2).
UNITS_DIR = Path(__file__).resolve().parent.parent / "examples" / "units"
UNIT_FILES = tuple(UNITS_DIR / f"seed000-pair{n}.json" for n in (1, 2))
RATE_HZ = 250.0
DURATION_S = 10.0
RATED_NM = 10.0
#: The torque sensor's full scale (N*m, bipolar) written to run.json ``sensors``.
FULL_SCALE_NM = 20.0
#: When a generated campaign's first run starts, and the time between run starts (s): the
#: thermal lag of the ``lagged`` form is in units of it.
CAMPAIGN_START = datetime(2026, 1, 5, 8, 0, tzinfo=UTC)
RUN_SPACING_S = 300.0
#: The third seed of a case's artefact stream ``default_rng([seed, index, ARTIFACT_STREAM])``.
ARTIFACT_STREAM = 20


def cycle_profile(rated_Nm: float, n: int, steps_per_quarter: int = 8,
                  ramp_share: float = 0.6) -> np.ndarray:
    """Commanded torque (N*m), one value per sample: 0 -> +T -> -T -> +T -> 0 in equal steps
    plus a step at +-3 % of rated (the lost-motion points), each a ramp (``ramp_share`` of the
    step) then a dwell; the unit starts on the -1 flank."""
    q = np.unique(np.append(np.linspace(0.0, 1.0, steps_per_quarter + 1), 0.03))
    r = q[::-1]
    levels = np.concatenate([q, r[1:], -q[1:], -r[1:], q[1:], r[1:]]) * rated_Nm
    per = n / (levels.size - 1)
    k = np.arange(n) / per
    i = np.minimum(k.astype(int), levels.size - 2)
    frac = np.clip((k - i) / ramp_share, 0.0, 1.0)
    return levels[i] + (levels[i + 1] - levels[i]) * frac


@dataclass
class Case:
    """One validation case: the label, what was switched on, and the campaign design."""

    index: int
    kind: str
    config: PlantConfig
    positions_deg: list[float]
    temperatures_C: list[float]
    truth: dict[str, Any] = field(default_factory=dict)
    #: Effects added to the plant's output outside the plant (other functional forms than the
    #: plant's own), applied by :func:`simulate_campaign`.
    post: dict[str, Any] = field(default_factory=dict)
    #: The effect's functional form (:data:`FORMS`) and the loading profile (:data:`LOADINGS`).
    form: str = "-"
    loading: str = "stepped"
    #: Sensor artifacts: torque channel lag (s), impact ringing at the play crossing
    #: (amplitude_arcsec, frequency_Hz, decay_s), none when empty.
    lag_s: float = 0.0
    impact: dict[str, float] = field(default_factory=dict)
    #: Play change per run (um) the plant gets through its center distance (not in the unit
    #: data written): a twice-per-revolution runout or a quadratic thermal play.
    play_change_um: list[float] = field(default_factory=list)
    #: The loading drive regulates on the measured torque: its command is offset by -this.
    command_offset_Nm: float = 0.0
    #: The torque reading's zero drifts linearly during each run by this much (N*m, start to
    #: end) on top of the plant's constant offset: a sensor warming up between tares.
    offset_drift_Nm: float = 0.0
    #: A real rig's measuring system (issue 20), None: the plant's columns as they are.
    artifacts: RigArtifacts | None = None
    #: Seed of the per-run draws of the measuring system (zero residual, ripple phase, ...).
    artifact_seed: int = 0

    @property
    def expected(self) -> set[str]:
        """Verdicts counted correct."""
        if self.kind == "shaft_compliance":
            return {"ambiguous", "shaft_compliance"}
        if self.kind in OUT_OF_VOCABULARY:
            return {"unexplained", "ambiguous"}
        return {self.kind}


def _unit(rng: np.random.Generator, base: dict[str, Any]) -> dict[str, Any]:
    """Unit data around seed 000 pair 1 or pair 2 (their inspected M values), with drawn face
    width, center distance, M value shifts, inspected runouts and bearing clearances."""
    pair = json.loads(UNIT_FILES[int(rng.integers(len(UNIT_FILES)))].read_text())
    base = {**base, **{k: pair[k] for k in ("m_value_internal_mm", "m_value_external_mm")}}
    unit = dict(base)
    unit["face_width_mm"] = float(round(rng.uniform(7.0, 14.0), 1))
    unit["center_distance_mm"] = float(round(2.5 + rng.uniform(-0.004, 0.002), 4))
    shift_i = rng.uniform(-0.015, 0.015)
    shift_e = rng.uniform(-0.015, 0.015)
    unit["m_value_internal_mm"] = [round(v + shift_i, 3) for v in base["m_value_internal_mm"]]
    unit["m_value_external_mm"] = [round(v + shift_e, 3) for v in base["m_value_external_mm"]]
    unit["runout_internal_mm"] = float(round(rng.uniform(0.01, 0.03), 3))
    unit["runout_external_mm"] = float(round(rng.uniform(0.008, 0.025), 3))
    unit["bearing_clearance_mm"] = [float(round(rng.uniform(0.003, 0.008), 3)) for _ in range(2)]
    return unit


def draw_runout(rng: np.random.Generator, config: PlantConfig
                ) -> tuple[dict[str, Any], PlantConfig]:
    """A runout effect's truth (true F_r of both members, mm, and the phases, deg) and the
    unit data the lab inspected: within +-25 % of the true F_r (at least 0.005 mm)."""
    truth = {"internal_mm": float(rng.uniform(0.012, 0.035)),
             "external_mm": float(rng.uniform(0.0, 0.03)),
             "beta_deg": float(rng.uniform(-180, 180)),
             "internal_phase_deg": float(rng.uniform(-180, 180))}
    config = config.with_changes(unit={
        "runout_internal_mm": round(max(truth["internal_mm"] * rng.uniform(0.8, 1.25),
                                        0.005), 3),
        "runout_external_mm": round(max(truth["external_mm"] * rng.uniform(0.8, 1.25),
                                        0.005), 3)})
    return truth, config


def make_case(index: int, kind: str, rng: np.random.Generator,
              base: PlantConfig | None = None, widened: bool = False,
              artifacts_rng: np.random.Generator | None = None) -> Case:
    """Draw a case of ``kind`` (an effect, 'none', 'creep' or 'direction_gain'); ``widened``:
    then draw the form, loading profile and sensor artifacts too (:func:`widen`);
    ``artifacts_rng``: then measure it through a real rig's measuring system, its sizes drawn
    from this stream (:func:`with_artifacts`)."""
    base = base or load_plant_config()
    for _ in range(20):
        unit = _unit(rng, base.unit)
        try:
            config = base.nominal().with_changes(unit=unit)
            break
        except ValueError:
            continue
    noise = {"twist_arcsec_rms": float(rng.uniform(0.1, 0.8)),
             "torque_Nm_rms": float(rng.uniform(0.001, 0.01)), "seed": int(rng.integers(1e9))}
    config = config.with_changes(noise=noise)
    start = float(rng.uniform(0, 360))
    positions = [round(start + k * 45.0, 1) for k in range(8)]
    temps = [20.0] * 8
    truth: dict[str, Any] = {}
    post: dict[str, Any] = {}
    if kind == "friction":
        law = str(rng.choice(["coulomb", "dahl", "lugre"]))
        truth = {"coulomb_torque_Nm": float(rng.uniform(0.25, 0.8)),
                 "model": "lugre" if law == "lugre" else "dahl", "law": law,
                 # a very stiff bristle is the Coulomb stop; a soft one a smooth Dahl curve
                 "rest_stiffness_Nm_per_arcmin": 3000.0 if law == "coulomb"
                 else float(rng.uniform(80.0, 600.0))}
        truth["static_torque_Nm"] = truth["coulomb_torque_Nm"] * float(rng.uniform(1.0, 1.3))
        if law == "lugre":
            truth["stribeck_velocity_arcmin_per_s"] = float(rng.uniform(1.0, 10.0))
    elif kind == "stiffness_nonlinearity" and rng.random() < 0.5:
        # another stiffening curve than the plant's: a Hertz-like power law (see _power_law)
        post = {"stiffening_power_law": {
            "twist_at_rated_arcmin": float(rng.uniform(0.2, 0.5)),
            "exponent": float(rng.uniform(0.4, 0.67))}}
    elif kind == "stiffness_nonlinearity":
        truth = {"soft_twist_arcmin": float(rng.uniform(0.12, 0.4)),
                 "torque_scale_Nm": float(rng.uniform(0.6, 2.5))}
    elif kind == "runout":
        truth, config = draw_runout(rng, config)
    elif kind == "bearing_clearance":
        truth = {"soft_stiffness_Nm_per_arcmin": float(rng.uniform(3.0, 9.0)),
                 "soft_stage_torque_Nm": float(rng.uniform(0.6, 2.0))}
    elif kind == "thermal_expansion":
        truth = {"coefficient_um_per_K": float(rng.choice([-1, 1]) * rng.uniform(0.2, 0.6)),
                 "reference_C": 20.0}
        p0 = positions[0]
        positions = [p0] * 8
        temps = [t for t in (12.0, 24.0, 36.0, 48.0) for _ in range(2)]
    elif kind == "torque_sensor_offset":
        truth = {"offset_Nm": float(rng.choice([-1, 1]) * rng.uniform(0.06, 0.3))}
    elif kind == "shaft_compliance":
        truth = {"stiffness_Nm_per_arcmin": float(rng.uniform(30.0, 120.0))}
    elif kind == "tooth_spacing_error":
        truth = {"thickness_error_um_rms": float(rng.uniform(2.0, 5.0)),
                 "pitch_error_um_rms": float(rng.uniform(0.0, 4.0)),
                 "seed": int(rng.integers(1e6))}
        teeth = [round(start + k * 360.0 / 45.0 * 3 + 4.0, 1) for k in range(6)]
        positions = [p for p in teeth for _ in range(2)]
        temps = [20.0] * len(positions)
    elif kind == "creep":
        truth = {"stiffness_Nm_per_arcmin": float(rng.uniform(40.0, 120.0)),
                 "time_constant_s": float(rng.uniform(0.15, 0.6))}
    elif kind == "direction_gain":
        truth = {"gain_positive": 1.0, "gain_negative": float(rng.uniform(0.6, 0.8))}
    elif kind == "parallel_spring":
        # a spring beside the gear (a cable carrier, a seal, a fixture bearing preloaded on the
        # output) carries torque inside the free play: 1-4 % of the mesh stiffness
        share = float(rng.uniform(0.01, 0.04))
        k_mesh = reference_nominal(config.unit).stiffness_Nm_per_arcmin
        post = {"parallel_spring": {"stiffness_Nm_per_arcmin": share * k_mesh}}
        truth = {**post["parallel_spring"], "share_of_mesh_stiffness": share}
    elif kind != "none":
        raise ValueError(f"unknown case kind {kind!r}; known: {', '.join(KINDS)}")
    if kind not in ("none", "parallel_spring") and not post:
        config = config.with_effect(kind, **{k: v for k, v in truth.items() if k != "law"})
    case = Case(index, kind, config, positions, temps, truth or dict(post), post,
                form=_classic_form(kind, truth, post))
    case = widen(case, rng) if widened else case
    return with_artifacts(case, artifacts_rng) if artifacts_rng is not None else case


def with_artifacts(case: Case, rng: np.random.Generator) -> Case:
    """The case measured through a real rig (simulators/offline_rig.py): the artefact sizes
    drawn from ``rng`` (:func:`simulators.offline_rig.draw_artifacts`), its encoder, no
    pure channel delay nor fixed ringing (the sensor's lag and the contact oscillator's
    impacts replace them). The truth under ``generator`` gains ``measuring_system``."""
    art = draw_artifacts(rng, RATED_NM, FULL_SCALE_NM)
    config = case.config.with_changes(rig={"encoder_counts_per_rev": art.encoder_counts_per_rev})
    truth = {**case.truth, "encoder_counts_per_rev": art.encoder_counts_per_rev,
             "torque_lag_s": art.torque_lag_s, "impact": {},
             "measuring_system": art.to_dict()}
    return Case(case.index, case.kind, config, case.positions_deg, case.temperatures_C, truth,
                case.post, form=case.form, loading=case.loading, lag_s=0.0, impact={},
                play_change_um=case.play_change_um, command_offset_Nm=case.command_offset_Nm,
                offset_drift_Nm=case.offset_drift_Nm, artifacts=art,
                artifact_seed=int(rng.integers(2 ** 31)))


def _classic_form(kind: str, truth: dict[str, Any], post: dict[str, Any]) -> str:
    if kind == "friction":
        return {"lugre": "stribeck"}.get(truth["law"], truth["law"])
    if kind == "stiffness_nonlinearity":
        return "hertz" if post else "exponential"
    return FORMS[kind][0]


def widen(case: Case, rng: np.random.Generator) -> Case:
    """Draw the functional form of the case's effect (:data:`FORMS`), the loading profile
    (:data:`LOADINGS`, each a third), a coarse encoder (half the cases, 2^19..2^23 counts per
    revolution), a torque-channel lag (a third, 2-20 ms) and impact ringing at the play
    crossing (a third, 0.5-3 arcsec at 20-60 Hz decaying in 10-50 ms)."""
    kind, config = case.kind, case.config
    temps = list(case.temperatures_C)
    forms = FORMS[kind]
    form = case.form if kind == "friction" else str(forms[int(rng.integers(len(forms)))])
    truth, post = dict(case.truth), dict(case.post)
    play: list[float] = []
    offset = 0.0
    if kind == "stiffness_nonlinearity" and form == "hertz":
        post = {"stiffening_power_law": {
            "twist_at_rated_arcmin": float(rng.uniform(0.2, 0.5)),
            "exponent": float(rng.uniform(0.4, 0.67))}}
        truth = dict(post)
        config = config.with_effect(kind, enabled=False)
    elif kind == "stiffness_nonlinearity":
        # hardening over the whole range: the scale is 0.4-1 rated torque, so the extra
        # compliance is still falling at rated (a take-up that ends at a small torque is the
        # bearing clearance's shape, not this one)
        truth = {"soft_twist_arcmin": float(rng.uniform(0.3, 0.8)),
                 "torque_scale_Nm": float(rng.uniform(0.4, 1.0) * RATED_NM)}
        post = {}
        config = config.with_effect(kind, **truth)
    elif kind == "runout" and form == "2x":
        amp, phase = float(rng.uniform(3.0, 8.0)), float(rng.uniform(-180.0, 180.0))
        truth = {"harmonic": 2, "play_amplitude_um": amp, "phase_deg": phase}
        play = [amp * math.cos(math.radians(2.0 * p + phase)) for p in case.positions_deg]
        config = config.with_effect(kind, enabled=False)
    elif kind == "bearing_clearance" and form == "smooth":
        post = {"smooth_takeup": {"clearance_arcmin": float(rng.uniform(0.1, 0.4)),
                                  "knee_Nm": float(rng.uniform(0.03, 0.15) * RATED_NM)}}
        truth = dict(post)
        config = config.with_effect(kind, enabled=False)
    elif kind == "thermal_expansion" and form == "quadratic":
        c1 = float(rng.choice([-1, 1]) * rng.uniform(0.1, 0.4))
        c2 = float(rng.choice([-1, 1]) * rng.uniform(0.005, 0.015))
        truth = {"um_per_K": c1, "um_per_K2": c2, "reference_C": 20.0}
        play = [c1 * (t - 20.0) + c2 * (t - 20.0) ** 2 for t in case.temperatures_C]
        config = config.with_effect(kind, enabled=False)
    elif kind == "torque_sensor_offset" and form == "regulated":
        offset = float(truth["offset_Nm"])
        truth = {**truth, "drive_regulates_on_measured_torque": True}
    elif kind == "runout" and form == "ovality":
        # the eccentricities of eq. 4 (kept) and an oval ring or bearing seat on top: a play
        # change twice per crank turn of 2-5 um
        amp, phase = float(rng.uniform(2.0, 5.0)), float(rng.uniform(-180.0, 180.0))
        truth = {**truth, "ovality_play_amplitude_um": amp, "ovality_phase_deg": phase}
        play = [amp * math.cos(math.radians(2.0 * p + phase)) for p in case.positions_deg]
    elif kind == "thermal_expansion" and form == "lagged":
        # the play follows the mesh temperature, which lags the housing sensor by the unit's
        # thermal time constant (0.5-5 times the time between runs, RUN_SPACING_S); heated
        # then cooled half the time, so the lag shows as a hysteresis in the sensor's
        # temperature
        coeff = float(rng.choice([-1, 1]) * rng.uniform(0.2, 0.6))
        ratio = float(rng.uniform(0.5, 5.0))
        if rng.random() < 0.5:
            temps = [12.0, 24.0, 36.0, 48.0, 48.0, 36.0, 24.0, 12.0]
        mesh = thermal_lag_C(temps, ratio)
        truth = {"um_per_K": coeff, "lag_runs": ratio, "reference_C": 20.0,
                 "mesh_temperature_C": mesh}
        play = [coeff * (t - 20.0) for t in mesh]
        config = config.with_effect(kind, enabled=False)
    elif kind == "torque_sensor_offset" and form == "drifting":
        drift = float(rng.choice([-1, 1]) * rng.uniform(0.03, 0.12))
        truth = {**truth, "drift_per_run_Nm": drift}
    elif kind == "shaft_compliance" and form == "mild":
        # a loaded stiffness only 3-8 % below the model's (a coupling, or a mesh a little
        # softer than seed 004 eq. 8): a series spring k_s = K (1 - d) / d
        deficit = float(rng.uniform(0.03, 0.08))
        k_mesh = reference_nominal(config.unit).stiffness_Nm_per_arcmin
        truth = {"stiffness_Nm_per_arcmin": k_mesh * (1.0 - deficit) / deficit,
                 "stiffness_deficit": deficit}
        config = config.with_effect(kind, **{k: v for k, v in truth.items()
                                             if k == "stiffness_Nm_per_arcmin"})
    elif kind == "tooth_spacing_error" and form == "harmonic":
        # a smooth thickness pattern around each gear (order 2-4, like an accumulated
        # cutting error) instead of tooth-to-tooth scatter; pitch errors alone would only
        # shift the loop, which a locked-input loop cannot see
        z = (int(config.unit["z_internal"]), int(config.unit["z_external"]))
        amp = (float(rng.uniform(3.0, 6.0)), float(rng.uniform(0.0, 3.0)))
        order = (int(rng.integers(2, 5)), int(rng.integers(2, 5)))
        phase = (float(rng.uniform(0, 2 * math.pi)), float(rng.uniform(0, 2 * math.pi)))
        tables = [[round(a * math.cos(2 * math.pi * h * i / n + ph), 4) for i in range(n)]
                  for a, h, ph, n in zip(amp, order, phase, z, strict=True)]
        truth = {"thickness_internal_um": tables[0], "thickness_external_um": tables[1],
                 "pitch_error_um_rms": 0.0, "orders": list(order)}
        config = config.with_effect(kind, **{k: v for k, v in truth.items() if k != "orders"})
    loading = str(LOADINGS[int(rng.integers(len(LOADINGS)))])
    if rng.random() < 0.5:
        counts = int(COARSE_COUNTS[int(rng.integers(len(COARSE_COUNTS)))])
        config = config.with_changes(rig={"encoder_counts_per_rev": counts})
    lag = float(rng.uniform(0.002, 0.02)) if rng.random() < 1 / 3 else 0.0
    impact = {"amplitude_arcsec": float(rng.uniform(0.5, 3.0)),
              "frequency_Hz": float(rng.uniform(20.0, 60.0)),
              "decay_s": float(rng.uniform(0.01, 0.05))} if rng.random() < 1 / 3 else {}
    truth = {**truth, "form": form, "loading": loading,
             "encoder_counts_per_rev": config.rig.encoder_counts_per_rev,
             "torque_lag_s": lag, "impact": impact}
    return Case(case.index, kind, config, case.positions_deg, temps, truth, post,
                form=form, loading=loading, lag_s=lag, impact=impact, play_change_um=play,
                command_offset_Nm=offset, offset_drift_Nm=float(truth.get("drift_per_run_Nm",
                                                                           0.0)))


def loading_profile(loading: str, rated_Nm: float, n: int) -> np.ndarray:
    """The commanded torque (N*m) of a loading profile (:data:`LOADINGS`), n samples."""
    if loading == "stepped":
        return cycle_profile(rated_Nm, n)
    if loading == "ramp":
        return ramp_profile(rated_Nm, n)
    if loading == "sine":
        return sine_profile(rated_Nm, n)
    raise ValueError(f"unknown loading {loading!r}; known: {', '.join(LOADINGS)}")


def _extra_twist_arcmin(case: Case, flange_Nm: np.ndarray) -> np.ndarray:
    """The effects added outside the plant (other forms), as twist (arcmin) of the flange
    torque: a Hertzian power-law stiffening, a smooth clearance take-up."""
    extra = np.zeros_like(flange_Nm)
    law = case.post.get("stiffening_power_law")
    if law is not None:
        extra += power_law_twist_arcmin(flange_Nm, RATED_NM, **law)
    takeup = case.post.get("smooth_takeup")
    if takeup is not None:
        extra += smooth_takeup_twist_arcmin(flange_Nm, **takeup)
    return extra


def _plant_columns(case: Case, config: PlantConfig, profile: np.ndarray, pos: float,
                   temp: float) -> dict[str, np.ndarray]:
    """A run's columns from the plant with the sensor artifacts of :func:`widen`."""
    counts = case.config.rig.encoder_counts_per_rev
    samples = profile.size
    cols = simulate_run(config, profile, duration_s=samples / RATE_HZ,
                        sample_rate_Hz=RATE_HZ, input_angle_deg=pos, temperature_C=temp)
    flange = cols["true_torque_Nm"]
    extra = _extra_twist_arcmin(case, flange)
    if case.impact:
        extra += impact_ringing_arcsec(cols["t_s"], flange, **case.impact) / 60.0
    if extra.any():
        cols["output_angle_deg"] = quantise_deg(cols["output_angle_deg"] + extra / 60.0,
                                                counts)
    if case.lag_s > 0.0:
        lagged = delayed(cols["t_s"], flange, case.lag_s)
        cols["torque_Nm"] = cols["torque_Nm"] + lagged - flange
    return cols


def _measured_columns(case: Case, k: int, config: PlantConfig, pos: float,
                      temp: float) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """A run's columns measured through the case's rig (:func:`measure_run`), and what the
    run's own draws were (zero residual, dropped rows, impacts and bounces)."""
    art = case.artifacts
    assert art is not None
    n = int(round(DURATION_S * art.sample_rate_Hz))
    profile = path_profile(case.loading, RATED_NM, n, art.precycles,
                           art.first_sign) - case.command_offset_Nm
    noise = case.config.noise
    res = measure_run(config, profile, art, twist_noise_arcsec=noise.twist_arcsec_rms,
                      torque_noise_Nm=noise.torque_Nm_rms,
                      rng=np.random.default_rng([case.artifact_seed, k]),
                      input_angle_deg=pos, temperature_C=temp,
                      extra_twist_arcmin=(lambda f: _extra_twist_arcmin(case, f))
                      if case.post else None)
    tr = res["truth"]
    run_truth = {"tare_residual_Nm": float(tr["zero_Nm"][0]),
                 "zero_drift_Nm": float(tr["zero_Nm"][-1] - tr["zero_Nm"][0]),
                 "dropped_rows": int((~tr["keep"]).sum()), "dropped_bursts": tr["bursts"],
                 "impacts": tr["contact"]["impacts"], "bounces": tr["contact"]["bounces"]}
    return res["columns"], run_truth


def simulate_campaign(case: Case, samples: int = int(DURATION_S * RATE_HZ)) -> Campaign:
    """The case's campaign as rig-run/1 runs (labels only under run.json ``generator``).
    With :attr:`Case.artifacts` the runs are measured through that rig (``samples`` is then
    its sample rate times :data:`DURATION_S`)."""
    counts = case.config.rig.encoder_counts_per_rev
    alpha = float(case.config.unit.get("pressure_angle_deg", 20.0))
    art = case.artifacts
    profile = loading_profile(case.loading, RATED_NM, samples) - case.command_offset_Nm
    runs = []
    for k, (pos, temp) in enumerate(zip(case.positions_deg, case.temperatures_C, strict=True)):
        config = case.config
        if case.play_change_um:
            a = float(config.unit["center_distance_mm"])
            da = center_distance_change_mm(case.play_change_um[k], alpha)
            config = config.with_changes(unit={"center_distance_mm": a + da})
        generator: dict[str, Any] = {"kind": case.kind, "truth": case.truth,
                                     "what": "rig.validate (simulated, not a measurement)"}
        if art is None:
            cols = _plant_columns(case, config, profile, pos, temp)
        else:
            cols, generator["measuring_system_run"] = _measured_columns(case, k, config, pos,
                                                                        temp)
        spring = case.post.get("parallel_spring")
        if spring is not None:
            cols["torque_Nm"] = cols["torque_Nm"] + parallel_spring_torque_Nm(
                cols["output_angle_deg"], spring["stiffness_Nm_per_arcmin"])
        if case.offset_drift_Nm:
            cols["torque_Nm"] = cols["torque_Nm"] + drifting_zero_Nm(cols["t_s"],
                                                                     case.offset_drift_Nm)
        if art is not None and (spring is not None or case.offset_drift_Nm):
            # both act on the sensor's analog signal, before its ADC: back on the ADC's grid
            step = art.adc_step_Nm
            cols["torque_Nm"] = np.round(cols["torque_Nm"] / step) * step
        run_id = f"case{case.index:03d}-run{k:02d}"
        plan = {"stepped": "cycle-steps", "ramp": "cycle-ramp", "sine": "cycle-sine"}[case.loading]
        test = {"rated_torque_Nm": RATED_NM, "input_angle_deg": pos, "temperature_C": temp,
                "cycles": 1, "plan": plan}
        if art is not None:
            test["cycles"] = 1 + art.precycles
            test["start_flank"] = -1
        started = CAMPAIGN_START + timedelta(seconds=k * RUN_SPACING_S)
        runs.append(Run.from_arrays(
            run_id, cols["t_s"], cols["torque_Nm"], cols["output_angle_deg"],
            input_angle_deg=cols["input_angle_deg"], temperature_C=cols["temperature_C"],
            unit=case.config.unit, test=test,
            sensors={"encoder_counts_per_rev": counts, "torque_full_scale_Nm": FULL_SCALE_NM},
            extra_meta={"generator": generator,
                        "started_at": started.strftime("%Y-%m-%dT%H:%M:%SZ")},
        ))
    meta = {"format": "rig-campaign/1", "name": f"validation-case{case.index:03d}",
            "runs": [r.run_id for r in runs]}
    return Campaign(meta=meta, runs=runs)


def case_kinds(n: int) -> list[str]:
    """N case kinds cycling through every kind (each in-vocabulary effect several times)."""
    return [KINDS[i % len(KINDS)] for i in range(n)]


@dataclass
class CaseResult:
    case: Case
    verdict: str
    candidates: list[str]
    shrink: float | None
    seconds: float
    #: The rig-diagnosis/1 report as ``rig diagnose --json`` writes it (graded by the labels).
    report: dict[str, Any] = field(default_factory=dict)

    @property
    def correct(self) -> bool:
        if self.verdict not in self.case.expected:
            return False
        if self.case.kind == "shaft_compliance" and self.verdict == "ambiguous":
            return "shaft_compliance" in self.candidates
        return True


def run_validation(n_cases: int, seed: int = 0,
                   progress: Callable[[CaseResult], None] | None = None,
                   jobs: int = 1, artifacts: bool = False, nulls: int = 0) -> list[CaseResult]:
    """Generate and blindly diagnose ``n_cases`` campaigns (and ``nulls`` more null ones);
    returns one result per case."""
    return list(iter_validation(n_cases, seed, progress, jobs, artifacts, nulls))


def draw_case(seed: int, index: int, kind: str, artifacts: bool = False) -> Case:
    """Case ``index`` of ``kind`` drawn by the widened generator from its own stream
    ``default_rng([seed, index])`` (the same case whatever the number of jobs); with
    ``artifacts`` measured through a real rig drawn from ``[seed, index, ARTIFACT_STREAM]``."""
    arts = np.random.default_rng([seed, index, ARTIFACT_STREAM]) if artifacts else None
    return make_case(index, kind, np.random.default_rng([seed, index]), load_plant_config(),
                     widened=True, artifacts_rng=arts)


def validate_one(args: tuple[int, int, str] | tuple[int, int, str, bool]) -> CaseResult:
    """:func:`draw_case` of ``(seed, index, kind[, artifacts])``, simulated and diagnosed
    blind."""
    seed, index, kind = args[:3]
    case = draw_case(seed, index, kind, bool(args[3]) if len(args) > 3 else False)
    return diagnose_blind(case, simulate_campaign(case))


def diagnose_blind(case: Case, campaign: Campaign) -> CaseResult:
    """The diagnosis of ``case``'s simulated ``campaign``, blind to the case, with its time
    (s); the report as JSON has it (no NaN)."""
    t0 = time.perf_counter()
    report = diagnose_campaign(campaign).to_dict()
    seconds = time.perf_counter() - t0
    report = json.loads(json.dumps(finite_for_json(report), allow_nan=False))
    return CaseResult(case, report["verdict"], list(report.get("candidates") or []),
                      report.get("shrink"), seconds, report)


def iter_validation(n_cases: int, seed: int = 0,
                    progress: Callable[[CaseResult], None] | None = None,
                    jobs: int = 1, artifacts: bool = False, nulls: int = 0
                    ) -> Iterator[CaseResult]:
    """:func:`validate_one` for cases 0..n-1 (kinds by :func:`case_kinds`), then ``nulls``
    null cases n..n+nulls-1 (their own draws), in order."""
    from rig.validate.cases import parallel_map

    kinds = case_kinds(n_cases) + ["none"] * nulls
    args = [(seed, i, kind, artifacts) for i, kind in enumerate(kinds)]
    for res in parallel_map(validate_one, args, jobs):
        if progress is not None:
            progress(res)
        yield res


def case_label(case: Case) -> Label:
    """The case's answer in the labels' format (:mod:`rig.validate.labels`); its category is
    the loading profile."""
    effect = "unexplained" if case.kind in OUT_OF_VOCABULARY else case.kind
    cands = ("shaft_compliance",) if case.kind == "shaft_compliance" else ()
    return Label(f"case{case.index:03d}", effect, tuple(sorted(case.expected)), cands,
                 category=case.loading)


def graded_validation(n_cases: int, seed: int = 0, jobs: int = 1,
                      progress: Callable[[CaseResult], None] | None = None,
                      name: str = "ours", artifacts: bool = False, nulls: int = 0
                      ) -> tuple[list[CaseResult], dict[str, Any]]:
    """Our generator graded exactly as a labelled folder (:func:`summarise_graded`); with
    ``artifacts`` each case measured through a real rig's measuring system."""
    from rig.validate.cases import record, summarise_graded

    results = run_validation(n_cases, seed, progress, jobs, artifacts, nulls)
    records = []
    for r in results:
        rec = record(case_label(r.case), {**r.report, "seconds": r.seconds})
        rec["form"], rec["loading"] = r.case.form, r.case.loading
        records.append(rec)
    return results, summarise_graded(name, records)


def summarise(results: list[CaseResult]) -> dict[str, Any]:
    """Confusion matrix (true kind -> verdict counts) and the issue's four figures."""
    confusion: dict[str, Counter] = {}
    for r in results:
        confusion.setdefault(r.case.kind, Counter())[r.verdict] += 1
    inv = [r for r in results if r.case.kind in IN_VOCABULARY or r.case.kind == "none"]
    nulls = [r for r in results if r.case.kind == "none"]
    oov = [r for r in results if r.case.kind in OUT_OF_VOCABULARY]
    shrinks = [r.shrink for r in results if r.case.kind in IN_VOCABULARY and r.correct
               and r.shrink is not None and r.case.kind != "shaft_compliance"]

    def share(items: list[CaseResult], ok: Callable[[CaseResult], bool]) -> float | None:
        return sum(ok(r) for r in items) / len(items) if items else None

    return {
        "cases": len(results),
        "confusion": {k: dict(v) for k, v in confusion.items()},
        "correct_share": share(inv, lambda r: r.correct),
        "false_alarm_share": share(nulls, lambda r: r.verdict != "none"),
        "oov_unexplained_or_ambiguous_share": share(oov, lambda r: r.correct),
        "median_shrink": float(np.median(shrinks)) if shrinks else None,
        "seconds_per_case": float(np.mean([r.seconds for r in results])) if results else None,
        "targets": {"correct_share": 0.95, "false_alarm_share": 0.05,
                    "oov_unexplained_or_ambiguous_share": 0.8, "median_shrink": 0.7},
    }


def meets_targets(summary: dict[str, Any]) -> bool:
    """True when all four figures meet the issue's targets."""
    t = summary["targets"]
    checks = [
        summary["correct_share"] is None or summary["correct_share"] >= t["correct_share"],
        summary["false_alarm_share"] is None
        or summary["false_alarm_share"] <= t["false_alarm_share"],
        summary["oov_unexplained_or_ambiguous_share"] is None
        or summary["oov_unexplained_or_ambiguous_share"] >= t["oov_unexplained_or_ambiguous_share"],
        summary["median_shrink"] is None or summary["median_shrink"] >= t["median_shrink"],
    ]
    return all(checks) and not math.isnan(float(len(checks)))
