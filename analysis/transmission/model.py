"""The seeds' TE prediction beside a measured TE run, by unit kind.

- ``internal_involute`` (seed 000): :mod:`.model_internal`, the unit's own curve from its
  inspected runouts and tooth positions (eq. 4, eq. 1) and the batch band of Table 1 by Monte
  Carlo;
- ``planetary`` (seed 003): the Monte Carlo of the paper's train
  (:mod:`analysis.models.seed003_montecarlo`, the distribution ``rig montecarlo`` prints), as a
  band of peak-to-peak TE and of each order's amplitude; the nominal is the batch median;
- ``beveloid`` (seed 001): the tooth contact analysis's TE over one mesh cycle (eq. 11) for the
  installation errors of ``unit.installation`` (``dx_mm``, ``dy_mm``, ``dz_mm``,
  ``horizontal_deg``, ``vertical_deg``), repeated once per pinion tooth; no band (the TCA is
  deterministic).

Every prediction carries the same metric names as the measurement (run-format.md) and, where
there is a batch, ``band``: ``[P0.5, P99.5]`` of each metric and ``[0, P99.5]`` of each order's
amplitude over the sampled units.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from analysis.errors import AnalysisError
from analysis.transmission.analyse import Kinematics
from analysis.transmission.orders import Order, order_number, standard_orders

BAND_PERCENTILES = (0.5, 99.5)
BAND_SAMPLES = 1000


@dataclass
class TEPrediction:
    """A model's TE: metrics (the measured names), orders (one entry per order and flank:
    ``order``, ``per``, ``frequency_per_output_rev``, ``amplitude_arcsec``, ``phase_deg`` or
    None, ``direction``), the band of a batch, and the curve over one output revolution."""

    name: str
    kinematics: Kinematics
    metrics: dict[str, float | None]
    orders: list[dict[str, Any]]
    band: dict[str, list[float]] | None = None
    order_band: dict[float, list[float]] = field(default_factory=dict)
    curve_deg: np.ndarray | None = None
    curve_arcsec: dict[int, np.ndarray] = field(default_factory=dict)
    samples: int = 0
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, **self.metrics, "te_orders": self.orders}
        if self.band is not None:
            out["band"] = {**self.band, "te_orders": [
                {"frequency_per_output_rev": f, "amplitude_arcsec": b}
                for f, b in sorted(self.order_band.items())],
                "percentiles": list(BAND_PERCENTILES), "samples": self.samples}
        out["notes"] = list(self.notes)
        return out


def _sliding_range(curves: np.ndarray, width: int) -> np.ndarray:
    """Largest max - min over any ``width`` consecutive (periodic) points, per row."""
    from scipy.ndimage import maximum_filter1d, minimum_filter1d
    hi = maximum_filter1d(curves, size=width, axis=1, mode="wrap")
    lo = minimum_filter1d(curves, size=width, axis=1, mode="wrap")
    return (hi - lo).max(axis=1)


def _order_basis(orders: list[Order], out_deg: np.ndarray, in_deg: np.ndarray,
                 kin: Kinematics) -> np.ndarray:
    cols = [np.ones_like(out_deg)]
    for o in orders:
        if o.per == "output_rev":
            phi = np.radians(out_deg)
        elif o.per == "crank":
            phi = np.radians(in_deg) * float(kin.crank_per_input or 0.0)
        elif o.per == "mesh":
            phi = np.radians(in_deg) * float(kin.mesh_per_input or 0.0)
        else:
            phi = np.radians(in_deg)
        cols += [np.sin(o.order * phi), np.cos(o.order * phi)]
    return np.column_stack(cols)


def _orders_of(curves: np.ndarray, solver: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Amplitudes and phases (deg) of the orders in each row of ``curves`` (least squares,
    the measurement's convention ``A cos(k phi + p)``); ``solver``: the pseudo-inverse of the
    orders' basis (:func:`_order_basis`)."""
    beta = solver @ np.atleast_2d(curves).T
    a, b = beta[1::2], beta[2::2]
    return np.hypot(a, b).T, np.degrees(np.arctan2(-a, b)).T


