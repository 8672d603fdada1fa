"""How far to trust a verdict: the diagnosis on labelled campaigns like this one (issue 20, 3).

``rig validate-diagnosis --like CAMPAIGN`` (and ``rig diagnose --self-check N`` through
:func:`self_check`) makes N labelled campaigns with the campaign's own design and diagnoses
them blind:

- the design is replayed: each run's measured torque channel (smoothed, and zero within
  three noise sigmas of zero: the sensor's noise is no torque on the unit) is the drive
  command of the time-domain plant (simulators/plant) on the run's own time base (the
  plant steps on a uniform grid at the median sample interval and is read at the measured
  sample times, gaps and jitter included), at the run's eccentric-shaft position and
  temperature, with the campaign's unit data; the torque channel written is the measured
  one (plus an effect of the reading, if that is the withheld effect);
- the measuring system is the campaign's own, estimated from its data: the twist noise from
  robust second differences (:func:`analysis.loop.branches.white_noise_std`), the encoder
  and ADC resolution from the data's grid (:func:`analysis.diagnosis.data.resolution_of`),
  the torque channel's lag behind the twist from the loaded flanks
  (:func:`analysis.channels.lag.channel_lag_samples`);
- each in-vocabulary effect this design can show is withheld in turn at a size of a few
  (2-8, log-uniform) times the measured twist noise in twist terms (:func:`effect_params`;
  an effect the design cannot show, such as thermal expansion at one temperature, is left
  out and named), plus null campaigns (one in five);
- the confusion: per effect right/wrong, the false alarms on the nulls, the smallest size
  (in noise multiples and the effect's own parameters) found per effect.

Nothing here reads labels of the source campaign; the generated campaigns' labels stay in
this module.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rig.core.errors import RigError
from rig.runformat import Campaign, Run

IN_VOCABULARY = ("friction", "stiffness_nonlinearity", "runout", "bearing_clearance",
                 "thermal_expansion", "torque_sensor_offset", "shaft_compliance",
                 "tooth_spacing_error")
#: Withheld effects at this many times the measured twist noise (log-uniform between).
NOISE_MULTIPLES = (2.0, 8.0)
#: One case in this many is a null campaign.
NULL_EVERY = 5
#: Campaign-level effects need this spread of the design (K of temperature; positions).
MIN_TEMPERATURE_SPREAD_K = 2.0


@dataclass(frozen=True)
class RunDesign:
    """One run's design: what the campaign folder says and the measured torque history."""

    run_id: str
    t_s: np.ndarray
    torque_Nm: np.ndarray
    temperature_C: np.ndarray | None
    input_angle_deg: float
    test: dict[str, Any]
    sensors: dict[str, Any]


@dataclass(frozen=True)
class Design:
    """A campaign's design and its measured measuring system."""

    name: str
    unit: dict[str, Any]
    runs: list[RunDesign]
    twist_noise_arcmin: float  # robust second differences, median over runs
    twist_resolution_deg: float  # the output encoder's count (0: not visibly quantised)
    torque_resolution_Nm: float  # the ADC's count (0: not visibly quantised)
    torque_lag_s: float  # the torque channel behind the twist (s, >= 0 is behind)
    amplitude_Nm: float
    extra: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        """The estimates (JSON-ready)."""
        temps = [float(np.nanmean(r.temperature_C)) for r in self.runs
                 if r.temperature_C is not None]
        return {"runs": len(self.runs),
                "samples": [int(r.t_s.size) for r in self.runs],
                "positions_deg": [r.input_angle_deg for r in self.runs],
                "temperatures_C": [round(t, 2) for t in temps],
                "amplitude_Nm": self.amplitude_Nm,
                "twist_noise_arcsec": self.twist_noise_arcmin * 60.0,
                "twist_resolution_arcsec": self.twist_resolution_deg * 3600.0,
                "torque_resolution_Nm": self.torque_resolution_Nm,
                "torque_lag_s": self.torque_lag_s}


def _campaign(campaign: Campaign | str | Path) -> Campaign:
    if isinstance(campaign, Campaign):
        return campaign
    from rig.runformat import read_run_or_campaign

    try:
        return read_run_or_campaign(campaign)
    except (OSError, ValueError) as exc:
        raise RigError(f"{campaign}: {exc}") from exc


