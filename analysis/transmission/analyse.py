"""Transmission error of one run: curves, figures, orders and their uncertainties.

The metric names are those of docs/run-format.md ("A transmission error run"): ``te_pp_arcsec``
(GB/T 35089 transmission accuracy, the larger direction), ``te_pp_forward_arcsec``,
``te_pp_reverse_arcsec``, ``te_total_Fi_arcsec`` (ISO 1328-1 F'_i), ``te_tooth_fi_arcsec``
(ISO 1328-1 f'_i over one output tooth pitch), ``te_hysteresis_arcmin`` and ``te_orders``.

Standard uncertainties (arcsec unless named):

- encoder resolution: a reading of a ``N``-count encoder is within half a count, uniform:
  ``q / sqrt(12)`` with ``q = 1296000 / N`` arcsec; the input's divided by ``|i|``. Quantisation
  of a slowly turning shaft is systematic, so it is not divided by the samples averaged;
- sampling: the spread ``s`` of the samples about their bin means, divided by the root of the
  samples averaged in the bin;
- a TE value ``u_p = sqrt(s^2 / n + u_q^2)``; a peak-to-peak, a difference of two values:
  ``sqrt(2) u_p``;
- encoder mounting eccentricity (:mod:`analysis.transmission.eccentricity`): the uncertainty
  ``u_e`` of the removed term (or, when none was removed, a declared bound ``b`` as ``b/sqrt(3)``)
  adds ``sqrt(2) u_e`` to the peak-to-peak figures and ``u_e`` to the output order 1;
- orders: the least-squares covariance scaled by the residual variance; fitted on the
  complete output revolutions of each direction (the span of the grid), so that the orders of
  the output revolution are orthogonal and content the fit does not name does not leak in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from analysis.errors import AnalysisError
from analysis.transmission.curve import (
    DIRECTIONS,
    DirectionCurve,
    direction_curve,
    grid_size,
    te_arcsec,
)
from analysis.transmission.eccentricity import EncoderEccentricity
from analysis.transmission.figures import (
    hysteresis_arcmin,
    peak_to_peak_arcsec,
    tooth_to_tooth_arcsec,
    total_composite_arcsec,
)
from analysis.transmission.orders import (
    Order,
    OrderFit,
    fit_orders,
    order_number,
    standard_orders,
)

ARCSEC_PER_REV = 1_296_000.0
METRIC_KEYS = ("te_pp_arcsec", "te_pp_forward_arcsec", "te_pp_reverse_arcsec",
               "te_total_Fi_arcsec", "te_tooth_fi_arcsec", "te_hysteresis_arcmin")
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
    """TE metrics of a run (docs/run-format.md): curves per direction on the output-angle grid,
    GB/T 35089 peak-to-peak, ISO 1328-1 F'_i and f'_i, hysteresis, orders, uncertainties.

    ``encoder_eccentricity``: a calibrated encoder term, subtracted from TE before anything
    else; ``eccentricity_bound_arcsec``: when none is given, a declared bound of the encoder's
    once-per-turn error, carried as an uncertainty."""
    ratio = float(kinematics.ratio)
    out = np.asarray(output_angle_deg, dtype=float)
    inp = np.asarray(input_angle_deg, dtype=float)
    if out.shape != inp.shape:
        raise AnalysisError("output and input angle columns differ in length")
    d = directions_from_input(inp) if direction is None else np.nan_to_num(
        np.asarray(direction, dtype=float)).astype(int)
    te = te_arcsec(out, inp, ratio)
    notes = list(kinematics.notes)
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
    u_q = _u_quant_arcsec(output_counts_per_rev, input_counts_per_rev, ratio)

    revs_seen = np.ptp(out[np.isfinite(out)]) / 360.0 if np.isfinite(out).any() else 0.0
    mesh_out = (kinematics.mesh_per_input * abs(ratio)) if kinematics.mesh_per_input else None
    per_direction = max(int(np.count_nonzero(d != 0)) / 2.0, 1.0)  # samples of one direction
    n = n_grid or grid_size(mesh_out, per_direction / max(revs_seen, 1e-9))
    curves: dict[int, DirectionCurve] = {}
    masks: dict[int, np.ndarray] = {}
    for code in (1, -1):
        mask = d == code
        if mask.sum() < 2:
            raise AnalysisError(f"no {DIRECTIONS[code]} samples (direction {code}): a TE run "
                                "turns the input both ways")
        masks[code] = mask
        curves[code] = direction_curve(out[mask], te[mask], code, n)

    def u_point(c: DirectionCurve, averaged: bool) -> float:
        # samples in one bin of one revolution, or of the revolution-averaged curve
        n_avg = max(c.samples_per_bin * (c.revolutions if averaged else 1), 1.0)
        return math.sqrt(c.residual_std_arcsec**2 / n_avg + u_q**2)

    metrics: dict[str, float | None] = {}
    unc: dict[str, float | None] = {}
    pp = {c: peak_to_peak_arcsec(curves[c]) for c in curves}
    upp = {c: math.sqrt(2 * u_point(curves[c], False) ** 2 + 2 * u_ecc**2) for c in curves}
    metrics["te_pp_forward_arcsec"], unc["te_pp_forward_arcsec"] = pp[1], upp[1]
    metrics["te_pp_reverse_arcsec"], unc["te_pp_reverse_arcsec"] = pp[-1], upp[-1]
    worst = 1 if pp[1] >= pp[-1] else -1
    metrics["te_pp_arcsec"], unc["te_pp_arcsec"] = pp[worst], upp[worst]
    fi = {c: total_composite_arcsec(curves[c]) for c in curves}
    worst_fi = 1 if fi[1] >= fi[-1] else -1
    metrics["te_total_Fi_arcsec"] = fi[worst_fi]
    unc["te_total_Fi_arcsec"] = math.sqrt(2 * u_point(curves[worst_fi], True) ** 2
                                          + 2 * u_ecc**2)
    errors: dict[str, str] = {}
    teeth = kinematics.output_teeth
    if teeth:
        fpi = {c: tooth_to_tooth_arcsec(curves[c], teeth) for c in curves}
        worst_f = 1 if fpi[1] >= fpi[-1] else -1
        metrics["te_tooth_fi_arcsec"] = fpi[worst_f]
        unc["te_tooth_fi_arcsec"] = math.sqrt(2.0) * u_point(curves[worst_f], True)
    else:
        metrics["te_tooth_fi_arcsec"] = unc["te_tooth_fi_arcsec"] = None
        errors["te_tooth_fi_arcsec"] = "the output's tooth count is unknown (unit data)"
    metrics["te_hysteresis_arcmin"] = hysteresis_arcmin(curves[1], curves[-1])
    u_off = [math.sqrt(c.residual_std_arcsec**2 / max(c.n_samples, 1) + u_q**2 / c.grid_deg.size)
             for c in curves.values()]
    unc["te_hysteresis_arcmin"] = math.hypot(*u_off) / 60.0

    orders = standard_orders(ratio, crank_per_input=kinematics.crank_per_input,
                             mesh_per_input=kinematics.mesh_per_input, harmonics=harmonics,
                             extra=kinematics.extra_orders)
    fitted: list[tuple[int, OrderFit]] = []
    for code in (1, -1):
        # whole revolutions only: every order of the output is then orthogonal to the others
        lo, hi = curves[code].span_deg
        m = masks[code] & (out >= lo) & (out < hi)
        fits, _ = fit_orders(out[m], inp[m], te[m], orders, ratio=ratio,
                             crank_per_input=kinematics.crank_per_input,
                             mesh_per_input=kinematics.mesh_per_input)
        for f in fits:
            if f.order.per == "output_rev" and f.order.order == 1 and u_ecc:
                f = OrderFit(f.order, f.amplitude_arcsec, f.phase_deg,
                             math.hypot(f.amplitude_u_arcsec, u_ecc),
                             min(180.0, math.degrees(math.hypot(f.amplitude_u_arcsec, u_ecc)
                                                     / max(f.amplitude_arcsec, 1e-12))))
            fitted.append((code, f))
    return TEResult(curves=curves, metrics=metrics, uncertainty=unc, orders=fitted,
                    encoder_eccentricity=ecc_record, grid_points=n, output_teeth=teeth,
                    resolution_arcsec=u_q * math.sqrt(12.0), notes=notes, errors=errors)
