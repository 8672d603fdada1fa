"""The raw transmission error curve of a run, by the definition of docs/run-format.md
("A transmission error run"): ``TE = 3600 (output_angle_deg - input_angle_deg / ratio - c_d)``
(arcsec), ``c_d`` each direction's mean, against the output angle modulo 360 deg.

This is the curve as measured: nothing removed (the output encoder's mounting eccentricity
included). The analysis of a TE run (peak-to-peak with uncertainties, ISO 1328 F'_i/f'_i,
orders, the eccentricity's removal) is analysis/transmission; the rig uses this for the live
plot and as the run's first look.
"""

from __future__ import annotations

from typing import Any

import numpy as np

DIRECTIONS = {1: "forward", -1: "reverse"}


def te_arcsec(output_angle_deg: np.ndarray, input_angle_deg: np.ndarray,
              ratio: float) -> np.ndarray:
    """``3600 (output - input / ratio)`` (arcsec), before the per-direction mean."""
    out = np.asarray(output_angle_deg, dtype=float)
    inp = np.asarray(input_angle_deg, dtype=float)
    return 3600.0 * (out - inp / float(ratio))


def te_curves(output_angle_deg: np.ndarray, input_angle_deg: np.ndarray,
              direction: np.ndarray, ratio: float) -> dict[str, Any]:
    """Per direction (``forward``/``reverse``, rows with ``direction`` +1/-1; 0 is not
    analysed): ``output_deg`` (output angle modulo 360), ``te_arcsec`` (minus that
    direction's mean), ``pp_arcsec``, ``mean_arcsec`` (the ``c_d``) and ``n``; and, with both
    directions, ``hysteresis_arcmin`` (|forward mean - reverse mean| / 60) and ``pp_arcsec``
    (the larger direction's)."""
    raw = te_arcsec(output_angle_deg, input_angle_deg, ratio)
    d = np.asarray(direction, dtype=float)
    out = np.asarray(output_angle_deg, dtype=float)
    curves: dict[str, Any] = {}
    for sign, name in DIRECTIONS.items():
        keep = (d == sign) & np.isfinite(raw)
        if keep.sum() < 2:
            continue
        values = raw[keep]
        mean = float(values.mean())
        te = values - mean
        curves[name] = {"output_deg": np.mod(out[keep], 360.0), "te_arcsec": te,
                        "pp_arcsec": float(te.max() - te.min()), "mean_arcsec": mean,
                        "n": int(keep.sum())}
    if curves:
        curves["pp_arcsec"] = max(c["pp_arcsec"] for k, c in curves.items()
                                  if k in DIRECTIONS.values())
    if "forward" in curves and "reverse" in curves:
        curves["hysteresis_arcmin"] = abs(curves["forward"]["mean_arcsec"]
                                          - curves["reverse"]["mean_arcsec"]) / 60.0
    return curves


def te_summary(data: dict[str, np.ndarray], ratio: float) -> dict[str, Any]:
    """The raw figures of a TE run's columns (``output_angle_deg``, ``input_angle_deg``,
    ``direction``): ``pp_arcsec``, ``pp_forward_arcsec``, ``pp_reverse_arcsec``,
    ``hysteresis_arcmin`` (those present), the samples per direction, and the definition."""
    curves = te_curves(data["output_angle_deg"], data["input_angle_deg"], data["direction"],
                       ratio)
    out: dict[str, Any] = {"definition": "docs/run-format.md: TE = 3600 (output - input / "
                           "ratio - c_d), nothing removed"}
    for name in DIRECTIONS.values():
        if name in curves:
            out[f"pp_{name}_arcsec"] = curves[name]["pp_arcsec"]
            out[f"samples_{name}"] = curves[name]["n"]
    for key in ("pp_arcsec", "hysteresis_arcmin"):
        if key in curves:
            out[key] = curves[key]
    return out