def design_of(campaign: Campaign | str | Path) -> Design:
    """The campaign's design and measuring system, estimated from its data alone."""
    from analysis.channels.lag import channel_lag_samples
    from analysis.diagnosis.data import resolution_of
    from analysis.loop.branches import white_noise_std
    from rig.results.diagnose import run_input

    camp = _campaign(campaign)
    if not camp.runs:
        raise RigError(f"{camp.name}: no runs to take a design from")
    runs, noise, lags, twist_res, torque_res = [], [], [], [], []
    amplitude = 0.0
    for run in camp.runs:
        ri = run_input(run)
        if ri.input_angle_deg is None:
            raise RigError(f"{camp.name}/{run.run_id}: no eccentric-shaft position "
                           "(test.input_angle_deg or an input_angle_deg column) to replay")
        t = np.asarray(run.t_s, dtype=float)
        twist = np.asarray(ri.twist_arcmin, dtype=float)
        res_deg = resolution_of(run.output_angle_deg)
        # a reading that stays within a count has at least the count's own noise q / sqrt(12)
        sigma = max(white_noise_std(twist), res_deg * 60.0 / math.sqrt(12.0))
        noise.append(sigma)
        dt = float(np.median(np.diff(t)))
        lags.append(-channel_lag_samples(t, ri.torque_Nm, twist, max(sigma, 1e-9)) * dt)
        twist_res.append(res_deg)
        torque_res.append(resolution_of(run.torque_Nm))
        amplitude = max(amplitude, float(np.percentile(np.abs(run.torque_Nm), 99.5)))
        temp = None if ri.temperature_C is None else np.asarray(ri.temperature_C, dtype=float)
        runs.append(RunDesign(run.run_id, t, np.asarray(run.torque_Nm, dtype=float), temp,
                              float(ri.input_angle_deg), dict(run.test), dict(run.sensors)))
    counts = camp.runs[0].sensors.get("encoder_counts_per_rev")
    enc = float(np.median(twist_res))
    sigma = float(np.median(noise))
    if enc == 0.0 and counts:
        enc = 360.0 / float(counts)
    if sigma <= 0.0:
        sigma = max(enc * 60.0 / math.sqrt(12.0), 1e-6)
    return Design(camp.name, dict(camp.runs[0].unit), runs, sigma, enc,
                  float(np.median(torque_res)), float(np.median(lags)), amplitude)


def _plant_config(design: Design):
    from simulators.plant.config import load_plant_config

    try:
        return load_plant_config().nominal().with_changes(
            unit=design.unit, rig={"drive_time_constant_s": 1e-5, "step_s": 0.001})
    except ValueError as exc:
        raise RigError(f"{design.name}: the simulated plant cannot make campaigns with this "
                       f"unit ({exc})") from exc


def _play_spread_arcmin(design: Design, kind: str, params: dict[str, Any]) -> float:
    """The spread (std over the runs, arcmin) of the free play the design shows with
    ``kind`` at ``params``: what runout, tooth spacing and thermal play vary between runs."""
    from simulators.plant.model import PlantModel

    config = _plant_config(design).with_effect(kind, **params)
    plays = []
    for r in design.runs:
        temp = float(np.nanmean(r.temperature_C)) if r.temperature_C is not None else 20.0
        model = PlantModel(config.with_changes(
            rig={"initial_input_angle_deg": r.input_angle_deg},
            housing={"initial_C": temp, "ambient_C": temp}))
        plays.append(model.geometry.arcmin_from_um(model.mesh_play_um()))
    return float(np.std(plays))


