"""Torque/twist hysteresis loop of a gear reducer and its metrics (seed 000, Fig. 6).

The input of the reducer is locked, torque is applied at the output from 0 to +T, back
through 0 to -T and back (one or more cycles, ramps or steps with dwell), and the output
twist is recorded: the "mechanical hysteresis loop" (机械滞后回线) of seed 000 Fig. 6, whose
width is the lost motion (空程回差) that seed 000 eq. (1) relates to the circumferential
backlash ``j_phi = 6.876 j_t / (m Z1)`` arcmin.

Conventions and definitions (all per cycle, then averaged over the cycles):

* Twist (arcmin) increases with torque (N·m). Loading branch: torque increasing; unloading
  branch: torque decreasing (see :mod:`analysis.loop.branches` for the split).
* Branch value ``θ_L(T)``, ``θ_U(T)``: a local straight-line fit of the branch samples in a
  torque window (:func:`analysis.loop.fit.branch_value`); interpolation only. Window
  half-width ``min(|T|/2, 5 % of rated)``, so a window never crosses zero torque.
  Midline ``m(T) = (θ_L(T) + θ_U(T)) / 2``.
* **Lost motion** (arcmin), Nabtesco/Spinea/GB/T at ±3 % of rated, Harmonic Drive at ±4 %
  (:data:`PROFILES`): ``m(+p T_r) - m(-p T_r)``.
* **Backlash** (arcmin): the loop width at zero torque,
  ``θ_U(0+) - θ_L(0-)``: the unloading branch read coming down to zero from the positive
  side, the loading branch read coming up to zero from the negative side (one-sided
  windows of width ``p T_r``). That is how the vendors measure it (return to zero from
  +rated, return to zero from -rated, difference of the twists), and it gives the full
  free play for a dead zone whose flank changes exactly at zero torque; readings within
  4 torque-noise standard deviations of zero are left out of these two fits (they may be
  on the other flank; kept when the rest has no torque spread, i.e. a dwell at zero), the
  fitted lines are read at zero. Aliases: Nabtesco
  "backlash" and its FAQ's "hysteresis loss", Harmonic Drive "hysteresis loss", GB/T
  齿隙; one canonical name here, ``backlash_arcmin``.
* **Torsional stiffness** (N·m/arcmin), secant of the midline between 50 % and 100 % of
  rated torque: ``K+ = (T_r - T_r/2) / (m(T_r) - m(T_r/2))`` and
  ``K- = (T_r/2 - T_r) / (m(-T_r/2) - m(-T_r))``; ``stiffness_Nm_per_arcmin`` is their mean.
  The 100 % point is read with a window reaching down to 95 %.
* **Harmonic Drive K1/K2/K3** (given T1 < T2): on the loading curve away from zero (the
  loading branch for +T, the unloading branch for -T), twist measured from the zero-torque
  midpoint ``θ0 = (θ_L(0-) + θ_U(0+)) / 2``: ``θ(T) = ±(θ_branch(±T) - θ0)``;
  ``K1 = T1 / θ(T1)``, ``K2 = (T2 - T1) / (θ(T2) - θ(T1))``,
  ``K3 = (T3 - T2) / (θ(T3) - θ(T2))`` with ``T3`` the largest torque every cycle reaches on
  both sides. Branch values here use one-sided windows on the zero side of each torque
  (the segments end at T1, T2: a kink there does not bias them). Each K is the mean of
  the + and - sides. A play shows up in K1 (``θ(T1)`` includes half of it).
* **Loop area** (J): ``∮ T dθ`` over the cycle, θ in rad (:func:`analysis.loop.area.loop_area_J`),
  the energy dissipated per cycle; a pure dead zone has zero area (its play is crossed at
  zero torque); Coulomb friction ``T_f`` on a spring ``K`` driven to ``±T_m`` gives the
  parallelogram ``4 T_f (T_m - T_f) / K``.
* **Torque offset** (N·m): the torque at which the loop crosses its horizontal centre.
  The centre twist is ``θc = (m(+T3) + m(-T3)) / 2``; the offset is the mean of the torques
  at which the loading and the unloading paths cross ``θc``. For a loop with free play,
  ``θc`` falls inside the play, which each branch crosses at its flank-change torque, so
  the offset is where the dead zone sits on the torque axis (a torque sensor zero error).
  For a loop without play the vertical position of the loop is not identifiable (shift
  and offset look the same) and the offset reads 0.

Uncertainties are standard uncertainties: the residual scatter of the twist about each
local fit, the encoder resolution ``q/sqrt(12)`` and the torque resolution through the
local slope, propagated to each metric to first order; over several cycles the mean's
uncertainty ``sqrt(Σu_i²/n² + s²/n)`` also includes the cycle-to-cycle spread ``s``
(conservative: the spread holds the noise once more). A cycle that lacks a metric is
left out of that metric's mean (``LoopResult.cycle_values`` shows NaN for it).
A metric the run cannot give (torque not reached, no samples near a point) is left out
of ``metrics`` and explained in ``errors``; the other metrics are still computed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from analysis.errors import AnalysisError, MetricUnavailable
from analysis.loop.area import loop_area_J
from analysis.loop.branches import (
    Branches,
    at_measured_tips,
    default_threshold_Nm,
    split_branches,
    white_noise_std,
)
from analysis.loop.fit import (
    BranchPass,
    PointEstimate,
    Resolution,
    branch_value,
    torque_at_twist,
)

__all__ = [
    "PROFILES",
    "Branches",
    "LoopResult",
    "Metric",
    "analyse_loop",
    "branch_midline",
    "loop_curves",
    "split_branches",
    "twist_arcmin",
]

#: Lost-motion torque, percent of rated, by vendor/standard.
PROFILES: dict[str, float] = {"nabtesco": 3.0, "harmonic-drive": 4.0, "gbt": 3.0, "spinea": 3.0}

ARCMIN_PER_DEG = 60.0
#: Half-width of a branch window, fraction of rated torque (capped at half the torque).
WINDOW_FRACTION = 0.05
#: Tolerance on reaching a torque, fraction of rated (plus the torque resolution).
REACH_FRACTION = 1e-3
#: Half-width, in torque-noise standard deviations, of the band around zero torque left
#: out of the backlash fits (a reading there may be on the other flank).
ZERO_GAP_SIGMAS = 4.0

UNITS = {
    "lost_motion_arcmin": "arcmin",
    "backlash_arcmin": "arcmin",
    "stiffness_Nm_per_arcmin": "N·m/arcmin",
    "stiffness_pos_Nm_per_arcmin": "N·m/arcmin",
    "stiffness_neg_Nm_per_arcmin": "N·m/arcmin",
    "loop_area_J": "J",
    "torque_offset_Nm": "N·m",
    "hd_K1_Nm_per_arcmin": "N·m/arcmin",
    "hd_K2_Nm_per_arcmin": "N·m/arcmin",
    "hd_K3_Nm_per_arcmin": "N·m/arcmin",
}


def twist_arcmin(
    output_angle_deg: np.ndarray,
    input_angle_deg: np.ndarray | None = None,
    ratio: float | None = None,
) -> np.ndarray:
    """Twist of the reducer in arcmin: ``60 (output - input / ratio)`` with angles in degrees.

    With the input locked (``input_angle_deg`` None) the twist is the output angle alone.
    ``ratio`` is the reduction ratio (input turns per output turn).
    """
    out = np.asarray(output_angle_deg, dtype=float)
    if input_angle_deg is None:
        return out * ARCMIN_PER_DEG
    if ratio is None or not np.isfinite(ratio) or ratio == 0:
        raise AnalysisError(f"input angles need a finite, non-zero reduction ratio, got {ratio}")
    inp = np.asarray(input_angle_deg, dtype=float)
    if inp.shape != out.shape:
        raise AnalysisError(f"input angles {inp.shape} and output angles {out.shape} differ")
    return (out - inp / ratio) * ARCMIN_PER_DEG


@dataclass(frozen=True)
class Metric:
    """A metric value, its standard uncertainty (same unit) and the unit."""

    value: float
    uncertainty: float
    unit: str


@dataclass(frozen=True, eq=False)
class LoopResult:
    """Metrics of a run (mean over cycles), why the missing ones are missing, the branches.

    ``cycle_values[name]`` holds the per-cycle values (NaN where a cycle lacks it).
    """

    metrics: dict[str, Metric]
    errors: dict[str, str]
    branches: Branches
    lost_motion_pct: float
    n_cycles: int
    cycle_values: dict[str, tuple[float, ...]] = field(default_factory=dict)

    def to_dict(self) -> dict:
        """Plain dict: ``{name: value, ..., "uncertainty": {...}, "units": {...}, "errors"}``."""
        out: dict = {name: m.value for name, m in self.metrics.items()}
        out["uncertainty"] = {name: m.uncertainty for name, m in self.metrics.items()}
        out["units"] = {name: m.unit for name, m in self.metrics.items()}
        out["errors"] = dict(self.errors)
        out["lost_motion_pct"] = self.lost_motion_pct
        out["n_cycles"] = self.n_cycles
        return out


# ----------------------------------------------------------------------------- per cycle


class _Cycle:
    """Branch values of one cycle, cached; failures cached as MetricUnavailable."""

    def __init__(self, torque, twist, branches: Branches, c: int, tol: float, res: Resolution):
        load, unload = branches.passes[c]
        self.torque, self.twist = torque, twist
        self.slices = {"loading": branches.slices(load), "unloading": branches.slices(unload)}
        # A turning sample ends one segment and starts the next; the fits give it to the
        # segment it ends only, so that the two branches of a cycle share no sample.
        self.passes = {
            name: BranchPass(
                torque, twist, sl, 1 if name == "loading" else -1, [s.start > 0 for s in sl]
            )
            for name, sl in self.slices.items()
        }
        self.tol, self.res = tol, res
        self._cache: dict[tuple, PointEstimate | MetricUnavailable] = {}

    def value(
        self, branch: str, at: float, lo: float, hi: float, exclude: float = 0.0
    ) -> PointEstimate:
        key = (branch, at, lo, hi, exclude)
        if key not in self._cache:
            try:
                self._cache[key] = branch_value(
                    self.passes[branch], at, lo, hi,
                    tol_Nm=self.tol, resolution=self.res, label=branch, exclude_Nm=exclude,
                )  # fmt: skip
            except MetricUnavailable as exc:
                self._cache[key] = exc
        got = self._cache[key]
        if isinstance(got, MetricUnavailable):
            raise got
        return got

    def centred(self, branch: str, at: float, rated: float) -> PointEstimate:
        """Value in a window centred on ``at`` (half-width min(|at|/2, 5 % rated))."""
        w = min(0.5 * abs(at), WINDOW_FRACTION * rated)
        return self.value(branch, at, at - w, at + w)

    def toward_zero(self, branch: str, at: float, width: float) -> PointEstimate:
        """Value in a one-sided window of ``width`` on the zero side of ``at``."""
        lo, hi = (at - width, at) if at > 0 else (at, at + width)
        return self.value(branch, at, lo, hi)

    def midline(self, at: float, rated: float) -> tuple[float, float]:
        a, b = self.centred("loading", at, rated), self.centred("unloading", at, rated)
        return 0.5 * (a.value + b.value), 0.5 * np.hypot(a.uncertainty, b.uncertainty)


def _ratio(num: float, den: float, u_den: float, what: str) -> tuple[float, float]:
    if den == 0 or not np.isfinite(den):
        raise MetricUnavailable(f"the twist does not change over {what}")
    k = num / den
    return k, abs(k) * u_den / abs(den)


@dataclass(frozen=True)
class _Setup:
    rated: float
    p_Nm: float
    hd: tuple[float, float] | None
    T3: float
    twist_sigma: float
    torque_sigma: float
    torque_noise: float
    branches: Branches


def _lost_motion(cy: _Cycle, s: _Setup) -> dict[str, tuple[float, float]]:
    mp, up = cy.midline(+s.p_Nm, s.rated)
    mn, un = cy.midline(-s.p_Nm, s.rated)
    return {"lost_motion_arcmin": (mp - mn, float(np.hypot(up, un)))}


def _zero_points(cy: _Cycle, s: _Setup) -> tuple[PointEstimate, PointEstimate]:
    """Loading branch at 0- and unloading branch at 0+, leaving out the torque-noise band."""
    gap = min(ZERO_GAP_SIGMAS * s.torque_noise, 0.5 * s.p_Nm)
    lo = cy.value("loading", 0.0, -s.p_Nm, 0.0, gap)
    up = cy.value("unloading", 0.0, 0.0, s.p_Nm, gap)
    return lo, up


def _backlash(cy: _Cycle, s: _Setup) -> dict[str, tuple[float, float]]:
    lo, up = _zero_points(cy, s)
    u = float(np.hypot(lo.uncertainty, up.uncertainty))
    return {"backlash_arcmin": (up.value - lo.value, u)}


def _stiffness_side(cy: _Cycle, s: _Setup, sign: float) -> tuple[float, float]:
    m100, u100 = cy.midline(sign * s.rated, s.rated)
    m50, u50 = cy.midline(sign * 0.5 * s.rated, s.rated)
    what = f"{sign * 0.5 * s.rated:+.4g}..{sign * s.rated:+.4g} N·m"
    return _ratio(0.5 * s.rated, sign * (m100 - m50), float(np.hypot(u100, u50)), what)


def _stiffness_pos(cy: _Cycle, s: _Setup) -> dict[str, tuple[float, float]]:
    return {"stiffness_pos_Nm_per_arcmin": _stiffness_side(cy, s, +1.0)}


def _stiffness_neg(cy: _Cycle, s: _Setup) -> dict[str, tuple[float, float]]:
    return {"stiffness_neg_Nm_per_arcmin": _stiffness_side(cy, s, -1.0)}


def _stiffness_mean(cy: _Cycle, s: _Setup) -> dict[str, tuple[float, float]]:
    kp, up = _stiffness_side(cy, s, +1.0)
    kn, un = _stiffness_side(cy, s, -1.0)
    return {"stiffness_Nm_per_arcmin": (0.5 * (kp + kn), 0.5 * float(np.hypot(up, un)))}


def _hd_side(cy: _Cycle, s: _Setup, sign: float, which: int) -> tuple[float, float]:
    """K_which (1, 2 or 3) on one side, N·m/arcmin, with its uncertainty."""
    assert s.hd is not None
    T1, T2 = s.hd
    branch = "loading" if sign > 0 else "unloading"

    def theta(T: float) -> PointEstimate:
        w = min(0.5 * T, WINDOW_FRACTION * s.rated)
        return cy.toward_zero(branch, sign * T, w)

    if which == 1:
        lo, up = _zero_points(cy, s)
        th0 = 0.5 * (lo.value + up.value)
        u0 = 0.5 * float(np.hypot(lo.uncertainty, up.uncertainty))
        p1 = theta(T1)
        return _ratio(T1, sign * (p1.value - th0), float(np.hypot(p1.uncertainty, u0)), "0..T1")
    if which == 2:
        a, b, dT, what = theta(T1), theta(T2), T2 - T1, "T1..T2"
    else:
        if s.T3 <= T2:
            raise MetricUnavailable(f"no cycle reaches more than T2 = {T2:.4g} N·m on both sides")
        a, b, dT, what = theta(T2), theta(s.T3), s.T3 - T2, f"T2..{s.T3:.4g} N·m"
    u = float(np.hypot(a.uncertainty, b.uncertainty))
    return _ratio(dT, sign * (b.value - a.value), u, what)


def _hd(which: int) -> Callable[[_Cycle, _Setup], dict[str, tuple[float, float]]]:
    def compute(cy: _Cycle, s: _Setup) -> dict[str, tuple[float, float]]:
        kp, up = _hd_side(cy, s, +1.0, which)
        kn, un = _hd_side(cy, s, -1.0, which)
        return {f"hd_K{which}_Nm_per_arcmin": (0.5 * (kp + kn), 0.5 * float(np.hypot(up, un)))}

    return compute


def _area(cy: _Cycle, s: _Setup) -> dict[str, tuple[float, float]]:
    path = cy.slices["unloading"] + cy.slices["loading"]
    a, u = loop_area_J(
        cy.torque, cy.twist, path, twist_sigma_arcmin=s.twist_sigma, torque_sigma_Nm=s.torque_sigma
    )
    return {"loop_area_J": (a, u)}


def _offset(cy: _Cycle, s: _Setup) -> dict[str, tuple[float, float]]:
    if not s.T3 > 0:
        raise MetricUnavailable("the cycles do not reach a torque of both signs")
    w = min(0.5 * s.T3, WINDOW_FRACTION * s.rated)
    hi = [cy.toward_zero(b, +s.T3, w) for b in ("loading", "unloading")]
    lo = [cy.toward_zero(b, -s.T3, w) for b in ("loading", "unloading")]
    centre = 0.25 * sum(p.value for p in hi + lo)
    u_centre = 0.25 * float(np.sqrt(sum(p.uncertainty**2 for p in hi + lo)))
    torques, u2 = [], 0.0
    for branch in ("loading", "unloading"):
        sl = cy.slices[branch]
        t, spread, n, step = torque_at_twist(cy.torque, cy.twist, sl, centre)
        shift = 0.0
        if u_centre > 0:
            t_hi = torque_at_twist(cy.torque, cy.twist, sl, centre + u_centre)[0]
            t_lo = torque_at_twist(cy.torque, cy.twist, sl, centre - u_centre)[0]
            shift = 0.5 * abs(t_hi - t_lo)
        torques.append(t)
        u2 += max(spread, s.torque_sigma) ** 2 / n + step**2 / 12.0 + shift**2
    return {"torque_offset_Nm": (0.5 * (torques[0] + torques[1]), 0.5 * float(np.sqrt(u2)))}


def _combine(values: list[tuple[float, float]], unit: str) -> Metric:
    v = np.array([a for a, _ in values])
    u = np.array([b for _, b in values])
    n = v.size
    u2 = float(u @ u) / n**2
    if n > 1:
        u2 += float(v.var(ddof=1)) / n
    return Metric(value=float(v.mean()), uncertainty=float(np.sqrt(u2)), unit=unit)


# ----------------------------------------------------------------------------- public


MAX_MAGNITUDE = 1e50
"""The largest magnitude of a time (s), torque (N·m) or twist (arcmin) the metrics take: their
sums of squares stay finite (no measured value comes near it)."""


def _validate(t_s, torque_Nm, twist) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    arrays = {}
    for name, a in (("t_s", t_s), ("torque_Nm", torque_Nm), ("twist_arcmin", twist)):
        x = np.asarray(a, dtype=float)
        if x.ndim != 1:
            raise AnalysisError(f"{name} must be 1-D, got shape {x.shape}")
        bad = np.flatnonzero(~np.isfinite(x))
        if bad.size:
            raise AnalysisError(f"{name}[{bad[0]}] is not a finite number ({x[bad[0]]})")
        bad = np.flatnonzero(np.abs(x) > MAX_MAGNITUDE)
        if bad.size:
            raise AnalysisError(f"{name}[{bad[0]}] is {x[bad[0]]:g}, beyond {MAX_MAGNITUDE:g}: "
                                "no measured value (its square overflows)")
        arrays[name] = x
    n = {k: v.size for k, v in arrays.items()}
    if len(set(n.values())) != 1:
        raise AnalysisError(f"arrays differ in length: {n}")
    if n["t_s"] < 3:
        raise AnalysisError(f"a loop needs at least 3 samples, got {n['t_s']}")
    back = np.flatnonzero(np.diff(arrays["t_s"]) < 0)
    if back.size:
        raise AnalysisError(f"t_s goes back in time at sample {back[0] + 1}")
    return arrays["t_s"], arrays["torque_Nm"], arrays["twist_arcmin"]


def _reach_T3(torque: np.ndarray, branches: Branches) -> float:
    """The largest torque that every cycle reaches on both sides (0 if none)."""
    reach = []
    for load, unload in branches.passes:
        hi = max(float(torque[s].max()) for s in branches.slices(load))
        lo = min(float(torque[s].min()) for s in branches.slices(unload))
        reach.append(min(hi, -lo))
    return max(0.0, min(reach)) if reach else 0.0


def _branches(torque: np.ndarray, threshold_Nm: float, command_Nm: np.ndarray | None):
    """Branches of the run: from the torque command when one is recorded for every sample
    and it moves (noise-free, so 1 % of its amplitude marks a reversal; each turn then moved
    to the measured torque's extremum next to it, the loop's tip), else from the measured
    torque with ``threshold_Nm``."""
    if command_Nm is not None:
        cmd = np.asarray(command_Nm, dtype=float)
        if cmd.shape == torque.shape and np.all(np.isfinite(cmd)):
            span = float(np.max(cmd) - np.min(cmd)) if cmd.size else 0.0
            if span > 2.0 * threshold_Nm:
                return at_measured_tips(
                    split_branches(cmd, threshold_Nm=max(0.005 * span, 1e-9)), torque)
    return split_branches(torque, threshold_Nm=threshold_Nm)


def analyse_loop(
    t_s: np.ndarray,
    torque_Nm: np.ndarray,
    twist_arcmin: np.ndarray,
    *,
    rated_torque_Nm: float,
    lost_motion_pct: float = 3.0,
    twist_resolution_arcmin: float = 0.0,
    torque_resolution_Nm: float = 0.0,
    hd_T1_Nm: float | None = None,
    hd_T2_Nm: float | None = None,
    threshold_Nm: float | None = None,
    command_Nm: np.ndarray | None = None,
) -> LoopResult:
    """Metrics of a hysteresis run (see the module docstring for each definition).

    ``t_s`` (s, non-decreasing), ``torque_Nm`` (N·m) and ``twist_arcmin`` (arcmin, e.g.
    from :func:`twist_arcmin`) are the samples in time order. ``rated_torque_Nm`` sets the
    lost-motion and stiffness torques; ``lost_motion_pct`` the lost-motion torque in percent
    of rated (:data:`PROFILES`); the resolutions (one count / one step) enter the
    uncertainties; ``hd_T1_Nm < hd_T2_Nm`` ask for the Harmonic Drive K1/K2/K3;
    ``threshold_Nm`` overrides the reversal threshold of :func:`split_branches`.
    ``command_Nm`` (N·m, the rig's torque command per sample, when recorded) decides which
    samples load and which unload: a transient of the measured torque (the flank impact at
    the play crossing dips it by several % of the amplitude) is not a reversal of the loading.
    """
    _, torque, twist = _validate(t_s, torque_Nm, twist_arcmin)
    if not (np.isfinite(rated_torque_Nm) and rated_torque_Nm > 0):
        raise AnalysisError(f"rated torque must be > 0 N·m, got {rated_torque_Nm}")
    if not 0 < lost_motion_pct < 50:
        raise AnalysisError(f"lost-motion torque must be 0..50 % of rated, got {lost_motion_pct}")
    if twist_resolution_arcmin < 0 or torque_resolution_Nm < 0:
        raise AnalysisError("resolutions must be >= 0")
    hd: tuple[float, float] | None = None
    if hd_T1_Nm is not None or hd_T2_Nm is not None:
        if hd_T1_Nm is None or hd_T2_Nm is None or not 0 < hd_T1_Nm < hd_T2_Nm:
            raise AnalysisError(
                f"Harmonic Drive K1/K2/K3 need 0 < T1 < T2, got T1={hd_T1_Nm}, T2={hd_T2_Nm}"
            )
        hd = (float(hd_T1_Nm), float(hd_T2_Nm))

    twist_noise = white_noise_std(twist)
    torque_noise = white_noise_std(torque)
    if threshold_Nm is None:
        threshold_Nm = default_threshold_Nm(torque, torque_resolution_Nm, torque_noise)
    branches = _branches(torque, threshold_Nm, command_Nm)
    setup = _Setup(
        rated=float(rated_torque_Nm),
        p_Nm=lost_motion_pct / 100.0 * rated_torque_Nm,
        hd=hd,
        T3=_reach_T3(torque, branches),
        twist_sigma=float(np.hypot(twist_noise, twist_resolution_arcmin / np.sqrt(12.0))),
        torque_sigma=float(np.hypot(torque_noise, torque_resolution_Nm / np.sqrt(12.0))),
        torque_noise=torque_noise,
        branches=branches,
    )
    res = Resolution(twist_resolution_arcmin, torque_resolution_Nm, twist_noise)
    # a torque counts as reached within its resolution, 0.1 % of rated, or 4 noise
    # standard deviations (a dwell at +T read by a noisy sensor is at +T)
    tol = max(torque_resolution_Nm, REACH_FRACTION * rated_torque_Nm, 4.0 * torque_noise)

    rated, p = setup.rated, setup.p_Nm
    jobs: list[tuple[tuple[str, ...], Callable, str]] = [
        (("lost_motion_arcmin",), _lost_motion,
         f"lost motion needs ±{p:.4g} N·m ({lost_motion_pct:g} % of rated) on both branches"),
        (("backlash_arcmin",), _backlash, "backlash needs both branches through 0 N·m"),
        (("stiffness_Nm_per_arcmin",), _stiffness_mean,
         f"stiffness needs ±{rated:.4g} N·m (100 % of rated)"),
        (("stiffness_pos_Nm_per_arcmin",), _stiffness_pos,
         f"stiffness (+ side) needs +{rated:.4g} N·m (100 % of rated)"),
        (("stiffness_neg_Nm_per_arcmin",), _stiffness_neg,
         f"stiffness (- side) needs -{rated:.4g} N·m (100 % of rated)"),
        (("loop_area_J",), _area, "loop area needs a closed cycle"),
        (("torque_offset_Nm",), _offset, "torque offset needs a closed cycle"),
    ]  # fmt: skip
    if hd is not None:
        for k, need in ((1, f"±{hd[0]:.4g} N·m"), (2, f"±{hd[1]:.4g} N·m"),
                        (3, f"more than ±{hd[1]:.4g} N·m")):  # fmt: skip
            jobs.append(((f"hd_K{k}_Nm_per_arcmin",), _hd(k), f"Harmonic Drive K{k} needs {need}"))

    cycles = [_Cycle(torque, twist, branches, c, tol, res) for c in range(branches.n_cycles)]
    reach = f"the run reaches {float(torque.max()):+.3g}/{float(torque.min()):+.3g} N·m"
    metrics: dict[str, Metric] = {}
    errors: dict[str, str] = {}
    cycle_values: dict[str, tuple[float, ...]] = {}
    for names, compute, need in jobs:
        got: dict[str, list[tuple[float, float]]] = {name: [] for name in names}
        per_cycle: dict[str, list[float]] = {name: [] for name in names}
        why = "the run has no complete cycle (no loading and unloading pass)"
        for cy in cycles:
            try:
                out = compute(cy, setup)
            except MetricUnavailable as exc:
                why = str(exc)
                for name in names:
                    per_cycle[name].append(float("nan"))
                continue
            for name in names:
                got[name].append(out[name])
                per_cycle[name].append(out[name][0])
        for name in names:
            cycle_values[name] = tuple(per_cycle[name])
            if got[name]:
                metrics[name] = _combine(got[name], UNITS[name])
            else:
                errors[name] = f"{need}; {reach}: {why}"
    return LoopResult(
        metrics=metrics,
        errors=errors,
        branches=branches,
        lost_motion_pct=float(lost_motion_pct),
        n_cycles=branches.n_cycles,
        cycle_values=cycle_values,
    )


def loop_curves(
    result_or_branches: LoopResult | Branches,
    torque_Nm: np.ndarray,
    twist_arcmin: np.ndarray,
    *,
    n_bins: int = 200,
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Loading, unloading and midline curves for plotting: binned means over all cycles.

    Returns ``{"loading": (torque_Nm, twist_arcmin), "unloading": ..., "midline": ...}``,
    torque at the bin centres (bins symmetric about 0 N·m, zero is a bin edge), only the
    bins a branch has samples in (the midline: bins both have).
    """
    br = result_or_branches.branches if isinstance(result_or_branches, LoopResult) else (
        result_or_branches
    )
    torque = np.asarray(torque_Nm, dtype=float)
    twist = np.asarray(twist_arcmin, dtype=float)
    if torque.shape != (br.n_samples,) or twist.shape != torque.shape:
        raise AnalysisError(
            f"torque {torque.shape} and twist {twist.shape} do not match the branches "
            f"({br.n_samples} samples)"
        )
    half = max(1, n_bins // 2)
    top = float(np.abs(torque).max()) or 1.0
    edges = np.linspace(-top, top, 2 * half + 1)
    centres = 0.5 * (edges[1:] + edges[:-1])
    idx = np.clip(np.searchsorted(edges, torque, side="right") - 1, 0, 2 * half - 1)
    direction = br.sample_direction()
    means = {}
    for name, sign in (("loading", 1), ("unloading", -1)):
        m = direction == sign
        count = np.bincount(idx[m], minlength=2 * half)
        total = np.bincount(idx[m], weights=twist[m], minlength=2 * half)
        with np.errstate(invalid="ignore", divide="ignore"):
            means[name] = total / count
    out = {}
    for name in ("loading", "unloading"):
        ok = np.isfinite(means[name])
        out[name] = (centres[ok], means[name][ok])
    both = np.isfinite(means["loading"]) & np.isfinite(means["unloading"])
    out["midline"] = (centres[both], 0.5 * (means["loading"][both] + means["unloading"][both]))
    return out


def branch_midline(
    result_or_branches: LoopResult | Branches,
    torque_Nm: np.ndarray,
    twist_arcmin: np.ndarray,
    *,
    n_bins: int = 200,
) -> tuple[np.ndarray, np.ndarray]:
    """The loop's midline ``(torque_Nm, twist_arcmin)``, binned as in :func:`loop_curves`."""
    return loop_curves(result_or_branches, torque_Nm, twist_arcmin, n_bins=n_bins)["midline"]
