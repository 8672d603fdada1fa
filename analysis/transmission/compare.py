"""Where the measured TE departs from the model: figure by figure and order by order, the
gap ``measured - model`` and whether the measurement lies in the model's band (the TE
counterpart of the loop's gap map).

A measured value is outside the band when even its ``k = 2`` expanded interval, widened by
the encoders' resolution ``q`` (the least change the rig can see), misses it:
``value - 2u - q > high`` (above: flagged, the unit has more TE than a unit made within the
tolerances can have) or ``value + 2u < low`` (below: reported, not flagged; a better unit than
the band's lower end is no fault of the unit). Without a band (a deterministic model such as
seed 001's TCA), a gap beyond ``2u`` and 10 % of the model value is flagged.
"""

from __future__ import annotations

from typing import Any

from analysis.transmission.analyse import METRIC_KEYS, TEResult
from analysis.transmission.model import TEPrediction

COVERAGE = 2.0
RELATIVE_TOLERANCE = 0.10


def _verdict(value: float, u: float, model: float | None, band: list[float] | None,
             q: float = 0.0) -> dict[str, Any]:
    out: dict[str, Any] = {"measured": value, "u": u, "model": model,
                           "gap": None if model is None else value - model}
    if band is not None:
        low, high = band
        out["band"] = [low, high]
        if value - COVERAGE * u - q > high:
            out.update(inside=False, side="above", flag=True)
        elif value + COVERAGE * u + q < low:
            out.update(inside=False, side="below", flag=False)
        else:
            out.update(inside=True, side=None, flag=False)
    elif model is not None:
        far = abs(value - model) > max(COVERAGE * u + q, RELATIVE_TOLERANCE * abs(model))
        out.update(inside=not far, side=(None if not far else
                                         ("above" if value > model else "below")), flag=far)
    else:
        out.update(inside=None, side=None, flag=False)
    return out


def compare(result: TEResult, prediction: TEPrediction) -> dict[str, Any]:
    """``{"metrics": {name: verdict}, "orders": [verdict per order and direction], "flagged":
    [names]}``; each verdict has ``measured``, ``u``, ``model``, ``gap``, ``band``, ``inside``,
    ``side`` and ``flag``."""
    metrics: dict[str, Any] = {}
    flagged: list[str] = []
    for key in METRIC_KEYS:
        value, model = result.metrics.get(key), prediction.metrics.get(key)
        if value is None:
            continue
        band = (prediction.band or {}).get(key) if prediction.band is not None else None
        v = _verdict(value, result.uncertainty.get(key) or 0.0, model, band,
                     0.0 if key.endswith("arcmin") else result.resolution_arcsec)
        metrics[key] = v
        if v["flag"]:
            flagged.append(key)
    model_orders = {(round(o["frequency_per_output_rev"], 9), o["direction"]): o
                    for o in prediction.orders}
    orders = []
    for entry, u_entry in zip(result.orders_list(), result.orders_u_list(), strict=True):
        f = round(entry["frequency_per_output_rev"], 9)
        m = model_orders.get((f, entry["direction"]))
        band = prediction.order_band.get(entry["frequency_per_output_rev"]) \
            if prediction.band is not None else None
        if band is None and prediction.band is not None:
            band = next((b for k, b in prediction.order_band.items() if abs(k - f) < 1e-6),
                        None)
        v = _verdict(entry["amplitude_arcsec"], u_entry["amplitude_arcsec"],
                     None if m is None else m["amplitude_arcsec"], band, result.resolution_arcsec)
        v.update(order=entry["order"], per=entry["per"], direction=entry["direction"],
                 frequency_per_output_rev=entry["frequency_per_output_rev"],
                 source=entry.get("source") or (m or {}).get("source", ""))
        if m is not None and m.get("phase_deg") is not None:
            v["phase_gap_deg"] = (entry["phase_deg"] - m["phase_deg"] + 180.0) % 360.0 - 180.0
        orders.append(v)
        if v["flag"]:
            flagged.append(f"{entry['per']} {entry['order']:g} ({entry['direction']})")
    return {"metrics": metrics, "orders": orders, "flagged": flagged}