def effect_params(design: Design, kind: str, multiple: float,
                  rng: np.random.Generator) -> dict[str, Any] | None:
    """The plant parameters of ``kind`` whose twist signature is ``multiple`` times the
    design's twist noise ``s = m sigma`` (arcmin), or None when this design cannot show it.

    With K the unit's nominal stiffness (N*m/arcmin) and A the torque amplitude: friction
    shifts each flank by F/K (F = s K, a Coulomb stop); an offset shifts the loop by o/K
    (o = +-s K); a shaft adds A/K_s at the amplitude (K_s = A / 2s); a soft contact layer
    adds d = 2s over 0.3 A; a bearing stage adds t_b/K_b = 2s up to t_b = 0.15 A; runout,
    tooth spacing and thermal expansion change the play between runs, each flank by half of
    it: their size is scaled until the spread of the play over the design's runs is 2s."""
    from simulators.plant.geometry import reference_nominal

    s = multiple * design.twist_noise_arcmin
    k = float(reference_nominal(design.unit).stiffness_Nm_per_arcmin)
    a = design.amplitude_Nm
    sign = float(rng.choice([-1.0, 1.0]))
    if kind == "friction":
        return {"model": "dahl", "coulomb_torque_Nm": s * k,
                "rest_stiffness_Nm_per_arcmin": 3000.0}
    if kind == "torque_sensor_offset":
        return {"offset_Nm": sign * s * k}
    if kind == "shaft_compliance":
        return {"stiffness_Nm_per_arcmin": a / (2.0 * s)}
    if kind == "stiffness_nonlinearity":
        return {"soft_twist_arcmin": 2.0 * s, "torque_scale_Nm": 0.3 * a}
    if kind == "bearing_clearance":
        return {"soft_stiffness_Nm_per_arcmin": 0.15 * a / (2.0 * s),
                "soft_stage_torque_Nm": 0.15 * a}
    if kind == "runout":
        ref = {"internal_mm": 0.02, "external_mm": 0.0,
               "beta_deg": float(rng.uniform(-180, 180)),
               "internal_phase_deg": float(rng.uniform(-180, 180))}
        spread = _play_spread_arcmin(design, kind, ref)
        if spread < 1e-6:
            return None
        return {**ref, "internal_mm": 0.02 * 2.0 * s / spread}
    if kind == "tooth_spacing_error":
        ref = {"thickness_error_um_rms": 3.0, "pitch_error_um_rms": 0.0,
               "seed": int(rng.integers(1_000_000))}
        spread = _play_spread_arcmin(design, kind, ref)
        if spread < 1e-6:
            return None
        return {**ref, "thickness_error_um_rms": 3.0 * 2.0 * s / spread}
    if kind == "thermal_expansion":
        temps = [float(np.nanmean(r.temperature_C)) for r in design.runs
                 if r.temperature_C is not None]
        if len(temps) < 2 or np.ptp(temps) < MIN_TEMPERATURE_SPREAD_K:
            return None
        ref = {"coefficient_um_per_K": 1.0, "reference_C": float(np.mean(temps))}
        spread = _play_spread_arcmin(design, kind, ref)
        if spread < 1e-6:
            return None
        return {**ref, "coefficient_um_per_K": sign * 2.0 * s / spread}
    raise ValueError(f"unknown effect {kind!r}")


def testable_effects(design: Design) -> tuple[list[str], dict[str, str]]:
    """The in-vocabulary effects this design can show, and why the others cannot."""
    rng = np.random.default_rng(0)
    ok, why = [], {}
    for kind in IN_VOCABULARY:
        if effect_params(design, kind, 4.0, rng) is None:
            why[kind] = ("one temperature (spread under "
                         f"{MIN_TEMPERATURE_SPREAD_K:g} K)" if kind == "thermal_expansion"
                         else "the runs do not change the play (one position)")
        else:
            ok.append(kind)
    return ok, why


