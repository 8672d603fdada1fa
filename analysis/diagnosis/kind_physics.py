"""The diagnosis' effect physics in each unit kind's own geometry (issue 23 item 2).

The effect vocabulary (docs/run-format.md) and the report stay the same for every kind; what
changes is each effect's *signature*, read from the unit's own geometry:

* which angle the play repeats over (the orders of the runout terms over one input turn and
  the tooth pair in mesh at a locking angle);
* how a center-distance change (an eccentricity, a bearing's radial clearance) becomes output
  play (the kind's counterpart of seed 000 eq. 3);
* the conversion between a circumferential play (um) and an output angle (arcmin): the
  counterpart of seed 000 eq. (1) on the output member's reference radius;
* what the inspected tolerances allow (plausibility budgets and the priors of the fit);
* the unit's own nominal loop shape where it is not the pinned linear loop (the compound
  cycloid's play over the mesh phase, its flanks engaging one after another);
* the effects that have no meaning of their own for the kind (``not_testable``).

``internal_involute`` (seed 000) keeps the code paths of :mod:`analysis.diagnosis` unchanged:
:func:`physics_for_unit` returns None for it. Units: lengths um (mm in unit keys), angles
arcmin at the output, input angles deg, torques N*m.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np

from analysis.errors import AnalysisError

ARCMIN_PER_RAD = 10800.0 / math.pi
#: Seed 002 Table 2 (JB/T 10419 grade 5): radial runout Delta_frt and single pitch deviation
#: Delta_fpt of the cycloid gear (mm): the inspection budget when the unit gives none.
CYCLOID_RUNOUT_MM = 0.016
CYCLOID_PITCH_DEVIATION_MM = 0.008
#: A beveloid unit without inspected runouts: ISO 1328-2 radial runout F_r of a grade 6 gear
#: of module 3 and about 60 mm diameter (mm).
BEVELOID_RUNOUT_MM = 0.020
#: Mesh phases over one tooth pitch at which the cycloid's nominal play and loaded flank
#: curve are tabulated (seed 002's free play varies with the mesh phase): the nominal
#: model's (analysis.models.cycloid_nominal.MESH_PHASES), linear between.
CYCLOID_PHASES = 6
#: Relative step of the numerical derivative of the play by the center distance (mm).
CD_STEP_MM = 0.002


@dataclass(frozen=True)
class KindPhysics:
    """One kind's effect signatures (see the module docstring).

    ``z_input``: mesh steps per input turn (the tooth pair index advances by it); ``z_mate``:
    the other member's tooth count (the same pair meshes again after ``lcm`` steps);
    ``runout_order``: the second eccentricity term's cycles per input turn (the first is one
    per turn); ``radius_mm``: the output member's reference radius of the um <-> arcmin
    conversion; ``play_per_center_distance``: d(play)/d(center distance) (arcmin per um;
    negative when a larger center distance closes the play)."""

    kind: str
    z_input: int
    z_mate: int
    runout_order: float
    radius_mm: float
    play_per_center_distance: float
    runout_budget_arcmin: float
    bearing_budget_arcmin: float | None
    spacing_prior_arcmin: float
    spacing_limit_um: float
    thermal_limit_um_per_K: float
    not_testable: dict[str, str] = field(default_factory=dict)
    equations: dict[str, str] = field(default_factory=dict)
    inspected: dict[str, Any] = field(default_factory=dict)
    #: The cycloid's nominal loop over the mesh phase (None: the pinned linear loop).
    cycloid: CycloidShape | None = None

    def um_to_arcmin(self, j_um: float | np.ndarray) -> np.ndarray:
        """A circumferential play on the output's reference radius (um) as an output angle
        (arcmin): ``j / r`` rad (the kind's seed 000 eq. 1)."""
        return np.asarray(j_um, dtype=float) / (1000.0 * self.radius_mm) * ARCMIN_PER_RAD

    def arcmin_to_um(self, angle_arcmin: float | np.ndarray) -> np.ndarray:
        """Inverse of :meth:`um_to_arcmin`."""
        return np.asarray(angle_arcmin, dtype=float) / ARCMIN_PER_RAD * 1000.0 * self.radius_mm

    def runout_basis(self, input_angle_deg: float) -> np.ndarray:
        """The two eccentricity terms' columns (cos theta, sin theta, cos k theta,
        sin k theta) at the input angle, k = :attr:`runout_order` (first order of the kind's
        center distance over the input angle)."""
        theta = math.radians(float(input_angle_deg))
        k = self.runout_order
        return np.array([math.cos(theta), math.sin(theta), math.cos(k * theta),
                         math.sin(k * theta)])

    def eccentricity_um(self, play_amplitude_arcmin: float) -> float:
        """The eccentricity (um) whose center-distance change gives this play amplitude."""
        s = abs(self.play_per_center_distance)
        return play_amplitude_arcmin / s if s > 0 else math.nan

    def to_dict(self) -> dict[str, Any]:
        """What the report states about the kind's physics (JSON-ready)."""
        return {
            "kind": self.kind,
            "mesh_steps_per_input_turn": self.z_input,
            "tooth_repeat_input_turns": math.lcm(self.z_input, self.z_mate) / self.z_input,
            "runout_orders_per_input_turn": [1.0, self.runout_order],
            "output_radius_mm": self.radius_mm,
            "play_per_center_distance_arcmin_per_um": self.play_per_center_distance,
            "runout_budget_arcmin": self.runout_budget_arcmin,
            "bearing_budget_arcmin": self.bearing_budget_arcmin,
            "spacing_limit_um_rms": self.spacing_limit_um,
            "thermal_limit_um_per_K": self.thermal_limit_um_per_K,
            "inspected": dict(self.inspected),
            "equations": dict(self.equations),
            "nominal_shape": None if self.cycloid is None else self.cycloid.describe(),
        }


@dataclass(frozen=True, eq=False)
class CycloidShape:
    """Seed 002's assembled pair over one mesh cycle: the free play at each tabulated mesh
    phase (arcmin) and, per phase and flank side, the loaded turn of gear 1 against torque
    (the flanks engaging one after another, ``T = sum_i k l_i^2 (theta - theta_i)+``,
    seed 004 eq. 8's single-pair stiffness per flank). The mesh phase is the crank (input)
    angle modulo one tooth pitch of gear 2, 360 / z_internal deg."""

    z_internal: int
    phases_deg: np.ndarray
    plays_arcmin: np.ndarray
    torque_grid_Nm: np.ndarray
    turns_arcmin: np.ndarray  # (phase, side 0: +, 1: -, torque)
    secant_Nm_per_arcmin: float

    def _phase_index(self, input_angle_deg: float) -> tuple[int, int, float]:
        pitch = 360.0 / self.z_internal
        u = (float(input_angle_deg) % pitch) / pitch * self.phases_deg.size
        i = int(math.floor(u)) % self.phases_deg.size
        return i, (i + 1) % self.phases_deg.size, u - math.floor(u)

    #: The unit's calibrated mean play (arcmin) the mesh-phase change is added to (None:
    #: the nominal mean): an as-made deviation (an eccentricity error, a shift error) adds a
    #: constant to the play and leaves its change over the mesh phase as it is.
    play_reference_arcmin: float | None = None

    def play_ratio(self, input_angle_deg: float) -> float:
        """The free play at this mesh phase over the mean play: ``1 + (P(phase) - mean P) /
        P_ref`` (the play column's factor: its coefficient is the mean play)."""
        i, j, w = self._phase_index(input_angle_deg)
        play = (1 - w) * self.plays_arcmin[i] + w * self.plays_arcmin[j]
        mean = float(np.mean(self.plays_arcmin))
        ref = self.play_reference_arcmin or mean
        return float(1.0 + (play - mean) / ref) if ref > 0 else 1.0

    def shape_Nm(self, input_angle_deg: float, flank: np.ndarray, tau: np.ndarray
                 ) -> np.ndarray:
        """The loaded flank curve as an equivalent torque ``K_sec turn(|T|)`` (N*m): the
        turn of gear 1 beyond first contact, mean over the mesh phases and both flank sides
        (the flanks engaging one after another), the last slope continued beyond the grid;
        multiplied by the compliance ``1 / K_sec`` it is the twist. Equal to ``|T|`` where
        the flank is linear with the secant stiffness."""
        t = np.asarray(tau, dtype=float)
        mean = self.mean_turn_arcmin
        turn = np.interp(t, self.torque_grid_Nm, mean)
        top = self.torque_grid_Nm[-1]
        beyond = t > top
        if beyond.any():
            slope = (mean[-1] - mean[-2]) / (top - self.torque_grid_Nm[-2])
            turn[beyond] = mean[-1] + slope * (t[beyond] - top)
        return self.secant_Nm_per_arcmin * turn

    @property
    def mean_turn_arcmin(self) -> np.ndarray:
        """Gear 1's loaded turn beyond first contact (arcmin) on the torque grid, mean over
        the mesh phases and both sides."""
        return np.mean(self.turns_arcmin, axis=(0, 1))

    def describe(self) -> dict[str, Any]:
        return {
            "play_over_mesh_phase_arcmin": [float(self.plays_arcmin.min()),
                                            float(self.plays_arcmin.max())],
            "secant_stiffness_Nm_per_arcmin": self.secant_Nm_per_arcmin,
            "first_flank_stiffness_Nm_per_arcmin": float(
                self.torque_grid_Nm[1] / np.mean(self.turns_arcmin[:, :, 1])),
            "mesh_phase_period_deg": 360.0 / self.z_internal,
        }


def _num(unit: Mapping[str, Any], key: str, default: float | None = None) -> float | None:
    v = unit.get(key, default)
    if v is None or isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        return default
    return float(v)


def _clearances(unit: Mapping[str, Any]) -> list[float] | None:
    v = unit.get("bearing_clearance_mm")
    if isinstance(v, int | float) and not isinstance(v, bool):
        v = [v]
    if isinstance(v, list) and v and all(isinstance(c, int | float) and not isinstance(c, bool)
                                         and math.isfinite(c) and c >= 0 for c in v):
        return [float(c) for c in v]
    return None


# ---------------------------------------------------------------------------- cycloid


@lru_cache(maxsize=16)
def _cycloid_tables(pair: Any, mod: Any, face_width_mm: float | None, reference_Nm: float
                    ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, float]:
    """(d play / d shift arcmin per mm, plays per phase, torque grid, turns, secant)."""
    from analysis.models.mesh_stiffness import single_pair_stiffness_N_per_mm_um
    from analysis.models.seed002_clearance import (
        Modification,
        flank_contacts,
        loaded_turn_rad,
    )

    def mean_play(m: Any) -> float:
        plays = []
        for ph in np.arange(4) * 2.0 * math.pi / pair.z_internal / 4:
            plus = flank_contacts(pair, m, +1, ph).first_rad
            minus = flank_contacts(pair, m, -1, ph).first_rad
            plays.append((plus - minus) * ARCMIN_PER_RAD)
        return float(np.mean(plays))

    h = CD_STEP_MM
    up = Modification(mod.shift_mm + h, mod.rotation_mm)
    down = Modification(max(mod.shift_mm - h, 0.0), mod.rotation_mm)
    d_shift = (mean_play(up) - mean_play(down)) / (up.shift_mm - down.shift_mm)
    k = math.inf
    if face_width_mm is not None:
        k = face_width_mm * single_pair_stiffness_N_per_mm_um(pair.z_internal, pair.z_external)
    grid = np.concatenate([[0.0], np.geomspace(1e-3, 1.0, 40)]) * reference_Nm
    phases = np.arange(CYCLOID_PHASES) * 360.0 / pair.z_internal / CYCLOID_PHASES
    plays = np.empty(phases.size)
    turns = np.zeros((phases.size, 2, grid.size))
    for n, ph in enumerate(phases):
        firsts = []
        for s_i, side in enumerate((+1, -1)):
            reach = 150.0
            for _ in range(4):
                c = flank_contacts(pair, mod, side, math.radians(ph), reach_um=reach)
                if not math.isfinite(k):
                    break
                try:
                    turn = loaded_turn_rad(c, grid, k)
                    break
                except AnalysisError:
                    reach *= 4.0
            else:
                raise AnalysisError("cycloid flank curve beyond the flanks searched")
            firsts.append(c.first_rad)
            if math.isfinite(k):
                turns[n, s_i] = np.abs(turn - c.first_rad) * ARCMIN_PER_RAD
        plays[n] = (firsts[0] - firsts[1]) * ARCMIN_PER_RAD
    top = float(np.mean(turns[:, :, -1]))
    secant = reference_Nm / top if top > 0 else math.inf
    return d_shift, plays, grid, turns, secant


def cycloid_physics(unit: Mapping[str, Any], rated_Nm: float) -> KindPhysics:
    """Seed 002's compound cycloid few-tooth-difference pair (gear 2 internal, fixed; gear 1
    on the crank, the output).

    * **Repeat angle**: the crank (input) is the eccentric shaft of seed 000's eq. (4) with
      gear 2's z2 = ``z_internal`` and gear 1's z1 = ``z_external``: gear 2's eccentricity
      (fixed) moves the center distance once per crank turn, gear 1's (Delta_frt / 2, turning
      with gear 1) ``(2 z1 - z2) / z1`` times per turn; the tooth pair advances z2 mesh
      steps per crank turn and repeats after ``lcm(z1, z2) / z2`` turns (one output turn);
      the play itself varies over each mesh cycle of 360 / z2 deg (the mesh phase beta of
      eq. 6).
    * **Center distance -> play**: seed 002 eqs. (9)-(10): gear 1 generated at ``e + Delta1``
      and assembled at ``e`` has clearance; a center distance larger by ``d`` is the shift
      less by ``d``, so ``d play / d a = - d play / d Delta1``, read off the assembled pair's
      free play (:func:`analysis.models.seed002_clearance.free_play`) at ``Delta1 +- 2 um``.
      A crank bearing's radial clearance u_r moves O1 by ``u_r / 2`` (seed 000 eq. 7).
    * **Conversion**: a circumferential play on gear 1's pitch circle ``r1 = r2 - e``.
    * **Inspected tolerances**: ``runout_internal_mm`` / ``runout_external_mm`` (Delta_frt,
      default seed 002 Table 2's 0.016 mm), ``pitch_deviation_mm`` (Delta_fpt, default 0.008
      mm: the single-side clearance Delta_fpt / 2 is the prior of a tooth's play change, three
      times it the plausibility limit), ``bearing_clearance_mm`` (the crank bearings).
    * **Nominal shape**: the free play at the run's mesh phase and the flanks engaging one
      after another (:class:`CycloidShape`)."""
    from analysis.models.seed002_clearance import Modification
    from analysis.models.seed002_cycloid import CompoundCycloidPair

    try:
        pair = CompoundCycloidPair(
            module_mm=float(unit["module_mm"]), z_internal=int(unit["z_internal"]),
            z_external=int(unit["z_external"]), height_coeff=float(unit["height_coeff"]),
            shape_coeff=float(unit["shape_coeff"]),
            eccentricity_mm=_num(unit, "eccentricity_mm"))
    except (KeyError, TypeError, ValueError) as exc:
        raise AnalysisError(f"cycloid unit: {exc}") from exc
    mod = Modification(_num(unit, "shift_modification_mm", 0.0) or 0.0,
                       _num(unit, "rotation_modification_mm", 0.0) or 0.0)
    face = _num(unit, "face_width_mm")
    # the secant at the rated torque, as the nominal model's (analysis.models.by_kind)
    reference = float(rated_Nm) if rated_Nm > 0 else (_num(unit, "reference_torque_Nm")
                                                       or 200.0)
    d_shift, plays, grid, turns, secant = _cycloid_tables(pair, mod, face, float(reference))
    s = -d_shift / 1000.0  # arcmin per um of center distance (a larger one closes the play)
    z2, z1 = pair.z_internal, pair.z_external
    fr_int = _num(unit, "runout_internal_mm", CYCLOID_RUNOUT_MM)
    fr_ext = _num(unit, "runout_external_mm", CYCLOID_RUNOUT_MM)
    fpt = _num(unit, "pitch_deviation_mm", CYCLOID_PITCH_DEVIATION_MM)
    r1 = pair.pitch_radius_external_mm
    clear = _clearances(unit)
    runout_budget = abs(s) * 1000.0 * (fr_int + fr_ext) / 2.0
    bearing = abs(s) * 1000.0 * sum(c / 2.0 for c in clear) if clear else None
    shape = CycloidShape(z2, np.arange(CYCLOID_PHASES) * 360.0 / z2 / CYCLOID_PHASES, plays,
                         grid, turns, secant) if math.isfinite(secant) else None
    phys = KindPhysics(
        kind="cycloid", z_input=z2, z_mate=z1, runout_order=(2.0 * z1 - z2) / z1,
        radius_mm=r1, play_per_center_distance=s,
        runout_budget_arcmin=max(runout_budget, 1e-9),
        bearing_budget_arcmin=bearing,
        spacing_prior_arcmin=0.0, spacing_limit_um=3.0 * 1000.0 * fpt / 2.0,
        thermal_limit_um_per_K=3.0,
        equations={
            "runout": "seed 000 eq. (4) with z2 = z_internal, z1 = z_external (crank angle); "
                      "play change -(d play / d Delta1) d|AB| by seed 002 eqs. (9)-(10)",
            "bearing_clearance": "seed 000 eq. (7) de = u_r / 2 of the crank bearings, play by "
                                 "seed 002 eqs. (9)-(10)",
            "tooth_spacing_error": "seed 002 Table 2 Delta_fpt (JB/T 10419): play change of "
                                   "the tooth pair in mesh, z2 mesh steps per crank turn",
            "backlash": "seed 002 eqs. (1)-(14): free play of the assembled pair at the mesh "
                        "phase, flanks engaging one after another (seed 004 eq. 8 per flank)",
            "thermal_expansion": "play change per kelvin on gear 1's pitch circle",
        },
        inspected={"runout_internal_mm": fr_int, "runout_external_mm": fr_ext,
                   "pitch_deviation_mm": fpt, "bearing_clearance_mm": clear},
        cycloid=shape,
    )
    prior = float(phys.um_to_arcmin(1000.0 * fpt / 2.0))
    return _with(phys, spacing_prior_arcmin=prior)


def _with(p: KindPhysics, **changes: Any) -> KindPhysics:
    from dataclasses import replace

    return replace(p, **changes)


# ---------------------------------------------------------------------------- beveloid


def beveloid_physics(unit: Mapping[str, Any]) -> KindPhysics:
    """Seed 001's parallel-axis helical beveloid pair (the pinion is the input, locked; the
    gear is the output).

    * **Repeat angle**: no eccentric: the pinion's eccentricity moves the center distance once
      per input turn, the gear's ``z_pinion / z_gear`` times per input turn (the gear turns
      at that rate); the tooth pair advances ``z_pinion`` mesh steps per input turn and
      repeats after ``lcm / z_pinion`` turns.
    * **Center distance -> play**: the closed-form backlash of the pair
      (:func:`analysis.models.seed001_beveloid.backlash_closed_form`: the working pressure
      angles of both flanks at the center distance A and the thickening of the gear's axial
      position) differentiated by A: an external pair opens with A (``~ 2 tan(a_n) cos(delta)
      / cos(beta)`` um per um); a shaft bearing's radial clearance moves its axis by u_r / 2.
    * **Conversion**: a circumferential play on the gear's pitch circle.
    * **Inspected tolerances**: ``runout_pinion_mm`` / ``runout_gear_mm`` (F_r; else
      ``runout_external_mm`` / ``runout_internal_mm``; else 0.020 mm, ISO 1328-2 grade 6),
      ``bearing_clearance_mm`` (the shaft bearings).
    * **No meaning of its own**: with ``z_pinion == z_gear`` the same tooth pair meshes at the
      same input angle every turn (repeat period one input turn): a tooth's play error is a
      fixed function of the locking angle, which no design can tell from a play that changes
      with the position (runout and its harmonics): ``tooth_spacing_error`` is not testable."""
    from analysis.models.beveloid_nominal import beveloid_pair_from_unit
    from analysis.models.seed001_beveloid import backlash_closed_form

    pair, shift, _ = beveloid_pair_from_unit(unit)
    a = pair.center_distance_mm
    h = CD_STEP_MM
    hi = type(pair)(pair.pinion, pair.gear, a + h)
    lo = type(pair)(pair.pinion, pair.gear, a - h)
    s = (backlash_closed_form(hi, shift).angle_arcmin
         - backlash_closed_form(lo, shift).angle_arcmin) / (2.0 * h * 1000.0)
    zp, zg = pair.pinion.teeth, pair.gear.teeth
    # the plant's naming: the gear's runout under runout_internal_mm, the pinion's external
    fr_p = _num(unit, "runout_pinion_mm", _num(unit, "runout_external_mm", BEVELOID_RUNOUT_MM))
    fr_g = _num(unit, "runout_gear_mm", _num(unit, "runout_internal_mm", BEVELOID_RUNOUT_MM))
    clear = _clearances(unit)
    r2 = pair.gear.pitch_radius_mm
    not_testable = {}
    if zp == zg:
        not_testable["tooth_spacing_error"] = (
            f"beveloid {zp}/{zg}: the same tooth pair meshes at the same input angle every "
            "turn, so a tooth's play error is a fixed function of the locking angle and has "
            "no meaning apart from a play that changes with position (runout)")
    phys = KindPhysics(
        kind="beveloid", z_input=zp, z_mate=zg, runout_order=zp / zg, radius_mm=r2,
        play_per_center_distance=s,
        runout_budget_arcmin=max(abs(s) * 1000.0 * (fr_p + fr_g) / 2.0, 1e-9),
        bearing_budget_arcmin=abs(s) * 1000.0 * sum(c / 2.0 for c in clear) if clear else None,
        spacing_prior_arcmin=0.0, spacing_limit_um=12.0, thermal_limit_um_per_K=3.0,
        not_testable=not_testable,
        equations={
            "runout": "center distance of the parallel axes, pinion eccentricity once and gear "
                      "eccentricity z_pinion / z_gear times per input turn; play by the "
                      "closed-form backlash of seed 001's pair differentiated by A",
            "bearing_clearance": "seed 000 eq. (7) de = u_r / 2 of the shaft bearings, play by "
                                 "d(backlash)/dA of seed 001's pair",
            "tooth_spacing_error": "play change of the tooth pair in mesh, z_pinion mesh steps "
                                   "per input turn",
            "backlash": "seed 001: closed-form backlash at the center distance and axial "
                        "position (installation errors: axial shift, center distance)",
            "thermal_expansion": "play change per kelvin on the gear's pitch circle",
        },
        inspected={"runout_pinion_mm": fr_p, "runout_gear_mm": fr_g,
                   "bearing_clearance_mm": clear},
    )
    return _with(phys, spacing_prior_arcmin=float(phys.um_to_arcmin(4.0)))


def physics_for_unit(unit: Mapping[str, Any] | None, rated_Nm: float) -> KindPhysics | None:
    """The kind's effect physics; None for ``internal_involute`` (seed 000: the code paths of
    :mod:`analysis.diagnosis` as they are) and for a unit without data."""
    if not unit:
        return None
    kind = unit.get("kind", "internal_involute")
    if kind == "cycloid":
        return cycloid_physics(unit, rated_Nm)
    if kind == "beveloid":
        return beveloid_physics(unit)
    return None
