"""An independent generator of transmission error runs with known truth (issue 32 item 7).

Written from the definitions of docs/run-format.md and docs/transmission-error.md only: no
code of simulators/ (the plant) nor of analysis/transmission/ is used. TE is
``3600 (output - input / ratio)`` arcsec; the unit's TE at the ideal output angle ``t``
(deg) of flank ``d`` (+1 forward, -1 reverse) is

    TE_d(t) = sum_j A_j cos(k_j phi_j(t) + p_j) + P(t) + d * lost_motion / 2

with ``phi`` the output angle (``output_rev``), the input angle ``ratio * t`` (``input_rev``)
or ``z * t`` (``mesh``: the output gear's ``z`` teeth pass the mesh once a turn), and ``P`` the
output gear's tooth positions (cumulative single pitch deviations, a linear hand-over across
``transition`` of a pitch at each tooth change, closing round the turn).

Sampling: the input turns at a constant speed; samples are taken at a nominal period with
jitter, and the sampler stalls a few times (no rows for a while, the input keeps turning);
the count per output revolution is not a whole number. Forward, a few rows standing still
(``direction`` 0), then reverse. Both encoders quantise; the output reading has white noise.

The truth of every figure is taken on the noise-free curve at 64 points per period of the
fastest component, over the output revolutions the analysis says it used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.ndimage import maximum_filter1d, minimum_filter1d

LOST_MOTION_ARCSEC = 180.0  # 3 arcmin


@dataclass(frozen=True)
class Term:
    per: str  # output_rev, input_rev, mesh
    order: float
    amplitude_arcsec: float
    phase_deg: float


@dataclass
class TruthCase:
    name: str
    ratio: float
    teeth: int
    revolutions: float
    counts: int
    samples_per_output_rev: float
    terms: tuple[Term, ...]
    pitch_sd_arcsec: float = 1.5
    transition: float = 0.2
    noise_arcsec: float = 0.1
    jitter: float = 0.3
    stalls: int = 3
    stall_samples: int = 40
    seed: int = 0
    pitch: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        rng = np.random.default_rng(1000 + self.seed)
        fpt = rng.normal(0.0, self.pitch_sd_arcsec, self.teeth)
        fpt -= fpt.mean()  # the positions close round the turn
        pos = np.cumsum(fpt)
        self.pitch = pos - pos.mean()

    # --- the truth --------------------------------------------------------------------
    def frequency(self, term: Term) -> float:
        """Cycles per output revolution."""
        return {"output_rev": 1.0, "input_rev": abs(self.ratio),
                "mesh": float(self.teeth)}[term.per] * term.order

    def _angle_deg(self, term: Term, t: np.ndarray) -> np.ndarray:
        if term.per == "output_rev":
            return t
        if term.per == "input_rev":
            return self.ratio * t
        return self.teeth * t

    def pitch_arcsec(self, t: np.ndarray) -> np.ndarray:
        """The output gear's tooth positions with a linear hand-over at each tooth change."""
        pitch_deg = 360.0 / self.teeth
        x = np.mod(t, 360.0) / pitch_deg
        j = np.floor(x).astype(int) % self.teeth
        frac = x - np.floor(x)
        here, prev = self.pitch[j], self.pitch[(j - 1) % self.teeth]
        w = np.clip(frac / self.transition, 0.0, 1.0)
        return prev + (here - prev) * w

    def te_arcsec(self, t: np.ndarray, d: int, *, terms: bool = True, pitch: bool = True
                  ) -> np.ndarray:
        y = np.zeros_like(t, dtype=float) + d * LOST_MOTION_ARCSEC / 2.0
        if terms:
            for term in self.terms:
                y += term.amplitude_arcsec * np.cos(np.radians(
                    term.order * self._angle_deg(term, t) + term.phase_deg))
        if pitch:
            y += self.pitch_arcsec(t)
        return y

    # --- the run ----------------------------------------------------------------------
    def columns(self, nan_rows: tuple[int, float, float] | None = None) -> dict[str, Any]:
        """The samples: ``t_s``, ``input_angle_deg``, ``output_angle_deg``, ``direction``,
        ``torque_Nm``. ``nan_rows``: (direction, from, to) fractions of that direction's rows
        whose input angle is NaN."""
        rng = np.random.default_rng(self.seed)
        span_out = self.revolutions * 360.0
        n = int(self.revolutions * self.samples_per_output_rev)
        speed_in = 600.0  # deg/s of input
        dt = span_out * abs(self.ratio) / speed_in / n
        parts_in, parts_d, parts_t = [], [], []
        t0 = 0.0
        start_out = 17.3
        for d in (1, -1):
            k = np.arange(n, dtype=float)
            tk = k * dt + rng.uniform(-self.jitter, self.jitter, n) * dt
            tk = np.sort(tk)
            keep = np.ones(n, bool)
            for s in rng.integers(n // 10, n - n // 10, self.stalls):
                keep[s: s + self.stall_samples] = False
            tk = tk[keep]
            moved = np.clip(tk * speed_in, 0.0, span_out * abs(self.ratio))
            if d == 1:
                t_ideal = start_out + moved / abs(self.ratio)
            else:
                t_ideal = start_out + span_out - moved / abs(self.ratio)
            parts_in.append(self.ratio * t_ideal)
            parts_d.append(np.full(tk.size, d))
            parts_t.append(t0 + tk)
            t0 = t0 + tk[-1] + 0.5
            if d == 1:
                rest = np.full(20, self.ratio * t_ideal[-1])
                parts_in.append(rest)
                parts_d.append(np.zeros(20, int))
                parts_t.append(t0 + np.arange(20) * dt)
                t0 += 20 * dt + 0.5
        inp = np.concatenate(parts_in)
        direction = np.concatenate(parts_d)
        t_s = np.concatenate(parts_t)
        t_ideal = inp / self.ratio
        te = np.zeros_like(inp)
        for d in (1, -1):
            m = direction == d
            te[m] = self.te_arcsec(t_ideal[m], d)
        rest = direction == 0
        te[rest] = self.te_arcsec(t_ideal[rest], 1)
        out = t_ideal + (te + rng.normal(0.0, self.noise_arcsec, te.size)) / 3600.0
        q = 360.0 / self.counts
        out_r = np.round(out / q) * q
        in_r = np.round(inp / q) * q
        if nan_rows is not None:
            d, a, b = nan_rows
            idx = np.flatnonzero(direction == d)
            in_r[idx[int(a * idx.size): int(b * idx.size)]] = np.nan
        torque = -np.sign(direction * np.sign(self.ratio)) * 1.0
        return {"t_s": t_s, "input_angle_deg": in_r, "output_angle_deg": out_r,
                "direction": direction.astype(float), "torque_Nm": torque.astype(float)}

    def run(self, nan_rows: tuple[int, float, float] | None = None) -> Any:
        from rig.runformat import Run

        c = self.columns(nan_rows)
        return Run.from_arrays(
            f"truth-{self.name}", c["t_s"], c["torque_Nm"], c["output_angle_deg"],
            input_angle_deg=c["input_angle_deg"],
            unit={"kind": "generic_gear", "serial": self.name, "output_teeth": self.teeth},
            test={"kind": "transmission_error", "ratio": self.ratio, "input_speed_rpm": 100.0,
                  "brake_torque_Nm": 1.0, "directions": ["forward", "reverse"],
                  "output_revolutions": self.revolutions, "rated_torque_Nm": 10.0,
                  "temperature_C": 20.0},
            sensors={"encoder_counts_per_rev": self.counts,
                     "input_encoder_counts_per_rev": self.counts},
            extra_meta={"generator": {"name": "tests/support/te_truth.py", "case": self.name}},
            extra_columns={"direction": c["direction"]})

    # --- the truth of each figure ---------------------------------------------------
    def _dense(self, lo: float, hi: float) -> np.ndarray:
        fastest = max([self.frequency(t) for t in self.terms] + [4.0 * self.teeth])
        per_rev = int(math.ceil(64 * fastest / self.teeth)) * self.teeth
        revs = int(round((hi - lo) / 360.0))
        return lo + np.arange(revs * per_rev) * (360.0 / per_rev)

    def truth(self, spans: dict[str, tuple[float, float]]) -> dict[str, float]:
        """Every figure over the output revolutions ``spans[direction] = (lo, hi)`` deg."""
        res: dict[str, float] = {}
        means = {}
        for d, name in ((1, "forward"), (-1, "reverse")):
            lo, hi = spans[name]
            t = self._dense(lo, hi)
            y = self.te_arcsec(t, d)
            revs = int(round((hi - lo) / 360.0))
            per_rev = t.size // revs
            res[f"te_pp_{name}_arcsec"] = float(np.ptp(y))
            res[f"te_total_Fi_{name}_arcsec"] = float(np.max(np.ptp(
                y.reshape(revs, per_rev), axis=1)))
            width = per_rev // self.teeth + 1
            res[f"fi_{name}"] = _sliding(y, width)
            # ISO f_is: the orders below z/2 removed: the terms by their frequency, the
            # (periodic) tooth positions by their Fourier orders over one turn
            short = np.zeros_like(t)
            for term in self.terms:
                if self.frequency(term) >= self.teeth / 2.0:
                    short += term.amplitude_arcsec * np.cos(np.radians(
                        term.order * self._angle_deg(term, t) + term.phase_deg))
            one = self.pitch_arcsec(t[:per_rev])
            spec = np.fft.rfft(one)
            spec[np.arange(spec.size) < self.teeth / 2.0] = 0.0
            short += np.tile(np.fft.irfft(spec, per_rev), revs)
            res[f"fis_{name}"] = _sliding(short, width)
            means[d] = float(y.mean())
        res["te_pp_arcsec"] = max(res["te_pp_forward_arcsec"], res["te_pp_reverse_arcsec"])
        res["te_total_Fi_arcsec"] = max(res["te_total_Fi_forward_arcsec"],
                                        res["te_total_Fi_reverse_arcsec"])
        res["te_tooth_fi_arcsec"] = max(res["fi_forward"], res["fi_reverse"])
        res["te_tooth_fi_short_wave_arcsec"] = max(res["fis_forward"], res["fis_reverse"])
        res["te_hysteresis_arcmin"] = abs(means[1] - means[-1]) / 60.0
        return res

    def order_amplitude(self, per: str, order: float) -> float:
        """The injected amplitude of an order (plus, for whole output orders, the tooth
        positions' Fourier amplitude at that order)."""
        amp = sum(t.amplitude_arcsec for t in self.terms if t.per == per and t.order == order)
        if per == "output_rev":
            n = 64 * self.teeth
            spec = np.fft.rfft(self.pitch_arcsec(np.arange(n) * 360.0 / n)) * 2.0 / n
            z = sum(t.amplitude_arcsec * np.exp(1j * np.radians(t.phase_deg))
                    for t in self.terms if t.per == per and t.order == order)
            amp = abs(z + spec[int(order)])
        return float(amp)


def _sliding(y: np.ndarray, width: int) -> float:
    hi = maximum_filter1d(y, size=width, mode="nearest")
    lo = minimum_filter1d(y, size=width, mode="nearest")
    return float(np.max(hi - lo))


def _terms(a1: float, phase: float) -> tuple[Term, ...]:
    return (Term("output_rev", 1, a1, phase), Term("output_rev", 2, 5.0, 40.0 + phase),
            Term("input_rev", 1, 6.0, -30.0), Term("input_rev", 2, 2.0, 75.0),
            Term("mesh", 1, 4.0, 10.0), Term("mesh", 2, 1.5, -120.0))


CASES: tuple[TruthCase, ...] = (
    TruthCase("r81-z40", 81.0, 40, 1.25, 2**20, 9876.5, _terms(20.0, 15.0), seed=1),
    TruthCase("r81-z37", 81.0, 37, 2.3, 2**23, 7321.7, _terms(12.0, -60.0), seed=2),
    TruthCase("r-59-z72", -59.0, 72, 1.6, 2**23, 11111.1, _terms(25.0, 100.0), seed=3),
    TruthCase("r-47/13-z47", -47.0 / 13.0, 47, 2.0, 2**20, 8333.3, _terms(8.0, 30.0),
              seed=4),
    TruthCase("r320-z96", 320.0, 96, 1.25, 2**23, 15555.5, _terms(30.0, -10.0), seed=5),
    TruthCase("r320-z60", 320.0, 60, 2.1, 2**20, 12345.6, _terms(18.0, 70.0), seed=6),
)
