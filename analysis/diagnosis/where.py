"""Where the gap lies: gap map of standardised residuals, free play over position, lack of fit.

Pure numerics on the residuals of the calibrated nominal model (analysis.diagnosis.fit).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy import stats

from analysis.diagnosis.fit import LinearFit, Stack, run_columns


def _bins(values: np.ndarray, z: np.ndarray, zs: np.ndarray, labels: Sequence[Any],
          keys: np.ndarray) -> dict[str, Any]:
    rows = []
    total = float(np.sum(z**2)) or 1.0
    between = 0.0
    between_s = 0.0
    for lab in labels:
        m = keys == lab
        if not m.any():
            continue
        mean = float(z[m].mean())
        mean_s = float(zs[m].mean())
        between += m.sum() * mean**2
        between_s += m.sum() * mean_s**2
        rows.append({"bin": lab, "n": int(m.sum()), "mean_z": round(mean, 3),
                     "flank_signed_mean_z": round(mean_s, 3),
                     "rms_z": round(float(np.sqrt(np.mean(z[m] ** 2))), 3)})
    share = max(between, between_s) / total
    return {"bins": rows, "share": round(share, 4)}


def gap_map(stack: Stack, base: LinearFit) -> dict[str, dict[str, Any]]:
    """Standardised residuals z = r / sigma of the calibrated nominal model, binned by branch,
    torque band, position, temperature, amplitude and time since reversal. ``flank_signed``
    means s z (a play change shows there); ``share`` is the part of sum z^2 the bin means
    explain (0..1)."""
    z, zs, branch, band, pos, temp, amp, since = ([] for _ in range(8))
    for run in stack.runs:
        r = base.residual.get(run.run_id)
        if r is None:
            continue
        X = run_columns(stack, run, ["backlash"], base.nl, [])
        s = np.sign(X[:, 0])
        zz = r / run.sigma_arcmin
        z.append(zz)
        zs.append(s * zz)
        branch.append(np.where(run.branch >= 0, "loading", "unloading"))
        frac = np.abs(run.torque_Nm) / run.rated_torque_Nm
        band.append(np.select([frac < 0.05, frac < 0.2, frac < 0.5], ["0-5 %", "5-20 %",
                                                                       "20-50 %"], "50-100 %"))
        n = r.size
        pos.append(np.full(n, "?" if run.input_angle_deg is None
                           else f"{run.input_angle_deg:g}"))
        temp.append(np.full(n, "?" if run.mean_temperature_C is None
                            else f"{run.mean_temperature_C:.0f}"))
        amp.append(np.full(n, f"{run.amplitude_Nm:.3g}"))
        since.append(run.since_reversal_s)
    z_all = np.concatenate(z)
    zs_all = np.concatenate(zs)
    out: dict[str, dict[str, Any]] = {}
    cats = {"branch": np.concatenate(branch), "torque_band": np.concatenate(band),
            "position": np.concatenate(pos), "temperature": np.concatenate(temp),
            "amplitude": np.concatenate(amp)}
    for name, keys in cats.items():
        labels = list(dict.fromkeys(keys.tolist()))
        if name == "position":
            labels.sort(key=lambda v: float(v) if v != "?" else 0.0)
        out[name] = _bins(keys, z_all, zs_all, labels, keys)
    since_all = np.concatenate(since)
    edges = np.unique(np.quantile(since_all, [0, 0.2, 0.4, 0.6, 0.8, 1.0]))
    idx = np.clip(np.searchsorted(edges, since_all, side="right") - 1, 0, max(edges.size - 2, 0))
    labels = [f"{edges[i]:.2g}-{edges[i + 1]:.2g} s" for i in range(max(edges.size - 1, 1))] \
        if edges.size > 1 else ["all"]
    keys = np.array([labels[i] if i < len(labels) else labels[-1] for i in idx])
    out["time_since_reversal"] = _bins(keys, z_all, zs_all, labels, keys)
    return out


def per_run_play(stack: Stack, base: LinearFit) -> list[dict[str, Any]]:
    """Each run's own free play (arcmin), the calibrated compliance held: the play column
    refitted run by run (least squares, offset free), with its standard error."""
    out = []
    comp = base.coef("compliance")
    for run in stack.runs:
        X = run_columns(stack, run, ["backlash"], base.nl, [])
        y = run.twist_arcmin - X[:, 1] * comp
        a = X[:, 0] - X[:, 0].mean()
        yc = y - y.mean()
        den = float(a @ a)
        if den <= 0:
            continue
        play = float(a @ yc) / den
        resid = yc - a * play
        se = float(np.sqrt(max(resid @ resid, 0.0) / max(y.size - 2, 1) / den))
        out.append({"run_id": run.run_id, "input_angle_deg": run.input_angle_deg,
                    "temperature_C": run.mean_temperature_C, "play_arcmin": play,
                    "se_arcmin": se})
    return out


def play_fourier(plays: list[dict[str, Any]], max_order: int = 4) -> dict[str, Any] | None:
    """Free play over the eccentric-shaft angle as a Fourier series (order k: k cycles per
    crank revolution), least squares over the runs; amplitudes (arcmin) per order."""
    pts = [(p["input_angle_deg"], p["play_arcmin"]) for p in plays
           if p["input_angle_deg"] is not None]
    if len(pts) < 3:
        return None
    theta = np.radians([a for a, _ in pts])
    y = np.array([v for _, v in pts])
    n_distinct = len({round(a, 1) for a, _ in pts})
    order = min(max_order, (n_distinct - 1) // 2)
    if order < 1:
        return None
    cols = [np.ones_like(theta)]
    for k in range(1, order + 1):
        cols += [np.cos(k * theta), np.sin(k * theta)]
    A = np.column_stack(cols)
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    amps = [float(math.hypot(coef[2 * k - 1], coef[2 * k])) for k in range(1, order + 1)]
    phases = [float(math.degrees(math.atan2(coef[2 * k], coef[2 * k - 1])))
              for k in range(1, order + 1)]
    return {"mean_arcmin": float(coef[0]), "orders": list(range(1, order + 1)),
            "amplitude_arcmin": amps, "phase_deg": phases,
            "dominant_order": int(np.argmax(amps) + 1),
            "residual_rms_arcmin": float(np.sqrt(np.mean((y - A @ coef) ** 2)))}


def lack_of_fit(plays: list[dict[str, Any]], conditions: dict[str, tuple]) -> dict[str, Any] | None:
    """Lack-of-fit F test of the constant-play (nominal) model against the pure error of
    repeated conditions: between-condition against within-condition scatter of run plays."""
    groups: dict[tuple, list[float]] = {}
    for p in plays:
        groups.setdefault(conditions[p["run_id"]], []).append(p["play_arcmin"])
    reps = [g for g in groups.values() if len(g) >= 2]
    if not reps or len(groups) < 2:
        return None
    ss_pe = sum(float(np.sum((np.array(g) - np.mean(g)) ** 2)) for g in groups.values())
    df_pe = sum(len(g) - 1 for g in groups.values())
    grand = np.mean([v for g in groups.values() for v in g])
    ss_lof = sum(len(g) * (np.mean(g) - grand) ** 2 for g in groups.values())
    df_lof = len(groups) - 1
    if df_pe <= 0 or ss_pe <= 0:
        return None
    f = (ss_lof / df_lof) / (ss_pe / df_pe)
    return {"F": float(f), "df": [df_lof, df_pe], "p_value": float(stats.f.sf(f, df_lof, df_pe)),
            "pure_error_arcmin": float(math.sqrt(ss_pe / df_pe))}
