"""Transmission error of one run: curves, figures, orders and their uncertainties.

The metric names are those of docs/run-format.md ("A transmission error run"): ``te_pp_arcsec``
(GB/T 35089 transmission accuracy, the larger direction), ``te_pp_forward_arcsec``,
``te_pp_reverse_arcsec``, ``te_total_Fi_arcsec`` (ISO 1328-1:2013 F_is, the larger flank's
worst single revolution), ``te_total_Fi_forward_arcsec`` / ``_reverse`` (per flank),
``te_tooth_fi_arcsec`` (the project's f'_i over exactly one output tooth pitch),
``te_tooth_fi_short_wave_arcsec`` (ISO 1328-1:2013 f_is: the same after the orders below
``z / 2`` are removed), ``te_hysteresis_arcmin`` and ``te_orders``.

The curve (issue 32, :mod:`analysis.transmission.evaluate`): every named order fitted jointly
on the samples and evaluated exactly, plus the residual averaged in bins of a few samples; no
1-degree bins. Holes left by rows without a finite angle are never bridged.

Standard uncertainties (arcsec unless named):

- encoder resolution: a reading of a ``N``-count encoder is within half a count, uniform:
  ``q / sqrt(12)`` with ``q = 1296000 / N`` arcsec; the input's divided by ``|i|``. Quantisation
  of a slowly turning shaft is systematic, so it is not divided by the samples averaged; a
  peak-to-peak (a difference of two values) carries it twice;
- noise: the spread of the figure under the residual bins' own noise (a parametric bootstrap,
  :func:`analysis.transmission.evaluate.noise_bias`), whose mean shift, the bias an extreme
  value takes from the noise, is taken away (a quarter of it stays in the budget);
- the method: the figure again on a grid of half the points with residual bins twice as wide;
  the difference is carried as the method's remaining bias (``te_evaluation``);
- encoder mounting eccentricity (:mod:`analysis.transmission.eccentricity`): the uncertainty
  ``u_e`` of the removed term (or, when none was removed, a declared bound ``b`` as ``b/sqrt(3)``)
  adds ``sqrt(2) u_e`` to the peak-to-peak figures and ``u_e`` to the output order 1;
- orders: the least-squares covariance scaled by the residual variance (a tapered fit's
  sandwich for the orders that are not whole).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from analysis.errors import AnalysisError
from analysis.transmission.curve import DIRECTIONS, DirectionCurve, te_arcsec
from analysis.transmission.eccentricity import EncoderEccentricity
from analysis.transmission.evaluate import (
    NOISE_DRAWS,
    RICHARDSON,
    Evaluated,
    eval_points_per_rev,
    evaluate,
    figures,
    find_holes,
    noise_bias,
    revolutions_between_holes,
)
from analysis.transmission.figures import hysteresis_arcmin
from analysis.transmission.orders import (
    Order,
    OrderFit,
    OrderModel,
    fit_order_model,
    is_whole,
    nuisance_orders,
    order_number,
    standard_orders,
)
from analysis.transmission.unsampled import excess, u_of_excess

ARCSEC_PER_REV = 1_296_000.0
METRIC_KEYS = ("te_pp_arcsec", "te_pp_forward_arcsec", "te_pp_reverse_arcsec",
               "te_total_Fi_arcsec", "te_tooth_fi_arcsec", "te_hysteresis_arcmin",
               "te_total_Fi_forward_arcsec", "te_total_Fi_reverse_arcsec",
               "te_tooth_fi_short_wave_arcsec")
"""Scalar TE metrics (run-format.md); ``te_orders`` is the list beside them."""


@dataclass(frozen=True)
class Kinematics:
    """What the unit's geometry says about its TE orders: the signed ratio ``i``, the output's
    tooth count (the pitch of f'_i), crank turns and tooth meshes per input revolution, and
    further orders the model names (e.g. a gear's own eccentricity)."""

    ratio: float
    output_teeth: int | None = None
    crank_per_input: float | None = None
    mesh_per_input: float | None = None
    extra_orders: tuple[Order, ...] = ()
    notes: tuple[str, ...] = ()


def _fit_all_orders(th: np.ndarray, ip: np.ndarray, y: np.ndarray, whole_revs: np.ndarray,
                    orders: list[Order], ratio: float, crank_per_input: float | None,
                    mesh_per_input: float | None) -> tuple[list[OrderFit], OrderModel]:
    """Every named order of one direction, none leaking into another (issue 32 item 4).

    Orders that are not whole per output revolution (an input order of a ratio such as
    -47/13, a planetary line) are fitted first, on the whole record, tapered, jointly with
    every named order and the whole orders next to them (:func:`.orders.nuisance_orders`);
    their fitted sum is taken away and the whole orders are fitted on the whole revolutions
    (``whole_revs``), where they are orthogonal to every other whole order, named or not.
    Returns the fits in the order of ``orders`` and the model of their sum (with the constant)
    that the curve evaluates."""
    kw = {"ratio": ratio, "crank_per_input": crank_per_input, "mesh_per_input": mesh_per_input}
    whole = [o for o in orders if is_whole(o.frequency)]
    other = [o for o in orders if not is_whole(o.frequency)]
    if not other:
        fits, _, model = fit_order_model(th[whole_revs], ip[whole_revs], y[whole_revs],
                                         orders, **kw)
        return fits, model
    record_revs = float(np.ptp(th)) / 360.0
    named = whole + other
    fits_b, _, model_b = fit_order_model(th, ip, y, named + nuisance_orders(named, record_revs),
                                         taper=True, **kw)
    j0 = len(whole)
    beta_other = np.concatenate([[0.0], model_b.beta[1 + 2 * j0: 1 + 2 * len(named)]])
    other_model = OrderModel(tuple(other), beta_other, ratio, crank_per_input, mesh_per_input)
    y_whole = y[whole_revs] - other_model.evaluate(th[whole_revs], ip[whole_revs])
    if whole:
        fits_a, _, model_a = fit_order_model(th[whole_revs], ip[whole_revs], y_whole, whole,
                                             **kw)
        beta = np.concatenate([model_a.beta, beta_other[1:]])
    else:
        fits_a = []
        beta = np.concatenate([[float(np.mean(y_whole))], beta_other[1:]])
    by_order = {id(f.order): f for f in fits_a}
    by_order.update({id(o): f for o, f in zip(other, fits_b[j0:len(named)], strict=True)})
    fits = [by_order[id(o)] for o in named]
    fits = [next(f for f in fits if f.order is o) for o in orders]
    model = OrderModel(tuple(named), beta, ratio, crank_per_input, mesh_per_input)
    return fits, model


def directions_from_input(input_angle_deg: np.ndarray) -> np.ndarray:
    """The ``direction`` column when a run lacks it: the sign of the input's motion
    (``1`` forward, ``-1`` reverse, ``0`` standing)."""
    inp = np.asarray(input_angle_deg, dtype=float)
    d = np.sign(np.gradient(inp)) if inp.size > 1 else np.zeros_like(inp)
    return np.nan_to_num(d).astype(int)


@dataclass
class TEResult:
    """Everything a TE analysis reports (metrics ± u, curves, orders)."""

    curves: dict[int, DirectionCurve]
    metrics: dict[str, float | None]
    uncertainty: dict[str, float | None]
    orders: list[tuple[int, OrderFit]]
    encoder_eccentricity: dict[str, Any]
    grid_points: int
    output_teeth: int | None
    resolution_arcsec: float = 0.0
    notes: list[str] = field(default_factory=list)
    errors: dict[str, str] = field(default_factory=dict)
    evaluation: dict[str, Any] = field(default_factory=dict)
    """How the curve was evaluated (``te_evaluation``): grid, residual bins, the highest kept
    order, the method's remaining bias per figure, rows dropped, revolutions used."""

    def orders_list(self) -> list[dict[str, Any]]:
        """``te_orders`` of run-format.md (one entry per order and direction)."""
        return [{"order": order_number(f.order.order), "per": f.order.per,
                 "frequency_per_output_rev": f.order.frequency,
                 "amplitude_arcsec": f.amplitude_arcsec, "phase_deg": f.phase_deg,
                 "direction": DIRECTIONS[d], "source": f.order.source}
                for d, f in self.orders]

    def orders_u_list(self) -> list[dict[str, Any]]:
        """``te_orders_u``: the standard uncertainties, entry by entry."""
        return [{"order": order_number(f.order.order), "per": f.order.per,
                 "amplitude_arcsec": f.amplitude_u_arcsec, "phase_deg": f.phase_u_deg,
                 "direction": DIRECTIONS[d]} for d, f in self.orders]


def _u_quant_arcsec(counts_out: float | None, counts_in: float | None, ratio: float) -> float:
    q_out = ARCSEC_PER_REV / counts_out if counts_out else 0.0
    q_in = ARCSEC_PER_REV / counts_in / abs(ratio) if counts_in else 0.0
    return math.sqrt((q_out**2 + q_in**2) / 12.0)


def _encoder_term(te: np.ndarray, out: np.ndarray,
                  encoder_eccentricity: EncoderEccentricity | None,
                  eccentricity_bound_arcsec: float | None,
                  notes: list[str]) -> tuple[np.ndarray, float, dict[str, Any]]:
    """The output encoder's once-per-turn term: subtracted when calibrated, else carried as
    an uncertainty from its declared bound (uniform: bound/sqrt 3); (TE, u arcsec, record)."""
    ecc_record: dict[str, Any]
    u_ecc = 0.0
    if encoder_eccentricity is not None:
        te = te - encoder_eccentricity.arcsec(out)
        u_ecc = encoder_eccentricity.u_arcsec
        ecc_record = {"removed": True, "method": "reversal (coupling indexed by 180 deg), "
                      "subtracted as A cos(theta_out + p)", **encoder_eccentricity.to_dict()}
    else:
        ecc_record = {"removed": False, "method": "none: no calibrated encoder eccentricity; "
                      "the once-per-output-turn order holds the encoder's term too"}
        if eccentricity_bound_arcsec:
            u_ecc = float(eccentricity_bound_arcsec) / math.sqrt(3.0)
            ecc_record["bound_arcsec"] = float(eccentricity_bound_arcsec)
            ecc_record["u_arcsec"] = u_ecc
        else:
            notes.append("encoder mounting eccentricity neither calibrated nor bounded: not "
                         "in the uncertainty")
    return te, u_ecc, ecc_record


def _direction(code: int, mask: np.ndarray, rows_all: np.ndarray, out: np.ndarray,
               inp: np.ndarray, te: np.ndarray, shortest_deg: float, step: float, n: int,
               orders: list, ratio: float, crank_per_input: float | None,
               mesh_per_input: float | None, teeth: int | None, u_ecc: float,
               notes: list[str]) -> tuple[DirectionCurve, Evaluated, list[OrderFit], int]:
    """One direction's whole revolutions between holes: the named orders fitted jointly, the
    curve evaluated on ``n`` points a revolution; (curve, evaluation, order fits, rows
    dropped). Holes and stalls are noted in ``notes``, never bridged."""
    name = DIRECTIONS[code]
    kept: list[OrderFit] = []
    if mask.sum() < 2:
        raise AnalysisError(f"no {name} samples (direction {code}): a TE run "
                            "turns the input both ways")
    rows = rows_all[mask]
    valid = np.isfinite(out[mask]) & np.isfinite(inp[mask]) & np.isfinite(te[mask])
    dropped, holes = find_holes(rows, out[mask], valid, shortest_deg)
    if dropped:
        notes.append(f"{name}: {dropped} rows without a finite output or input angle "
                     "dropped (never interpolated)")
    th, ip, y = out[mask][valid], inp[mask][valid], te[mask][valid]
    if th.size < 2:
        raise AnalysisError(f"{name}: fewer than 2 finite samples")
    for h in holes:
        notes.append(f"{name}: {h.text()}, longer than the shortest kept period "
                     f"{shortest_deg:.3f} deg: not bridged")
    start, revs, span_notes = revolutions_between_holes(th, holes, step, n)
    notes.extend(f"{name}: {t}" for t in span_notes)
    if revs < 1:
        if holes:
            raise AnalysisError(
                f"{name}: no whole output revolution without a hole: "
                + "; ".join(h.text() for h in holes)
                + f" (longer than the shortest kept period {shortest_deg:.3f} deg; a "
                "hole is never interpolated)")
        raise AnalysisError(
            f"{name}: the output turned {np.ptp(th):.1f} deg; a TE run needs "
            "at least one full output revolution in each direction")
    hi = start + revs * 360.0
    m = (th >= start) & (th < hi)
    fits, model = _fit_all_orders(th, ip, y, m, orders, ratio, crank_per_input,
                                  mesh_per_input)
    for f in fits:
        if f.order.per == "output_rev" and f.order.order == 1 and u_ecc:
            f = OrderFit(f.order, f.amplitude_arcsec, f.phase_deg,
                         math.hypot(f.amplitude_u_arcsec, u_ecc),
                         min(180.0, math.degrees(math.hypot(f.amplitude_u_arcsec, u_ecc)
                                                 / max(f.amplitude_arcsec, 1e-12))))
        kept.append(f)
    ev = evaluate(th, ip, y, model, start, revs, n, teeth)
    if ev.longest_empty_deg > shortest_deg:
        notes.append(f"{name}: a stretch of {ev.longest_empty_deg:.2f} deg of output angle "
                     "without samples (the sampling stalled): there the curve is the "
                     "fitted orders plus the residual interpolated from its ends")
    offset = float(ev.values.mean())
    grid, mean = ev.folded(ev.values - offset)
    shift = int(round(start / step)) % n
    curve = DirectionCurve(
        direction=code, grid_deg=grid, mean_arcsec=mean,
        revs_arcsec=np.roll(ev.values - offset, shift, axis=1), offset_arcsec=offset,
        residual_std_arcsec=ev.residual_std_arcsec, samples_per_bin=ev.samples_per_bin,
        revolutions=revs, n_samples=ev.n_samples, span_deg=(start, hi))
    return curve, ev, kept, dropped


def _figures(evaluated: dict[int, Evaluated], teeth: int | None, u_q: float, u_ecc: float,
             errors: dict[str, str]) -> tuple[dict[str, float | None], ...]:
    """The figures of both flanks with their uncertainties, the method's bias, the noise
    bias removed and what a stall may hide (arcsec, :mod:`.unsampled`): (metrics,
    uncertainty, method bias, noise correction, unsampled excess). A figure
    that needs the tooth count is None when it is unknown, its reason in ``errors``."""
    def u_point(ev: Evaluated) -> float:
        # one value of one revolution: the residual averaged in a bin, the encoders
        return math.sqrt(ev.residual_std_arcsec**2 / max(ev.samples_per_bin, 1.0) + u_q**2)

    fig: dict[int, dict[str, float | None]] = {}
    fig_coarse: dict[int, dict[str, float | None]] = {}
    u_noise: dict[int, dict[str, float]] = {}
    b_noise: dict[int, dict[str, float]] = {}
    unseen: dict[int, dict[str, float]] = {}
    for c, ev in evaluated.items():
        unseen[c] = excess(ev, teeth)  # what a stall may hide: one-sided, into the budget
        # the noise's bias on an extreme is taken away (parametric bootstrap), its spread kept
        b_fine, u_fine = noise_bias(ev.values, ev.noise_at, teeth, periodic=ev.periodic)
        b_coarse, _ = noise_bias(ev.coarse, ev.noise_at_coarse, teeth, draws=NOISE_DRAWS // 2,
                                 periodic=ev.periodic)
        raw = figures(ev.values, teeth, ev.periodic)
        raw_coarse = figures(ev.coarse, teeth, ev.periodic)
        fig[c] = {k: (None if v is None else v - b_fine.get(k, 0.0)) for k, v in raw.items()}
        fig_coarse[c] = {k: (None if v is None else v - b_coarse.get(k, 0.0))
                         for k, v in raw_coarse.items()}
        u_noise[c], b_noise[c] = u_fine, b_fine
    bias: dict[str, float | None] = {}
    noise_corr: dict[str, float | None] = {}
    hidden: dict[str, float | None] = {}

    def method_bias(c: int, key: str) -> float:
        return abs(float(fig[c][key] or 0.0) - float(fig_coarse[c][key] or 0.0)) / RICHARDSON

    def u_fig(c: int, key: str, ecc: bool = True) -> float:
        # the noise's spread of the figure (or a difference of two values), the encoders'
        # resolution at both ends, the eccentricity, the method's and the noise correction's
        # remaining bias (a quarter of the correction: NOISE_BIAS_SCALE is a model)
        spread = u_noise[c].get(key)
        if spread is None:
            spread = math.sqrt(2.0) * u_point(evaluated[c])
        else:
            spread = math.sqrt(spread**2 + 2.0 * u_q**2)
        return math.sqrt(spread**2 + (2.0 * u_ecc**2 if ecc else 0.0)
                         + method_bias(c, key) ** 2 + (0.25 * b_noise[c].get(key, 0.0)) ** 2
                         + u_of_excess(unseen[c].get(key, 0.0)) ** 2)

    metrics: dict[str, float | None] = {}
    unc: dict[str, float | None] = {}
    for c, label in ((1, "forward"), (-1, "reverse")):
        for key, fkey in ((f"te_pp_{label}_arcsec", "pp"), (f"te_total_Fi_{label}_arcsec", "Fi")):
            metrics[key], unc[key] = fig[c][fkey], u_fig(c, fkey)
            bias[key], noise_corr[key] = method_bias(c, fkey), b_noise[c].get(fkey)
            hidden[key] = unseen[c].get(fkey)
    for key, fkey in (("te_pp_arcsec", "pp"), ("te_total_Fi_arcsec", "Fi")):
        w = 1 if (fig[1][fkey] or 0.0) >= (fig[-1][fkey] or 0.0) else -1
        src = f"{key[:-len('_arcsec')]}_{DIRECTIONS[w]}_arcsec"
        metrics[key], unc[key] = metrics[src], unc[src]
        bias[key], noise_corr[key], hidden[key] = bias[src], noise_corr[src], hidden[src]
    if teeth:
        for key, fkey in (("te_tooth_fi_arcsec", "fi"),
                          ("te_tooth_fi_short_wave_arcsec", "fis")):
            w = 1 if (fig[1][fkey] or 0.0) >= (fig[-1][fkey] or 0.0) else -1
            metrics[key], unc[key] = fig[w][fkey], u_fig(w, fkey, ecc=False)
            bias[key], noise_corr[key] = method_bias(w, fkey), b_noise[w].get(fkey)
            hidden[key] = unseen[w].get(fkey)
    else:
        for key in ("te_tooth_fi_arcsec", "te_tooth_fi_short_wave_arcsec"):
            metrics[key] = unc[key] = None
            errors[key] = "the output's tooth count is unknown (unit data)"
    return metrics, unc, bias, noise_corr, hidden


def analyse_te(
    output_angle_deg: np.ndarray,
    input_angle_deg: np.ndarray,
    direction: np.ndarray | None,
    kinematics: Kinematics,
    *,
    output_counts_per_rev: float | None = None,
    input_counts_per_rev: float | None = None,
    encoder_eccentricity: EncoderEccentricity | None = None,
    eccentricity_bound_arcsec: float | None = None,
    n_grid: int | None = None,
    harmonics: int = 2,
) -> TEResult:
    """TE metrics of a run (docs/run-format.md): curves per direction, GB/T 35089
    peak-to-peak, ISO 1328-1:2013 F_is per flank and f_is, the project's f'_i, hysteresis,
    orders, uncertainties (issue 32: :mod:`analysis.transmission.evaluate`).

    ``encoder_eccentricity``: a calibrated encoder term, subtracted from TE before anything
    else; ``eccentricity_bound_arcsec``: when none is given, a declared bound of the encoder's
    once-per-turn error, carried as an uncertainty; ``n_grid``: evaluation points per output
    revolution (default :func:`analysis.transmission.evaluate.eval_points_per_rev`)."""
    ratio = float(kinematics.ratio)
    out = np.asarray(output_angle_deg, dtype=float)
    inp = np.asarray(input_angle_deg, dtype=float)
    if out.shape != inp.shape:
        raise AnalysisError("output and input angle columns differ in length")
    d = directions_from_input(inp) if direction is None else np.nan_to_num(
        np.asarray(direction, dtype=float)).astype(int)
    te = te_arcsec(out, inp, ratio)
    notes = list(kinematics.notes)
    te, u_ecc, ecc_record = _encoder_term(te, out, encoder_eccentricity,
                                          eccentricity_bound_arcsec, notes)
    u_q = _u_quant_arcsec(output_counts_per_rev, input_counts_per_rev, ratio)

    teeth = kinematics.output_teeth
    mesh_per_input = kinematics.mesh_per_input
    if not mesh_per_input and teeth:
        # the output gear's teeth pass the mesh once each per output revolution
        mesh_per_input = float(teeth) / abs(ratio)
        notes.append(f"tooth mesh: the output's {teeth} teeth, {teeth} per output revolution "
                     "(orders per mesh)")
    orders = standard_orders(ratio, crank_per_input=kinematics.crank_per_input,
                             mesh_per_input=mesh_per_input, harmonics=harmonics,
                             extra=kinematics.extra_orders)
    highest = max(abs(o.frequency) for o in orders)
    shortest_deg = 360.0 / highest
    n = n_grid or eval_points_per_rev(highest, teeth)
    step = 360.0 / n
    rows_all = np.arange(out.size)
    errors: dict[str, str] = {}
    curves: dict[int, DirectionCurve] = {}
    evaluated: dict[int, Evaluated] = {}
    fitted: list[tuple[int, OrderFit]] = []
    dropped_total = 0
    for code in (1, -1):
        curve, ev, fits, dropped = _direction(
            code, d == code, rows_all, out, inp, te, shortest_deg, step, n, orders, ratio,
            kinematics.crank_per_input, mesh_per_input, teeth, u_ecc, notes)
        curves[code], evaluated[code] = curve, ev
        fitted.extend((code, f) for f in fits)
        dropped_total += dropped

    metrics, unc, bias, noise_corr, hidden = _figures(evaluated, teeth, u_q, u_ecc, errors)
    metrics["te_hysteresis_arcmin"] = hysteresis_arcmin(curves[1], curves[-1])
    u_off = [math.sqrt(c.residual_std_arcsec**2 / max(c.n_samples, 1)
                       + u_q**2 / (c.revolutions * n)) for c in curves.values()]
    unc["te_hysteresis_arcmin"] = math.hypot(*u_off) / 60.0
    evaluation = {
        "method": "named orders fitted jointly on the samples and evaluated exactly, plus the "
                  "residual averaged in bins and interpolated (docs/transmission-error.md)",
        "grid_points_per_rev": n, "grid_step_deg": step,
        "highest_order_per_output_rev": highest, "shortest_period_deg": shortest_deg,
        "points_per_shortest_period": n / highest,
        "residual_bins_per_rev": {DIRECTIONS[c]: ev.n_residual for c, ev in evaluated.items()},
        "samples_per_residual_bin": {DIRECTIONS[c]: ev.samples_per_bin
                                     for c, ev in evaluated.items()},
        "mesh_order_per_output_rev": (mesh_per_input * abs(ratio)) if mesh_per_input else None,
        "method_bias_arcsec": bias,
        "noise_bias_removed_arcsec": noise_corr,
        "unsampled_excess_arcsec": hidden,
        "rows_dropped_nan": dropped_total,
        "revolutions_used": {DIRECTIONS[c]: [cv.span_deg[0], cv.span_deg[1]]
                             for c, cv in curves.items()},
    }
    if dropped_total:
        notes.append(f"{dropped_total} rows without a finite angle dropped in all")
    return TEResult(curves=curves, metrics=metrics, uncertainty=unc, orders=fitted,
                    encoder_eccentricity=ecc_record, grid_points=n, output_teeth=teeth,
                    resolution_arcsec=u_q * math.sqrt(12.0), notes=notes, errors=errors,
                    evaluation=evaluation)
