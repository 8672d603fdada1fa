"""Statistical process control of a production line: individuals/moving-range charts, the
Western Electric run rules, process capability. Pure numerics, any unit.

Individuals and moving-range (I-MR) charts, ISO 7870-2:2023 Table 3 / Montgomery,
*Introduction to Statistical Quality Control*, 8th ed., eqs. 6.33 and 6.34: for values
``x_1..x_n`` in time order, ``MR_i = |x_i - x_(i-1)|``, ``MRbar`` their mean,
``sigma_within = MRbar / d2`` with ``d2 = 1.128`` (subgroups of 2); individuals chart
centre ``xbar``, limits ``xbar ± 3 sigma_within``; moving-range chart centre ``MRbar``, upper
limit ``D4 MRbar`` with ``D4 = 3.267``, lower limit ``D3 MRbar = 0``.

A quantity that cannot be negative (``lower_bound = 0``: lost motion, backlash, hysteresis
loss, stiffness) gets a one-sided chart where ``xbar - 3 sigma_within`` falls below the bound:
the lower control limit is the bound itself, ``LCL = max(xbar - 3 sigma_within, lower_bound)``,
and the chart says so (``lcl_clipped``); the upper limit stays ``xbar + 3 sigma_within``. A
limit below zero could never be crossed, so the chart has no lower limit there: the rule
of the c chart (Montgomery, ch. 7: a negative LCL is set to zero) and of the moving-range
chart's ``D3 = 0``. The zones of the run rules stay ``xbar ± k sigma_within``.
An individuals chart of the logarithm was not chosen: a zero-backlash unit is measured at 0
exactly, whose logarithm does not exist, and the limits would be read in log arcmin.

Run rules on the individuals chart (Western Electric Handbook, 1956; the zones are 1, 2, 3
sigma_within from the centre), plus Nelson's trend rule; on the MR chart only rule 1:

- ``WE1``: one point beyond 3 sigma (outside a control limit);
- ``WE2``: 2 of 3 consecutive points beyond 2 sigma, on the same side;
- ``WE3``: 4 of 5 consecutive points beyond 1 sigma, on the same side;
- ``WE4``: 8 consecutive points on the same side of the centre;
- ``N3``: 6 consecutive points steadily increasing or decreasing (Nelson 1984, rule 3).

A violation is reported at every point that completes its pattern (the point itself beyond
the zone for WE1-WE3), with every point of the pattern: a run of 10 points above the centre
signals WE4 at its 8th, 9th and 10th point (the convention of common SPC software).

Capability, ISO 22514-2:2017 / Montgomery eqs. 8.5-8.8: ``Cp = (USL - LSL) / 6 sigma``,
``Cpk = min(USL - mean, mean - LSL) / 3 sigma`` with ``sigma = sigma_within``; ``Pp``,
``Ppk`` the same with the overall standard deviation (n - 1). With one limit only, Cp/Pp
are undefined (None) and Cpk/Ppk use that side.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from analysis.errors import AnalysisError

D2 = 1.128  # d2 for moving ranges of 2 (ISO 7870-2 Table 2)
D4 = 3.267  # D4 for moving ranges of 2
RULES = {
    "WE1": "one point beyond 3 sigma (outside a control limit)",
    "WE2": "2 of 3 consecutive points beyond 2 sigma on the same side",
    "WE3": "4 of 5 consecutive points beyond 1 sigma on the same side",
    "WE4": "8 consecutive points on the same side of the centre line",
    "N3": "6 consecutive points steadily increasing or decreasing",
}


@dataclass(frozen=True)
class Violation:
    """One out-of-control signal: the rule, the chart ("I" or "MR"), the point that
    completes the pattern and every point of the pattern (indices into the values)."""

    rule: str
    chart: str
    index: int
    points: tuple[int, ...]

    def to_dict(self) -> dict:
        return {"rule": self.rule, "chart": self.chart, "index": self.index,
                "points": list(self.points), "description": RULES[self.rule]}


@dataclass(frozen=True)
class IMRChart:
    """An individuals/moving-range chart of ``values`` (see the module doc)."""

    values: np.ndarray
    centre: float
    sigma_within: float
    ucl: float
    lcl: float
    moving_ranges: np.ndarray
    mr_centre: float
    mr_ucl: float
    violations: list[Violation] = field(default_factory=list)
    lcl_clipped: bool = False
    """True where ``centre - 3 sigma_within`` was below ``lower_bound``: LCL is the bound
    (a one-sided chart, module doc)."""
    lower_bound: float | None = None

    def to_dict(self) -> dict:
        return {
            "individuals": {"values": self.values.tolist(), "centre": self.centre,
                            "ucl": self.ucl, "lcl": self.lcl,
                            "lcl_clipped": self.lcl_clipped, "lower_bound": self.lower_bound},
            "moving_range": {"values": self.moving_ranges.tolist(), "centre": self.mr_centre,
                             "ucl": self.mr_ucl, "lcl": 0.0},
            "sigma_within": self.sigma_within,
            "violations": [v.to_dict() for v in self.violations],
        }


def imr_chart(values: np.ndarray | list[float], lower_bound: float | None = None) -> IMRChart:
    """The I-MR chart of ``values`` in time order, with its rule violations (>= 2 values).

    ``lower_bound``: the smallest value the quantity can take (0 for lost motion, backlash,
    stiffness; None: unbounded); the LCL is never below it (a one-sided chart, module doc).
    """
    x = np.asarray(values, dtype=float)
    if x.ndim != 1 or x.size < 2:
        raise AnalysisError(f"an individuals chart needs at least 2 values, got {x.size}")
    if not np.all(np.isfinite(x)):
        raise AnalysisError("an individuals chart needs finite values")
    mr = np.abs(np.diff(x))
    mr_bar = float(mr.mean())
    centre = float(x.mean())
    sigma = mr_bar / D2
    lcl = centre - 3.0 * sigma
    clipped = lower_bound is not None and lcl < lower_bound
    chart = IMRChart(values=x, centre=centre, sigma_within=sigma, ucl=centre + 3.0 * sigma,
                     lcl=float(lower_bound) if clipped else lcl, moving_ranges=mr,
                     mr_centre=mr_bar, mr_ucl=D4 * mr_bar, lcl_clipped=bool(clipped),
                     lower_bound=None if lower_bound is None else float(lower_bound))
    chart.violations.extend(run_rules(x, centre, sigma))
    chart.violations.extend(
        Violation("WE1", "MR", int(i) + 1, (int(i), int(i) + 1))
        for i in np.flatnonzero(mr > D4 * mr_bar))
    return chart


def run_rules(x: np.ndarray, centre: float, sigma: float) -> list[Violation]:
    """The individuals-chart rules WE1-WE4 and N3 (module doc), in point order."""
    out: list[Violation] = []
    z = (np.asarray(x, dtype=float) - centre) / sigma if sigma > 0 else np.zeros(len(x))
    n = len(z)
    for i in range(n):
        if abs(z[i]) > 3.0:
            out.append(Violation("WE1", "I", i, (i,)))
        for rule, window, need, beyond in (("WE2", 3, 2, 2.0), ("WE3", 5, 4, 1.0)):
            if i + 1 < window:
                continue
            w = range(i + 1 - window, i + 1)
            for side in (1.0, -1.0):
                hits = tuple(j for j in w if side * z[j] > beyond)
                if len(hits) >= need and hits[-1] == i:
                    out.append(Violation(rule, "I", i, hits))
        if i >= 7:
            w8 = z[i - 7:i + 1]
            if np.all(w8 > 0) or np.all(w8 < 0):
                out.append(Violation("WE4", "I", i, tuple(range(i - 7, i + 1))))
        if i >= 5:
            d = np.diff(np.asarray(x[i - 5:i + 1], dtype=float))
            if np.all(d > 0) or np.all(d < 0):
                out.append(Violation("N3", "I", i, tuple(range(i - 5, i + 1))))
    return out


def capability(values: np.ndarray | list[float], sigma_within: float, *,
               lsl: float | None = None, usl: float | None = None) -> dict:
    """Cp, Cpk (sigma_within), Pp, Ppk (overall sigma) against ``lsl``/``usl`` (module doc);
    None where a limit or the spread is missing."""
    x = np.asarray(values, dtype=float)
    mean = float(x.mean())
    overall = float(x.std(ddof=1)) if x.size > 1 else 0.0

    def indices(sigma: float) -> tuple[float | None, float | None]:
        if not sigma > 0 or (lsl is None and usl is None):
            return None, None
        sides = []
        if usl is not None:
            sides.append((usl - mean) / (3.0 * sigma))
        if lsl is not None:
            sides.append((mean - lsl) / (3.0 * sigma))
        cp = (usl - lsl) / (6.0 * sigma) if usl is not None and lsl is not None else None
        return cp, min(sides)

    cp, cpk = indices(sigma_within)
    pp, ppk = indices(overall)
    return {"n": int(x.size), "mean": mean, "sigma_within": sigma_within,
            "sigma_overall": overall, "lsl": lsl, "usl": usl, "cp": cp, "cpk": cpk,
            "pp": pp, "ppk": ppk}
