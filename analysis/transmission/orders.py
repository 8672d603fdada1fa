"""The TE spectrum by order: amplitudes and phases of the known orders, by least squares.

An order ``k`` ``per`` a member is ``k`` cycles per revolution of that member: ``output_rev``
(the output angle), ``input_rev`` (the input angle), ``crank`` (the crank shaft, turning
``crank_per_input`` times per input revolution) and ``mesh`` (the tooth mesh, ``mesh_per_input``
engagements per input revolution). Each term is ``A cos(k phi + p)`` (the Fourier convention
of the simulated plant's truth) with ``phi`` the member's own angle from its encoder
(``phi_input = input angle``, ``phi_output = output angle``, ``phi_crank = crank_per_input *
input``, ``phi_mesh = mesh_per_input * input``); seed 003's ``Im(W exp(i (nu psi + p)))`` is
the same term 90 deg later. Fitted on the samples themselves (not on a
folded grid), so an order that does not repeat once per output revolution (a non-integer
ratio) and a record that is not a whole number of revolutions are fitted without leakage,
unlike a raw FFT; the normal equations are accumulated by chunks (1M samples in bounded
memory). Orders that coincide in frequency (``input_rev`` 1 and ``crank`` 1 when the crank is
the input) are fitted once, under the first name.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis.errors import AnalysisError

PERS = ("output_rev", "input_rev", "crank", "mesh")
CHUNK = 131_072
NUISANCE_MIN_SEPARATION = 0.3
"""Least separation (cycles over the fitted record) of a nuisance whole order from a named
non-whole one: closer, the two are too collinear to be told apart."""


def order_number(order: float) -> int | float:
    """An order as JSON shows it: a whole number as an int (9, not 9.0)."""
    return int(order) if float(order).is_integer() else float(order)


@dataclass(frozen=True)
class Order:
    """An order to fit: ``order`` cycles per revolution of ``per``; ``frequency`` in cycles per
    output revolution (signed by the member's sense); ``source``: what causes it."""

    order: int
    per: str
    frequency: float
    source: str = ""


@dataclass(frozen=True)
class OrderFit:
    """Fitted ``A cos(k phi + p)``: amplitude (arcsec) and phase (deg) with standard
    uncertainties from the least-squares covariance."""

    order: Order
    amplitude_arcsec: float
    phase_deg: float
    amplitude_u_arcsec: float
    phase_u_deg: float

    def phasor(self) -> complex:
        """``A exp(i p)`` (arcsec)."""
        return self.amplitude_arcsec * np.exp(1j * np.radians(self.phase_deg))


def is_whole(frequency: float) -> bool:
    """Whether an order of ``frequency`` cycles per output revolution repeats every output
    revolution (a whole number of cycles, to 1e-9)."""
    return abs(frequency - round(frequency)) < 1e-9


def standard_orders(ratio: float, *, crank_per_input: float | None,
                    mesh_per_input: float | None, harmonics: int = 2,
                    extra: tuple[Order, ...] = ()) -> list[Order]:
    """The orders of a unit: 1..``harmonics`` per output, input, crank and mesh (those whose
    ratio is known), plus ``extra``; orders of equal frequency kept once."""
    per_input = 1.0 / abs(ratio)  # output revs per input rev
    members = [("output_rev", 1.0), ("input_rev", 1.0 / per_input)]
    if crank_per_input:
        members.append(("crank", crank_per_input / per_input))
    if mesh_per_input:
        members.append(("mesh", mesh_per_input / per_input))
    out: list[Order] = []
    seen: list[float] = []
    for per, f1 in members:
        for k in range(1, harmonics + 1):
            f = k * f1
            if any(abs(f - s) < 1e-9 * max(1.0, f) for s in seen):
                continue
            seen.append(f)
            out.append(Order(k, per, f))
    for o in extra:
        if not any(abs(o.frequency - s) < 1e-9 * max(1.0, o.frequency) for s in seen):
            seen.append(o.frequency)
            out.append(o)
    return out


def _member_angle_rad(order: Order, output_deg: np.ndarray, input_deg: np.ndarray,
                      crank_per_input: float | None, mesh_per_input: float | None,
                      ratio: float) -> np.ndarray:
    if order.per == "output_rev":
        return np.radians(output_deg)
    if order.per == "input_rev":
        return np.radians(input_deg)
    if order.per == "crank":
        return np.radians(input_deg) * float(crank_per_input or 0.0)
    if order.per == "mesh":
        return np.radians(input_deg) * float(mesh_per_input or 0.0)
    raise AnalysisError(f"unknown order reference {order.per!r}; known: {', '.join(PERS)}")


def _design(orders: list[Order], out_d: np.ndarray, in_d: np.ndarray,
            crank_per_input: float | None, mesh_per_input: float | None,
            ratio: float) -> np.ndarray:
    """The least-squares basis ``[1, sin, cos, ...]`` of ``orders`` at the given angles."""
    x = np.empty((out_d.size, 1 + 2 * len(orders)))
    x[:, 0] = 1.0
    for j, o in enumerate(orders):
        phi = o.order * _member_angle_rad(o, out_d, in_d, crank_per_input, mesh_per_input, ratio)
        x[:, 1 + 2 * j] = np.sin(phi)
        x[:, 2 + 2 * j] = np.cos(phi)
    return x


@dataclass(frozen=True)
class OrderModel:
    """A joint least-squares fit of orders (constant first): the coefficients and what is
    needed to evaluate the fitted sum at any angles (:meth:`evaluate`)."""

    orders: tuple[Order, ...]
    beta: np.ndarray
    ratio: float
    crank_per_input: float | None
    mesh_per_input: float | None

    def evaluate(self, output_deg: np.ndarray, input_deg: np.ndarray) -> np.ndarray:
        """The fitted sum (constant included), arcsec, chunk by chunk."""
        out_d = np.asarray(output_deg, dtype=float)
        in_d = np.asarray(input_deg, dtype=float)
        y = np.empty(out_d.size)
        for start in range(0, out_d.size, CHUNK):
            sl = slice(start, start + CHUNK)
            y[sl] = _design(list(self.orders), out_d[sl], in_d[sl], self.crank_per_input,
                            self.mesh_per_input, self.ratio) @ self.beta
        return y


def fit_order_model(output_deg: np.ndarray, input_deg: np.ndarray, te_arcsec: np.ndarray,
                    orders: list[Order], *, ratio: float, crank_per_input: float | None = None,
                    mesh_per_input: float | None = None, taper: bool = False
                    ) -> tuple[list[OrderFit], float, OrderModel]:
    """Least-squares amplitudes and phases of ``orders`` in one direction's TE samples, all
    fitted jointly with a constant (so no named order, whole or not, takes another's
    content); returns the fits, the residual standard deviation (arcsec) and the model.

    ``taper``: weight the samples by a Hann window over their output-angle span (for a record
    that is not a whole number of periods: content the fit does not name then leaks into a
    named order only from close by, -31 dB beyond two cycles over the record and falling
    18 dB per octave); the covariance is then the weighted fit's sandwich."""
    out_d = np.asarray(output_deg, dtype=float)
    in_d = np.asarray(input_deg, dtype=float)
    y_all = np.asarray(te_arcsec, dtype=float)
    ok = np.isfinite(out_d) & np.isfinite(in_d) & np.isfinite(y_all)
    out_d, in_d, y_all = out_d[ok], in_d[ok], y_all[ok]
    n_par = 1 + 2 * len(orders)
    if y_all.size <= n_par:
        raise AnalysisError(f"{y_all.size} samples are too few to fit {len(orders)} orders")
    if taper:
        lo, span = float(out_d.min()), max(float(np.ptp(out_d)), 1e-12)
        w_all = np.sin(np.pi * (out_d - lo) / span) ** 2
    else:
        w_all = None
    xtx = np.zeros((n_par, n_par))
    xtwx = np.zeros((n_par, n_par))
    xty = np.zeros(n_par)
    yty = 0.0
    sw = sw2 = 0.0
    for start in range(0, y_all.size, CHUNK):
        sl = slice(start, start + CHUNK)
        x = _design(orders, out_d[sl], in_d[sl], crank_per_input, mesh_per_input, ratio)
        y = y_all[sl]
        if w_all is None:
            xtx += x.T @ x
            xty += x.T @ y
            yty += float(y @ y)
        else:
            w = w_all[sl]
            xw = x * w[:, None]
            xtx += xw.T @ x
            xtwx += xw.T @ xw
            xty += xw.T @ y
            yty += float((w * y) @ y)
            sw += float(w.sum())
            sw2 += float(w @ w)
    try:
        cov_unscaled = np.linalg.inv(xtx)
    except np.linalg.LinAlgError:
        raise AnalysisError("the orders cannot be told apart on this record (singular fit); "
                            "record more output revolutions") from None
    beta = cov_unscaled @ xty
    rss = max(yty - float(beta @ xty), 0.0)
    if w_all is None:
        dof = max(y_all.size - n_par, 1)
        sigma = float(np.sqrt(rss / dof))
        cov = cov_unscaled * sigma**2
    else:
        n_eff = sw**2 / max(sw2, 1e-300)
        sigma = float(np.sqrt(rss / max(sw * (1.0 - n_par / max(n_eff, n_par + 1.0)), 1e-300)))
        cov = cov_unscaled @ xtwx @ cov_unscaled * sigma**2
    fits = []
    for j, o in enumerate(orders):
        a, b = beta[1 + 2 * j], beta[2 + 2 * j]  # a sin + b cos = A cos(phi + p)
        amp = float(np.hypot(a, b))
        phase = float(np.degrees(np.arctan2(-a, b)))
        c = cov[1 + 2 * j: 3 + 2 * j, 1 + 2 * j: 3 + 2 * j]
        u_amp = float(np.sqrt(max(c[0, 0] + c[1, 1], 0.0) / 2.0))
        u_phase = float(np.degrees(u_amp / amp)) if amp > 0 else 180.0
        fits.append(OrderFit(o, amp, phase, u_amp, min(u_phase, 180.0)))
    model = OrderModel(tuple(orders), beta, ratio, crank_per_input, mesh_per_input)
    return fits, sigma, model


def fit_orders(output_deg: np.ndarray, input_deg: np.ndarray, te_arcsec: np.ndarray,
               orders: list[Order], *, ratio: float, crank_per_input: float | None = None,
               mesh_per_input: float | None = None) -> tuple[list[OrderFit], float]:
    """Least-squares amplitudes and phases of ``orders`` in one direction's TE samples, with a
    constant; returns the fits and the residual standard deviation (arcsec)."""
    fits, sigma, _ = fit_order_model(output_deg, input_deg, te_arcsec, orders, ratio=ratio,
                                     crank_per_input=crank_per_input,
                                     mesh_per_input=mesh_per_input)
    return fits, sigma


def nuisance_orders(named: list[Order], span_revolutions: float) -> list[Order]:
    """Whole orders of the output revolution next to each named order that is not whole
    (``floor(f) - 2 .. ceil(f) + 2``: a tapered fit's main lobe), fitted with the named ones
    but not reported: they take the content of the output's whole orders (e.g. a gear's
    pitch errors) that would otherwise leak into the non-whole order beside them (issue 32
    item 4). A whole order closer than :data:`NUISANCE_MIN_SEPARATION` cycles over the
    record (``span_revolutions``) to the non-whole one is left out (the two could not be
    told apart)."""
    taken = {round(abs(o.frequency), 9) for o in named}
    out: list[Order] = []
    for o in named:
        f = abs(o.frequency)
        if is_whole(f):
            continue
        for k in range(max(1, int(np.floor(f)) - 2), int(np.ceil(f)) + 3):
            if round(float(k), 9) in taken:
                continue
            if abs(k - f) * max(span_revolutions, 1) < NUISANCE_MIN_SEPARATION:
                continue
            taken.add(round(float(k), 9))
            out.append(Order(k, "output_rev", float(k), "nuisance: whole output order"))
    return out
