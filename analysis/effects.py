"""The quasi-static loop model as a composition of effect terms (run-format.md vocabulary).

One term per effect, each with bounded parameters of physical meaning and units, the seed
equation behind it where there is one, and its signature: where in the loop it shows and
across which campaign factor (position, temperature, amplitude, rate). ``backlash`` and
``mesh_stiffness`` form the reference nominal model; the others are the candidates of
:mod:`analysis.diagnosis`. This is a separate, quasi-static implementation: the simulator's
plant (simulators/) is a richer time-domain model and shares no code with it.

The composed loop, for a run at eccentric-shaft angle ``theta`` (deg) and housing temperature
``temp`` (deg C), along a history of *measured* torques ``T_m`` (N*m):

* ``T = T_m - offset`` (``torque_sensor_offset``),
* chain torque ``G = stop(T, F)`` (Coulomb ``friction`` F in parallel with the chain: the stop
  operator ``G_k = clip(G_(k-1), T_k - F, T_k + F)``, the exact quasi-static limit),
* flank ``s``: +1 once ``G > delta``, -1 once ``G < -delta``, kept between (delta: a noise band),
* twist (arcmin) ``= c + s (P(theta, temp, tooth) / 2 + h(|G|))`` with
  ``P = play + runout(theta) + thermal(temp) + spacing(tooth)`` and
  ``h(tau) = tau / K + tau / K_shaft + d_s (1 - exp(-tau / T_s)) + min(tau, T_b) / K_b``.

``c`` is the run's twist offset, free (run-format.md: the twist zero is arbitrary).
Plays are output angles (arcmin); circumferential plays (um on the ring's reference circle)
become angles by seed 000 eq. (1), ``arcmin = 6.876 j_t / (m z_internal)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from analysis.errors import AnalysisError

EQ1_FACTOR = 6.876
"""Seed 000 eq. (1) as printed: arcmin = 6.876 j_t(um) / (m z_internal)."""


@dataclass(frozen=True)
class Param:
    """One parameter of an effect: name (with unit), meaning, default bounds (None: per unit)."""

    name: str
    meaning: str
    lower: float | None = None
    upper: float | None = None


@dataclass(frozen=True)
class Effect:
    """An effect of the vocabulary: its parameters, seed equation, and loop signature."""

    name: str
    role: str  # "nominal" or "candidate"
    params: tuple[Param, ...]
    equation: str
    where_in_loop: str
    varies_with: tuple[str, ...]
    structural: bool = True  # False: no change of loop shape, only a parameter shift


EFFECTS: dict[str, Effect] = {
    e.name: e
    for e in (
        Effect(
            "backlash", "nominal",
            (Param("play_arcmin", "free play at zero torque", 0.0, None),),
            "seed 000 eqs. (1)-(3), (12)-(14)",
            "dead zone crossed at zero torque; loop width at zero torque", (),
        ),
        Effect(
            "mesh_stiffness", "nominal",
            (Param("stiffness_Nm_per_arcmin", "torsional stiffness of the mesh", 0.0, None),),
            "seed 004 eq. (8)", "slope of both flanks", (),
        ),
        Effect(
            "friction", "candidate",
            (Param("friction_Nm", "Coulomb friction torque in parallel with the chain", 0.0,
                   None),),
            "Coulomb (stop operator), no seed equation",
            "loading and unloading branches separate by 2 F / K at every torque; twist stuck "
            "for 2 F after each reversal", ("rate",),
        ),
        Effect(
            "stiffness_nonlinearity", "candidate",
            (Param("soft_twist_arcmin", "extra twist of the soft contact layer, fully loaded",
                   0.0, None),
             Param("torque_scale_Nm", "torque over which the contact stiffens (1/e)")),
            "contact stiffening d_s (1 - exp(-|T| / T_s)), no seed equation",
            "flanks curve near the ends of the free play, linear at load", ("amplitude",),
        ),
        Effect(
            "runout", "candidate",
            (Param("internal_um", "ring eccentricity |AO1| (= F_r,int / 2)", 0.0, None),
             Param("internal_phase_deg", "phase of the ring eccentricity", -180.0, 180.0),
             Param("external_um", "pinion eccentricity |BO2| (= F_r,ext / 2)", 0.0, None),
             Param("beta_deg", "initial phase of the pinion eccentricity (eq. 4)", -180.0,
                   180.0)),
            "seed 000 eq. (4) (center distance over the shaft angle), eqs. (3), (7)",
            "free play changes with the locking position: ring term once per crank turn, "
            "pinion term (2 z_ext - z_int) / z_ext times per turn", ("position",),
        ),
        Effect(
            "bearing_clearance", "candidate",
            (Param("extra_play_arcmin", "extra play of the radial clearances", 0.0, None),
             Param("soft_stiffness_Nm_per_arcmin", "stiffness of the soft stage", 0.0, None),
             Param("soft_stage_torque_Nm", "torque at which the soft stage closes", 0.0,
                   None)),
            "seed 000 eqs. (3) and (7) with de = u_r / 2",
            "extra play, then a softer stage up to T_b in series with the mesh", (),
        ),
        Effect(
            "thermal_expansion", "candidate",
            (Param("coefficient_arcmin_per_K", "free play change per kelvin", None, None),),
            "linear expansion of the play with housing temperature, no seed equation",
            "free play changes with temperature", ("temperature",),
        ),
        Effect(
            "torque_sensor_offset", "candidate",
            (Param("offset_Nm", "constant offset of the torque channel", None, None),),
            "sensor model, no seed equation",
            "the free play is crossed at T = offset instead of 0 (the dwell at zero torque "
            "sits on the other flank)", (),
        ),
        Effect(
            "shaft_compliance", "candidate",
            (Param("stiffness_Nm_per_arcmin", "series stiffness of shafts and couplings", 0.0,
                   None),),
            "series spring, no seed equation",
            "flank slope 1 / (1/K + 1/K_s): from one loop indistinguishable from the mesh "
            "stiffness", (), structural=False,
        ),
        Effect(
            "tooth_spacing_error", "candidate",
            (Param("play_change_arcmin_rms", "tooth-to-tooth play change (thickness errors)",
                   0.0, None),),
            "seed 003 (tooth-frequency pitch and thickness errors)",
            "free play changes from tooth pair to tooth pair (high orders over the position); "
            "pitch errors only shift the loop (invisible: the twist zero is free)",
            ("position",),
        ),
    )
}
"""The effect vocabulary, version 1 (docs/run-format.md), in its order."""

CANDIDATES: tuple[str, ...] = tuple(n for n, e in EFFECTS.items() if e.role == "candidate")


def um_to_arcmin(j_t_um: float | np.ndarray, module_mm: float, z_internal: int) -> np.ndarray:
    """Seed 000 eq. (1): circumferential play (um) -> output angle (arcmin)."""
    return EQ1_FACTOR * np.asarray(j_t_um, dtype=float) / (module_mm * z_internal)


def arcmin_to_um(angle_arcmin: float | np.ndarray, module_mm: float, z_internal: int) -> np.ndarray:
    """Inverse of seed 000 eq. (1): output angle (arcmin) -> circumferential play (um)."""
    return np.asarray(angle_arcmin, dtype=float) * module_mm * z_internal / EQ1_FACTOR


# ------------------------------------------------------------------ quasi-static operators


def chain_torque_Nm(torque_Nm: np.ndarray, friction_Nm: float, start_flank: int = -1) -> np.ndarray:
    """Torque carried by the chain with Coulomb friction ``F`` (N*m) in parallel: the stop
    operator ``G_k = clip(G_(k-1), T_k - F, T_k + F)``, the quasi-static limit of a spring
    with Coulomb friction. Before t = 0 the unit came from the ``start_flank`` side
    (run-format.md: preloaded to -T and back), so the friction opposed that motion:
    ``G_0 = T_0 + start_flank F``."""
    torque = np.asarray(torque_Nm, dtype=float)
    if friction_Nm < 0:
        raise AnalysisError(f"friction must be >= 0 N*m, got {friction_Nm}")
    if friction_Nm == 0 or torque.size == 0:
        return torque.copy()
    f = float(friction_Nm)
    values = torque.tolist()
    out = [0.0] * len(values)
    g = values[0] + (f if start_flank > 0 else -f)  # T_0 + start_flank F
    for k, t in enumerate(values):
        lo = t - f
        hi = t + f
        if g < lo:
            g = lo
        elif g > hi:
            g = hi
        out[k] = g
    return np.asarray(out)


def flank_sign(chain_torque: np.ndarray, threshold_Nm: float = 0.0, start_flank: int = -1
               ) -> np.ndarray:
    """The flank in contact (+1/-1) along a chain-torque history (N*m): +1 once the torque
    exceeds ``threshold``, -1 once it is below ``-threshold``, kept in between (the flank rule
    of run-format.md with a noise band; threshold 0 is the pinned rule)."""
    g = np.asarray(chain_torque, dtype=float)
    if start_flank not in (-1, 1):
        raise AnalysisError(f"start_flank must be -1 or +1, got {start_flank!r}")
    event = np.where(g > threshold_Nm, 1.0, np.where(g < -threshold_Nm, -1.0, 0.0))
    index = np.where(event != 0, np.arange(1, g.size + 1), 0)
    last = np.maximum.accumulate(index) if g.size else index
    return np.concatenate(([float(start_flank)], event))[last]


def stiffening_twist_arcmin(chain_torque_abs_Nm: np.ndarray, soft_twist_arcmin: float,
                            torque_scale_Nm: float) -> np.ndarray:
    """Contact stiffening: extra flank twist ``d_s (1 - exp(-|G| / T_s))`` (arcmin); slope at
    zero ``d_s / T_s`` arcmin/N*m, saturating at ``d_s``."""
    if not torque_scale_Nm > 0:
        raise AnalysisError(f"stiffening torque scale must be > 0 N*m, got {torque_scale_Nm}")
    return soft_twist_arcmin * -np.expm1(-np.asarray(chain_torque_abs_Nm) / torque_scale_Nm)


def bearing_soft_twist_arcmin(chain_torque_abs_Nm: np.ndarray, soft_stiffness_Nm_per_arcmin: float,
                              soft_stage_torque_Nm: float) -> np.ndarray:
    """Bearing soft stage: ``min(|G|, T_b) / K_b`` (arcmin), rigid beyond T_b (seed 000 eq. 7
    gives the clearance; the stage's stiffness has no seed equation)."""
    if not soft_stiffness_Nm_per_arcmin > 0:
        raise AnalysisError("bearing soft stiffness must be > 0 N*m/arcmin")
    tau = np.minimum(np.asarray(chain_torque_abs_Nm, dtype=float), soft_stage_torque_Nm)
    return tau / soft_stiffness_Nm_per_arcmin


def runout_center_distance_change_um(
    input_angle_deg: np.ndarray | float, *, center_distance_mm: float, internal_um: float,
    internal_phase_deg: float, external_um: float, beta_deg: float, z_internal: int,
    z_external: int,
) -> np.ndarray:
    """Seed 000 eq. (4): ``|AB| - a`` (um) at the eccentric-shaft angle, with the ring's
    eccentricity |AO1| at phase ``internal_phase_deg`` (0 = eq. 4 as printed) and the pinion's
    |BO2| at ``beta + (z_int - z_ext) theta / z_ext``; ``a = |O1O2|`` the eccentric distance."""
    theta = np.radians(np.asarray(input_angle_deg, dtype=float))
    a_um = 1000.0 * center_distance_mm
    phase = (z_internal - z_external) * theta / z_external + math.radians(beta_deg)
    psi = math.radians(internal_phase_deg)
    x = a_um * np.cos(theta) + external_um * np.cos(phase) + internal_um * math.cos(psi)
    y = a_um * np.sin(theta) + external_um * np.sin(phase) + internal_um * math.sin(psi)
    return np.hypot(x, y) - a_um


def runout_play_change_arcmin(
    input_angle_deg: np.ndarray | float, *, pressure_angle_deg: float, module_mm: float,
    z_internal: int, **eq4: float,
) -> np.ndarray:
    """Free play change of runout (arcmin): seed 000 eq. (3) ``-2 tan(alpha) (|AB| - a)`` of
    the eq. (4) center distance (``eq4``: the keywords of
    :func:`runout_center_distance_change_um` but ``z_internal``), by eq. (1)."""
    delta_um = runout_center_distance_change_um(input_angle_deg, z_internal=z_internal, **eq4)
    play_um = -2.0 * math.tan(math.radians(pressure_angle_deg)) * delta_um
    return um_to_arcmin(play_um, module_mm, z_internal)


def runout_basis(input_angle_deg: np.ndarray | float, z_internal: int, z_external: int,
                 order: float | None = None) -> np.ndarray:
    """First-order form of eq. (4) for fitting: ``|AB| - a ~ e_int cos(theta - psi) +
    e_ext cos(k theta - beta)`` with ``k = (2 z_ext - z_int) / z_ext`` (or ``order``: another
    kind's second term, analysis.diagnosis.kind_physics). Columns
    (cos theta, sin theta, cos k theta, sin k theta), shape (n, 4)."""
    theta = np.radians(np.asarray(input_angle_deg, dtype=float))
    k = (2.0 * z_external - z_internal) / z_external if order is None else float(order)
    return np.stack([np.cos(theta), np.sin(theta), np.cos(k * theta), np.sin(k * theta)],
                    axis=-1)


def runout_harmonic_basis(input_angle_deg: np.ndarray | float, orders: tuple[int, ...] = (2,)
                          ) -> np.ndarray:
    """Higher harmonics of the play change over the crank turn: columns (cos h theta,
    sin h theta) for each order h, shape (n, 2 len(orders)). Eq. (4) in first order holds
    orders 1 and (2 z_ext - z_int) / z_ext; an out-of-round (oval, two-lobed) ring, pinion
    bore or eccentric bearing seat moves the center distance twice per turn, and so does the
    second-order term ``e^2 / (2 a) cos 2 theta`` of eq. (4). The inspected radial runout
    F_r (a total indicator reading) holds every lobe, so the same tolerance budget bounds
    them."""
    theta = np.radians(np.asarray(input_angle_deg, dtype=float))
    cols = []
    for h in orders:
        cols += [np.cos(h * theta), np.sin(h * theta)]
    return np.stack(cols, axis=-1)


def tooth_pair_index(input_angle_deg: np.ndarray | float, z_internal: int) -> np.ndarray:
    """Mesh index of the tooth pair in contact at the eccentric-shaft angle: one pair per
    ``360 / z_internal`` deg (seed 003's tooth frequency); ring tooth = index mod z_int."""
    angle = np.asarray(input_angle_deg, dtype=float)
    return np.floor(angle * z_internal / 360.0 + 1e-9).astype(int)


def tooth_repeat_period_deg(z_internal: int, z_external: int) -> float:
    """Input angle (deg) after which the same ring tooth meshes with the same pinion tooth
    again: the mesh index ``n`` advances by ``z_internal`` per input turn; ring tooth
    ``n mod z_int`` and pinion tooth ``n mod z_ext`` repeat together after ``lcm(z_int,
    z_ext)`` mesh steps, i.e. ``360 lcm / z_int`` deg (one output revolution for 45/40)."""
    return 360.0 * math.lcm(int(z_internal), int(z_external)) / int(z_internal)


def tooth_pair_phase(input_angle_deg: np.ndarray | float, z_internal: int, z_external: int
                     ) -> np.ndarray:
    """Which tooth pair (ring tooth, pinion tooth) meshes: the mesh index of
    :func:`tooth_pair_index` modulo ``lcm(z_int, z_ext)``, i.e. the input angle modulo
    :func:`tooth_repeat_period_deg`. Positions one repeat period apart are repeats of the
    same pair (seed 003: spacing errors belong to teeth, not to input angles)."""
    n = tooth_pair_index(input_angle_deg, z_internal)
    return np.mod(n, math.lcm(int(z_internal), int(z_external)))


# ------------------------------------------------------------------------ the composition


@dataclass(frozen=True)
class LoopParams:
    """Parameters of the composed quasi-static loop; defaults are neutral (effect absent).

    ``play_arcmin`` and ``stiffness_Nm_per_arcmin`` are the nominal model's (backlash,
    mesh_stiffness). ``runout_coeffs_arcmin``: play change on :func:`runout_basis`,
    ``runout_order2_arcmin`` on :func:`runout_harmonic_basis` (twice per turn);
    ``spacing_play_arcmin``: play change per tooth-pair phase (:func:`tooth_pair_phase`);
    thermal (linear per K and quadratic per K^2) relative to ``thermal_reference_C``."""

    play_arcmin: float
    stiffness_Nm_per_arcmin: float
    friction_Nm: float = 0.0
    soft_twist_arcmin: float = 0.0
    stiffening_torque_Nm: float = 1.0
    runout_coeffs_arcmin: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    runout_order2_arcmin: tuple[float, float] = (0.0, 0.0)
    bearing_extra_play_arcmin: float = 0.0
    bearing_compliance_arcmin_per_Nm: float = 0.0
    bearing_stage_torque_Nm: float = 0.0
    thermal_arcmin_per_K: float = 0.0
    thermal_arcmin_per_K2: float = 0.0
    thermal_reference_C: float = 20.0
    torque_offset_Nm: float = 0.0
    shaft_stiffness_Nm_per_arcmin: float = math.inf
    spacing_play_arcmin: dict[int, float] = field(default_factory=dict)
    #: The second runout term's cycles per input turn (None: seed 000 eq. 4's).
    runout_order: float | None = None

    def with_(self, **changes: object) -> LoopParams:
        """A copy with some parameters replaced."""
        return replace(self, **changes)

    @property
    def compliance_arcmin_per_Nm(self) -> float:
        """Series compliance of mesh and shaft: 1/K + 1/K_s (arcmin/N*m)."""
        return 1.0 / self.stiffness_Nm_per_arcmin + 1.0 / self.shaft_stiffness_Nm_per_arcmin


def play_at_arcmin(params: LoopParams, input_angle_deg: float | None, temperature_C:
                   np.ndarray | float | None, z_internal: int, z_external: int
                   ) -> np.ndarray | float:
    """Free play (arcmin) at a position (deg) and temperature (deg C): nominal + bearing +
    runout + thermal + tooth spacing."""
    play: np.ndarray | float = params.play_arcmin + params.bearing_extra_play_arcmin
    if input_angle_deg is not None:
        play = play + float(runout_basis(input_angle_deg, z_internal, z_external,
                                         params.runout_order)
                            @ np.asarray(params.runout_coeffs_arcmin))
        if any(params.runout_order2_arcmin):
            play = play + float(runout_harmonic_basis(input_angle_deg)
                                @ np.asarray(params.runout_order2_arcmin))
        tooth = int(tooth_pair_phase(input_angle_deg, z_internal, z_external))
        play = play + params.spacing_play_arcmin.get(tooth, 0.0)
    if temperature_C is not None and (params.thermal_arcmin_per_K
                                      or params.thermal_arcmin_per_K2):
        dt = np.asarray(temperature_C, dtype=float) - params.thermal_reference_C
        play = play + params.thermal_arcmin_per_K * dt + params.thermal_arcmin_per_K2 * dt**2
    return play


def predict_twist_arcmin(
    params: LoopParams, torque_Nm: np.ndarray, *, input_angle_deg: float | None = None,
    temperature_C: np.ndarray | float | None = None, z_internal: int = 45, z_external: int = 40,
    start_flank: int = -1, threshold_Nm: float = 0.0,
) -> np.ndarray:
    """Twist (arcmin, zero at the centre of the play) of the composed loop along a history of
    measured torques (N*m) of one run (see the module docstring)."""
    torque = np.asarray(torque_Nm, dtype=float) - params.torque_offset_Nm
    g = chain_torque_Nm(torque, params.friction_Nm, start_flank)
    s = flank_sign(g, threshold_Nm, start_flank)
    tau = np.abs(g)
    h = tau * params.compliance_arcmin_per_Nm
    if params.soft_twist_arcmin:
        h = h + stiffening_twist_arcmin(tau, params.soft_twist_arcmin, params.stiffening_torque_Nm)
    if params.bearing_compliance_arcmin_per_Nm:
        h = h + np.minimum(tau, params.bearing_stage_torque_Nm) * (
            params.bearing_compliance_arcmin_per_Nm)
    play = play_at_arcmin(params, input_angle_deg, temperature_C, z_internal, z_external)
    return s * (np.asarray(play) / 2.0 + h)


def cycle_path_Nm(amplitude_Nm: float, points_per_quarter: int = 200) -> np.ndarray:
    """A quasi-static torque path 0 -> +A -> -A -> +A (N*m) for reading a model loop:
    ``points_per_quarter + 1`` points up, then ``2 points_per_quarter`` down, then up."""
    q = np.linspace(0.0, 1.0, points_per_quarter + 1)
    return amplitude_Nm * np.concatenate([q, 1 - 2 * q[1:], -1 + 2 * q[1:]])


def model_lost_motion_arcmin(
    params: LoopParams, rated_torque_Nm: float, pct: float = 3.0, *,
    input_angle_deg: float | None = None, temperature_C: float | None = None,
    z_internal: int = 45, z_external: int = 40, amplitude_Nm: float | None = None,
) -> float:
    """Lost motion of the model loop (arcmin): ``m(+p) - m(-p)`` of the midline of the
    unloading (+A -> -A) and loading (-A -> +A) branches at ``p = pct % of rated`` (the
    definition of analysis.loop), read on :func:`cycle_path_Nm`."""
    if not rated_torque_Nm > 0:
        raise AnalysisError(f"rated torque must be > 0 N*m, got {rated_torque_Nm}")
    amp = amplitude_Nm if amplitude_Nm is not None else rated_torque_Nm
    m = 200
    path = cycle_path_Nm(amp, m)  # indices: 0..m up to +A, m..2m down to -A, 2m..3m up
    twist = predict_twist_arcmin(params, path, input_angle_deg=input_angle_deg,
                                 temperature_C=temperature_C, z_internal=z_internal,
                                 z_external=z_external)
    down = slice(m, 2 * m + 1)  # +A -> -A
    up = slice(2 * m, None)  # -A -> +A
    p = pct / 100.0 * rated_torque_Nm

    def branch(sl: slice, at: float) -> float:
        t, th = path[sl], twist[sl]
        order = np.argsort(t, kind="stable")
        return float(np.interp(at, t[order], th[order]))

    mid_pos = 0.5 * (branch(down, p) + branch(up, p))
    mid_neg = 0.5 * (branch(down, -p) + branch(up, -p))
    return mid_pos - mid_neg


def worst_case_runout_play_arcmin(runout_internal_mm: float, runout_external_mm: float,
                                  pressure_angle_deg: float, module_mm: float,
                                  z_internal: int) -> float:
    """Seed 000 Table 3's runout term ``2 tan(alpha) (F_r,int + F_r,ext) / 2`` (arcmin, eq. 1):
    the largest play increase runout can cause; also the plausibility bound of a fit."""
    j_um = 1000.0 * 2.0 * math.tan(math.radians(pressure_angle_deg)) * (
        runout_internal_mm + runout_external_mm) / 2.0
    return float(um_to_arcmin(j_um, module_mm, z_internal))


def bearing_play_arcmin(clearances_mm: Sequence[float], pressure_angle_deg: float,
                        module_mm: float, z_internal: int) -> float:
    """Seed 000 eqs. (3) + (7) with de = u_r / 2: extra play ``2 tan(alpha) sum(u_r / 2)``
    (arcmin by eq. 1) of the bearings' radial clearances (mm)."""
    j_um = 1000.0 * 2.0 * math.tan(math.radians(pressure_angle_deg)) * sum(
        c / 2.0 for c in clearances_mm)
    return float(um_to_arcmin(j_um, module_mm, z_internal))