def like_campaign(design: Design, kind: str, params: dict[str, Any] | None,
                  rng: np.random.Generator, index: int = 0) -> Campaign:
    """One campaign with ``design``'s design and measuring system and ``kind`` (or 'none')
    switched on with ``params``: the replay described in the module docstring."""
    from simulators.offline import simulate_run

    config = _plant_config(design)
    unit = dict(design.unit)
    if kind != "none":
        config = config.with_effect(kind, **(params or {}))
        if kind == "runout":
            # the lab inspected this runout: the unit data say its size
            unit["runout_internal_mm"] = round(max(float(params["internal_mm"]), 0.001), 4)
            config = config.with_changes(unit={"runout_internal_mm":
                                               unit["runout_internal_mm"]})
    fx = config.effects
    sigma_deg = design.twist_noise_arcmin / 60.0
    q = design.twist_resolution_deg
    # the measured noise holds the encoder's own quantisation noise (q^2 / 12)
    add_deg = math.sqrt(max(sigma_deg ** 2 - q * q / 12.0, 0.0))
    runs = []
    for r in design.runs:
        t = r.t_s
        dt = float(np.median(np.diff(t)))
        n = int(math.floor((t[-1] - t[0]) / dt)) + 2
        grid = t[0] + np.arange(n) * dt
        # the twist at sample k answers the command held over the interval before it; the
        # true torque leads the measured channel by its lag
        command = np.interp(grid + dt + design.torque_lag_s, t, _true_torque(r.torque_Nm))
        temp = float(np.nanmean(r.temperature_C)) if r.temperature_C is not None else 20.0
        # implicit Euler is stable at any step: a quasi-static replay needs no finer one
        # than the samples (two steps per sample, at most 10 ms)
        run_cfg = config.with_changes(rig={"step_s": min(0.01, 0.5 * dt)})
        cols = simulate_run(run_cfg, command, duration_s=n * dt, sample_rate_Hz=1.0 / dt,
                            input_angle_deg=r.input_angle_deg, temperature_C=temp)
        out = np.interp(t, grid, cols["output_angle_deg"])
        inp = np.interp(t, grid, cols["input_angle_deg"])
        out = out + rng.standard_normal(t.size) * add_deg
        if q > 0:
            out, inp = np.round(out / q) * q, np.round(inp / q) * q
        torque = r.torque_Nm.copy()
        if fx.direction_gain.enabled:
            torque = torque * np.where(torque >= 0, fx.direction_gain.gain_positive,
                                       fx.direction_gain.gain_negative)
        if fx.torque_sensor_offset.enabled:
            torque = torque + fx.torque_sensor_offset.offset_Nm
            if design.torque_resolution_Nm > 0:
                torque = np.round(torque / design.torque_resolution_Nm) \
                    * design.torque_resolution_Nm
        runs.append(Run.from_arrays(
            r.run_id, t, torque, out, input_angle_deg=inp,
            temperature_C=r.temperature_C if r.temperature_C is not None
            else np.full(t.size, temp),
            unit=unit, test=r.test, sensors=r.sensors,
            extra_meta={"generator": {"kind": kind, "truth": params or {},
                                      "what": "rig.validate.like (simulated, not a "
                                              "measurement)"}}))
    meta = {"format": "rig-campaign/1", "name": f"like-{design.name}-{index:03d}",
            "runs": [r.run_id for r in runs]}
    return Campaign(meta=meta, runs=runs)


def _true_torque(measured_Nm: np.ndarray) -> np.ndarray:
    """The torque the unit carried, from the measured channel: its noise is the sensor's, not
    a torque on the unit (a frictionless plant would float across the play on it at zero
    torque). Savitzky-Golay smoothing (quadratic over 7 samples keeps ramps and steps' ends),
    and zero where the smoothed torque is within 3 noise sigmas of zero (a dwell at zero)."""
    from scipy.signal import savgol_filter

    from analysis.loop.branches import white_noise_std

    x = np.asarray(measured_Nm, dtype=float)
    if x.size < 9:
        return x.copy()
    smooth = savgol_filter(x, 7, 2)
    sigma = white_noise_std(x)
    return np.where(np.abs(smooth) < 3.0 * sigma, 0.0, smooth)


def _correct(kind: str, verdict: str, also: list[str], candidates: list[str]) -> bool:
    if kind == "none":
        return verdict == "none" and not also
    if kind == "shaft_compliance" and verdict == "ambiguous":
        return "shaft_compliance" in candidates
    return verdict == kind