def _summarise(name: str, kin: Kinematics, grid_out_deg: np.ndarray, grid_in_deg: np.ndarray,
               nominal: dict[int, np.ndarray], batch: dict[int, np.ndarray] | None,
               hysteresis_arcmin: float | None, notes: list[str], harmonics: int = 2,
               phases_known: bool = True) -> TEPrediction:
    """Metrics and orders of the nominal curves; bands of the batch curves."""
    orders = standard_orders(kin.ratio, crank_per_input=kin.crank_per_input,
                             mesh_per_input=kin.mesh_per_input, harmonics=harmonics,
                             extra=kin.extra_orders)
    teeth = kin.output_teeth

    def on_pitch_grid(c: np.ndarray) -> np.ndarray:
        # one revolution resampled (periodic) to a whole number of points per output pitch,
        # so that f'_i's window is exactly one pitch (issue 32 item 2)
        c = np.atleast_2d(c)
        n = c.shape[1]
        if not teeth or n % teeth == 0:
            return c
        m = int(teeth * math.ceil(n / teeth))
        x = np.arange(n) / n
        xs = np.arange(m) / m
        return np.vstack([np.interp(xs, x, row, period=1.0) for row in c])

    def short_wave(c: np.ndarray) -> np.ndarray:
        # ISO 1328-1:2013 f_is: orders below z / 2 removed (one periodic revolution)
        spec = np.fft.rfft(c, axis=1)
        spec[:, np.arange(spec.shape[1]) < (teeth or 0) / 2.0] = 0.0
        return np.fft.irfft(spec, c.shape[1], axis=1)

    def figures(curves: dict[int, np.ndarray]) -> dict[str, np.ndarray]:
        pp = {s: np.ptp(np.atleast_2d(c), axis=1) for s, c in curves.items()}
        same = curves[1] is curves[-1]
        fig = {"te_pp_forward_arcsec": pp[1], "te_pp_reverse_arcsec": pp[-1],
               "te_pp_arcsec": np.maximum(pp[1], pp[-1]),
               "te_total_Fi_forward_arcsec": pp[1], "te_total_Fi_reverse_arcsec": pp[-1],
               "te_total_Fi_arcsec": np.maximum(pp[1], pp[-1])}
        if teeth:
            for key, transform in (("te_tooth_fi_arcsec", lambda c: c),
                                   ("te_tooth_fi_short_wave_arcsec", short_wave)):
                vals = []
                for s in ((1,) if same else (1, -1)):
                    c = transform(on_pitch_grid(curves[s]))
                    vals.append(_sliding_range(c, c.shape[1] // teeth + 1))
                fig[key] = vals[0] if same else np.maximum(vals[0], vals[1])
        return fig

    solver = np.linalg.pinv(_order_basis(orders, grid_out_deg, grid_in_deg, kin))
    nom = figures(nominal)
    metrics: dict[str, float | None] = {k: float(v[0]) for k, v in nom.items()}
    metrics.setdefault("te_tooth_fi_arcsec", None)
    metrics.setdefault("te_tooth_fi_short_wave_arcsec", None)
    metrics["te_hysteresis_arcmin"] = hysteresis_arcmin
    order_list = []
    for s in (1, -1):
        amp, ph = _orders_of(nominal[s], solver)
        for j, o in enumerate(orders):
            order_list.append({"order": order_number(o.order), "per": o.per,
                               "frequency_per_output_rev": o.frequency,
                               "amplitude_arcsec": float(amp[0, j]),
                               "phase_deg": float(ph[0, j]) if phases_known else None,
                               "direction": "forward" if s == 1 else "reverse",
                               "source": o.source})
    pred = TEPrediction(name, kin, metrics, order_list, curve_deg=grid_out_deg,
                        curve_arcsec={s: np.atleast_2d(c)[0] for s, c in nominal.items()},
                        notes=notes)
    if batch is not None:
        fig = figures(batch)
        lo, hi = BAND_PERCENTILES
        pred.band = {k: [float(np.percentile(v, lo)), float(np.percentile(v, hi))]
                     for k, v in fig.items()}
        same = batch[1] is batch[-1]
        amps = np.vstack([_orders_of(batch[s], solver)[0] for s in ((1,) if same else (1, -1))])
        pred.order_band = {o.frequency: [0.0, float(np.percentile(amps[:, j], hi))]
                           for j, o in enumerate(orders)}
        pred.samples = int(np.atleast_2d(batch[1]).shape[0])
    return pred


def internal_prediction(unit: Mapping[str, Any], *, brake_torque_Nm: float | None = None,
                        samples: int = BAND_SAMPLES, seed: int = 0) -> TEPrediction:
    """Seed 000: the unit's curve (eq. 4 eccentricities, tooth positions) and the Table 1
    batch band; the hysteresis is the reference nominal model's play plus the windup of both
    flanks under the brake torque, ``play + 2 T / K`` (run-format.md's nominal model)."""
    from analysis.transmission import model_internal as mi

    geo = mi.geometry_from_unit(unit)
    kin = geo.kinematics()
    theta_in = mi.input_angles_deg(geo)
    out_deg = theta_in / geo.ratio
    errors = mi.unit_errors(geo, unit)
    nominal = mi.unit_curves(geo, errors, theta_in)
    rng = np.random.default_rng(seed)
    batch = mi.te_curves_arcsec(geo, theta_in, **mi.batch_errors(geo, samples, rng))
    notes = [f"assumed: {a}" for a in errors.assumed]
    notes.append(f"band: {samples} units within seed 000 Table 1 runouts and GB/T 10095.1 "
                 "single pitch deviations of the same grades")
    hyst = None
    try:
        from analysis.models.nominal import reference_nominal_model

        ref = reference_nominal_model({k: v for k, v in unit.items()
                                       if k not in ("serial", "design", "name")})
        model = ref[0] if isinstance(ref, tuple) else ref
        if brake_torque_Nm is not None:
            hyst = float(model.play_arcmin + 2.0 * brake_torque_Nm
                         / model.stiffness_Nm_per_arcmin)
    except (AnalysisError, KeyError, TypeError, AttributeError) as exc:
        notes.append(f"no hysteresis prediction: {exc}")
    phases_known = "runout_phase_deg" in unit
    return _summarise("seed 000 eq. (4) eccentricities and tooth spacing (internal involute)",
                      kin, out_deg, theta_in, nominal, batch, hyst, notes,
                      phases_known=phases_known)


def planetary_kinematics(train: Any) -> Kinematics:
    """Seed 003's train: sun input, carrier output; the output pitch is the last ring's."""
    from analysis.models.seed003_planetary import error_sources

    freqs = sorted({abs(s.frequency_per_rev) for s in error_sources(train)
                    if s.frequency_per_rev})
    extra = tuple(Order(float(f), "output_rev", float(f), "seed 003 source") for f in freqs)
    return Kinematics(ratio=float(train.total_ratio), output_teeth=train.stages[-1].z_ring,
                      extra_orders=extra,
                      notes=("output tooth pitch: 360/z_ring of the last stage (the output "
                             "carrier's planets mesh with it)",))


def planetary_prediction(unit: Mapping[str, Any], *, samples: int = BAND_SAMPLES, seed: int = 0
                         ) -> TEPrediction:
    """Seed 003: the paper's train (eqs. 1-11) with random errors and phases (eqs. 12-17),
    ``samples`` units: band of peak-to-peak TE and of each line's amplitude; the nominal
    figures are the batch's medians (seed 003 has no nominal unit, every error is random)."""
    from analysis.models.seed003_montecarlo import (
        TransmissionErrorModel,
        draw_phases_rad,
        draw_values_um,
    )
    from analysis.models.seed003_planetary import error_sources, paper_train

    train = paper_train()
    kin = planetary_kinematics(train)
    model = TransmissionErrorModel(error_sources(train))
    fastest = float(np.abs(model.frequencies).max())
    n = int(max(720, 16 * math.ceil(fastest)))
    psi = np.arange(n) * (2.0 * math.pi / n)
    rng = np.random.default_rng(seed)
    values = draw_values_um(model.sources, samples, rng)
    phases = draw_phases_rad(samples, len(model.sources), rng)
    curves = model.transmission_error_arcsec(values, phases, psi)
    curves -= curves.mean(axis=1, keepdims=True)
    out_deg = np.degrees(psi)
    in_deg = out_deg * kin.ratio
    pp = np.ptp(curves, axis=1)
    median = int(np.argsort(pp)[pp.size // 2])
    nominal = {1: curves[median], -1: curves[median]}
    batch = {1: curves, -1: curves}
    notes = [f"seed 003 paper train (3 stages, i = {train.total_ratio:g}); nominal: the "
             "batch's median unit", "geometric TE: the same both ways; no hysteresis model"]
    return _summarise("seed 003 Monte Carlo (planetary train)", kin, out_deg, in_deg,
                      nominal, batch, None, notes, phases_known=False)


def beveloid_prediction(unit: Mapping[str, Any], *, ratio: float | None = None
                        ) -> TEPrediction:
    """Seed 001: TCA transmission error, eq. (11), over one mesh cycle for the unit's
    installation errors, repeated over one output revolution (pinion input, gear output)."""
    from analysis.models.beveloid_nominal import beveloid_pair_from_unit
    from analysis.models.seed001_beveloid import Installation, transmission_error

    pair, _shift, assumed = beveloid_pair_from_unit(unit)
    inst_keys = dict(unit.get("installation") or {})
    installation = Installation(**{k: float(v) for k, v in inst_keys.items()})
    te = transmission_error(pair, installation, points_per_cycle=24)
    zp, zg = pair.pinion.teeth, pair.gear.teeth
    i = float(ratio) if ratio else -zg / zp
    kin = Kinematics(ratio=i, output_teeth=zg, mesh_per_input=float(zp),
                     notes=(f"output tooth pitch: 360/{zg} deg (the gear)",))
    cycle = te.te_arcsec[:-1]  # one mesh cycle, periodic
    in_deg = np.arange(zp * cycle.size) * (360.0 / (zp * cycle.size))
    curve = np.tile(cycle, zp)
    curve = curve - curve.mean()
    out_deg = in_deg / i
    notes = [f"assumed: {a}" for a in assumed] + [
        f"installation errors: {inst_keys or 'none'}; drive side for both directions"]
    return _summarise("seed 001 tooth contact analysis (beveloid)", kin, out_deg, in_deg,
                      {1: curve, -1: curve}, None, None, notes)


def predict(unit: Mapping[str, Any], *, ratio: float | None = None,
            brake_torque_Nm: float | None = None, samples: int = BAND_SAMPLES
            ) -> TEPrediction:
    """The prediction for ``unit.kind`` (internal_involute, planetary, beveloid)."""
    kind = unit.get("kind", "internal_involute")
    if kind == "internal_involute":
        return internal_prediction(unit, brake_torque_Nm=brake_torque_Nm, samples=samples)
    if kind == "planetary":
        return planetary_prediction(unit, samples=samples)
    if kind == "beveloid":
        return beveloid_prediction(unit, ratio=ratio)
    raise AnalysisError(f"no TE model for unit kind {kind!r} (internal_involute, planetary, "
                        "beveloid)")


def kinematics_for_unit(unit: Mapping[str, Any], ratio: float) -> Kinematics:
    """The orders, output tooth count and notes a unit's geometry gives (without the model's
    Monte Carlo); the measured ``ratio`` (test.ratio) is kept."""
    kind = unit.get("kind", "internal_involute")
    kin: Kinematics | None = None
    if kind == "internal_involute" and "z_internal" in unit:
        from analysis.transmission.model_internal import geometry_from_unit
        kin = geometry_from_unit(unit).kinematics()
    elif kind == "planetary":
        from analysis.models.seed003_planetary import paper_train
        kin = planetary_kinematics(paper_train())
    elif kind == "beveloid" and "z_pinion" in unit:
        kin = Kinematics(ratio=ratio, output_teeth=int(unit["z_gear"]),
                         mesh_per_input=float(unit["z_pinion"]))
    if kin is None:
        teeth = unit.get("output_teeth")
        return Kinematics(ratio=ratio, output_teeth=int(teeth) if teeth else None,
                          notes=("unit geometry unknown: orders per output and input, and the "
                                 "tooth mesh when output_teeth is given",))
    return Kinematics(ratio=ratio, output_teeth=kin.output_teeth,
                      crank_per_input=kin.crank_per_input, mesh_per_input=kin.mesh_per_input,
                      extra_orders=kin.extra_orders, notes=kin.notes)