def like_one(args: tuple[Design, int, str, float, int]) -> dict[str, Any]:
    """Case ``index``: draw its size (``multiple`` of the noise), make the campaign, diagnose
    it blind (:func:`rig.results.diagnose.diagnose_campaign`, as ``rig diagnose`` does)."""
    from rig.core.json_files import finite_for_json
    from rig.results.diagnose import diagnose_campaign

    design, index, kind, multiple, seed = args
    rng = np.random.default_rng([seed, index])
    params = None if kind == "none" else effect_params(design, kind, multiple, rng)
    t0 = time.perf_counter()
    try:
        camp = like_campaign(design, kind, params, rng, index)
        report = finite_for_json(diagnose_campaign(camp).to_dict())
    except Exception as exc:  # a crash of one case is a graded failure, not the end
        return {"index": index, "kind": kind, "noise_multiple": multiple, "size": params,
                "verdict": None, "also": [], "candidates": [], "correct": False,
                "error": f"{type(exc).__name__}: {exc}", "seconds": time.perf_counter() - t0}
    also = [a if isinstance(a, str) else a.get("effect", str(a))
            for a in report.get("also") or []]
    cands = list(report.get("candidates") or [])
    verdict = str(report["verdict"])
    return {"index": index, "kind": kind, "noise_multiple": multiple, "size": params,
            "verdict": verdict, "also": also, "candidates": cands,
            "correct": _correct(kind, verdict, also, cands),
            "seconds": time.perf_counter() - t0}


def plan(design: Design, cases: int, seed: int) -> tuple[list[tuple[str, float]],
                                                          dict[str, str]]:
    """The cases' kinds and noise multiples: the testable effects in turn with a null every
    :data:`NULL_EVERY`-th case, the multiples log-uniform in :data:`NOISE_MULTIPLES`."""
    effects, why = testable_effects(design)
    if not effects:
        raise RigError(f"{design.name}: this design cannot show any effect")
    rng = np.random.default_rng([seed, 20])
    lo, hi = (math.log(m) for m in NOISE_MULTIPLES)
    out, e = [], 0
    for i in range(cases):
        if i % NULL_EVERY == NULL_EVERY - 1:
            out.append(("none", 0.0))
            continue
        out.append((effects[e % len(effects)], float(math.exp(rng.uniform(lo, hi)))))
        e += 1
    return out, why


def summarise_like(results: list[dict[str, Any]]) -> dict[str, Any]:
    """Per effect right/wrong (with the verdicts), false alarms on nulls, smallest size found."""
    per: dict[str, dict[str, Any]] = {}
    smallest: dict[str, Any] = {}
    for r in results:
        d = per.setdefault(r["kind"], {"n": 0, "correct": 0, "wrong": 0, "verdicts": {}})
        d["n"] += 1
        d["correct" if r["correct"] else "wrong"] += 1
        got = "<crash>" if r["verdict"] is None else r["verdict"] + "".join(
            "+" + a for a in r["also"])
        d["verdicts"][got] = d["verdicts"].get(got, 0) + 1
        if r["kind"] != "none" and r["correct"]:
            best = smallest.get(r["kind"])
            if best is None or r["noise_multiple"] < best["noise_multiple"]:
                smallest[r["kind"]] = {"noise_multiple": r["noise_multiple"],
                                       "size": r["size"]}
    nulls = [r for r in results if r["kind"] == "none"]
    for kind in per:
        if kind != "none":
            smallest.setdefault(kind, None)
    return {"cases": len(results), "correct": sum(r["correct"] for r in results),
            "false_alarms": sum(not r["correct"] for r in nulls), "nulls": len(nulls),
            "per_effect": per, "smallest_found": smallest}


def self_check(campaign: Campaign | str | Path, cases: int = 20, jobs: int = 1,
               seed: int = 0,
               progress: Callable[[dict[str, Any]], None] | None = None) -> dict[str, Any]:
    """N labelled campaigns like ``campaign``, diagnosed blind; returns {"cases", "correct",
    "false_alarms", "nulls", "per_effect", "smallest_found", "seconds", "design",
    "untestable", "results"} (JSON-ready)."""
    from rig.validate.cases import parallel_map

    t0 = time.perf_counter()
    if cases < 1:
        raise RigError(f"--cases must be at least 1, got {cases}")
    design = design_of(campaign)
    kinds, why = plan(design, cases, seed)
    args = [(design, i, kind, m, seed) for i, (kind, m) in enumerate(kinds)]
    results = []
    for res in parallel_map(like_one, args, jobs):
        if progress is not None:
            progress(res)
        results.append(res)
    return {**summarise_like(results), "seconds": time.perf_counter() - t0,
            "campaign": design.name, "design": design.summary(), "untestable": why,
            "noise_multiples": list(NOISE_MULTIPLES), "results": results}
