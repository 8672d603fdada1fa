"""The diagnosis as one self-contained HTML page (figures as inline base64 PNG, no CDN).

Plain words first (verdict, how far the gap shrinks, what to do next), then the loops with the
model before and after, the gap map, the free play against position and the ranking.
"""

from __future__ import annotations

import base64
import html
import io
import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from analysis.diagnosis import Diagnosis  # noqa: E402
from analysis.diagnosis.fit import predict_run  # noqa: E402


def _png(fig: Any) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


PANEL_IN = (3.6, 3.0)
"""Width and height (inch) of one panel of the page's loops and gap map: at the page's 90 dpi
about 320 px wide, so that a phone (390 px) shows one panel at its size, labels legible."""


def _loops_figures(diagnosis: Diagnosis, effects: tuple[str, ...] | None) -> list[str]:
    """The first four runs' loops with the model before and after, one PNG each."""
    stack = diagnosis.stack
    after = diagnosis.models.get(effects[0]) if effects else None
    out = []
    for i in range(min(stack.n_runs, 4)):
        fig, ax = plt.subplots(figsize=PANEL_IN)
        run = stack.runs[i]
        y = run.twist_arcmin - run.twist_arcmin.mean()
        r0 = predict_run(stack, diagnosis.base, ("backlash",), i)
        ax.plot(run.torque_Nm, y * 60, ".", ms=2, color="0.4", label="measured")
        ax.plot(run.torque_Nm, (y - r0) * 60, "-", lw=1, color="tab:red",
                label="model before")
        if after is not None:
            r1 = predict_run(stack, after.fit, ("backlash", *after.effects), i)
            ax.plot(run.torque_Nm, (y - r1) * 60, "-", lw=1, color="tab:green",
                    label="model after")
        ax.set_title(run.run_id, fontsize=8)
        ax.set_xlabel("torque (N·m)")
        ax.set_ylabel("twist (arcsec)")
        if i == 0:
            ax.legend(fontsize=7)
        out.append(_png(fig))
    return out


def _gap_map_figures(report: dict[str, Any]) -> list[str]:
    """One PNG per factor of the gap map (bins' flank-signed mean and rms of the
    standardised residuals); bin labels slanted and anchored at their tick, whole."""
    gm = report.get("gap_map") or {}
    out = []
    for k, name in enumerate(gm):
        fig, ax = plt.subplots(figsize=PANEL_IN)
        bins = gm[name]["bins"]
        labels = [str(b["bin"]) for b in bins]
        ax.bar(range(len(bins)), [b["flank_signed_mean_z"] for b in bins], color="tab:blue",
               alpha=0.6, label="flank-signed mean z")
        ax.plot(range(len(bins)), [b["rms_z"] for b in bins], "o-", color="tab:red", ms=3,
                label="rms z")
        ax.set_xticks(range(len(bins)), labels, rotation=45, ha="right",
                      rotation_mode="anchor", fontsize=7)
        ax.set_title(f"{name} ({gm[name]['share']:.0%})", fontsize=8)
        if k == 0:
            ax.legend(fontsize=7)
        out.append(_png(fig))
    return out


def _play_figure(report: dict[str, Any]) -> str | None:
    plays = [p for p in report.get("free_play_by_run") or [] if p["input_angle_deg"] is not None]
    if len({round(p["input_angle_deg"], 1) for p in plays}) < 2:
        return None
    fig, ax = plt.subplots(figsize=(5, 3))
    x = np.array([p["input_angle_deg"] for p in plays])
    y = np.array([p["play_arcmin"] for p in plays])
    ax.errorbar(x, y, yerr=[2 * p["se_arcmin"] for p in plays], fmt="o", ms=3)
    fourier = report.get("free_play_fourier")
    if fourier:
        grid = np.linspace(x.min(), x.max(), 400)
        th = np.radians(grid)
        curve = np.full_like(grid, fourier["mean_arcmin"])
        for k, a, ph in zip(fourier["orders"], fourier["amplitude_arcmin"],
                            fourier["phase_deg"], strict=True):
            curve += a * np.cos(k * th - math.radians(ph))
        ax.plot(grid, curve, "-", lw=1, label="Fourier fit")
        ax.legend(fontsize=7)
    ax.set_xlabel("input_angle_deg (eccentric shaft)")
    ax.set_ylabel("free play (arcmin)")
    return _png(fig)


def _plain_words(report: dict[str, Any]) -> str:
    v = report["verdict"]
    before = report["gap_before"]["rms_arcsec"]
    if v == "none":
        return (f"The model explains the measurements within the noise: the held-out gap is "
                f"{before:.2f} arcsec RMS against a noise of {report['noise_arcsec']:.2f} arcsec.")
    if v == "ambiguous":
        return (f"The gap ({before:.2f} arcsec RMS) is explained equally well by "
                f"{html.escape(', '.join(report.get('candidates', [])))}. "
                f"Next: {html.escape(str(report.get('next_experiment')))}.")
    if v == "unexplained":
        closest = report.get("candidates") or []
        return (f"A systematic gap of {before:.2f} arcsec RMS remains that no effect of the "
                + (f"vocabulary closes (closest: {html.escape(', '.join(closest))})." if closest
                   else "vocabulary closes; no effect of the vocabulary comes close."))
    after = report.get("gap_after", {}).get("rms_arcsec", math.nan)
    text = (f"The gap is caused by <b>{html.escape(v)}</b>: adding it shrinks the held-out gap "
            f"from {before:.2f} to {after:.2f} arcsec RMS (shrink {report.get('shrink', 0):.0%}).")
    for a in report.get("also", []):
        text += f" Also {html.escape(a['effect'])} (shrink {a['shrink']:.0%} of what is left)."
    return text


def render_html(report: dict[str, Any], diagnosis: Diagnosis,
                header: dict[str, str] | None = None) -> str:
    """The whole page (rig/templates/diagnosis.html); ``header``: the certificate's header
    of the campaign (:func:`rig.reports.certificate.header.header_for_campaign`: unit, serial,
    operator, date, rig, software), drawn first by the same partial."""
    from markupsafe import Markup

    from rig.reports.certificate.header import template_env

    verdict = report["verdict"]
    effects = (verdict,) if verdict in diagnosis.models else None
    ranking = []
    for r in report["ranking"]:
        after = (r.get("gap_after") or {}).get("rms_arcsec")
        ev = r.get("evidence", {})
        ranking.append({
            "effect": r["effect"],
            "shrink": "" if r.get("shrink") is None else format(r["shrink"], ".2f"),
            "after": "" if after is None else format(after, ".3f"),
            "delta_bic": ev.get("delta_bic", ""), "cv": str(ev.get("cv", "")),
            "fap": "" if r.get("false_alarm_probability") is None
            else format(r["false_alarm_probability"], ".2g"),
            "params": ", ".join(f"{k}={v:.4g}" for k, v in (r.get("params") or {}).items()
                                if isinstance(v, int | float)),
        })
    return template_env().get_template("diagnosis.html").render(
        report=report, header=header, campaign=str(report.get("campaign", "")),
        plain_words=Markup(_plain_words(report)),  # its own parts are escaped
        loops_pngs=_loops_figures(diagnosis, effects), gap_map_pngs=_gap_map_figures(report),
        play_png=_play_figure(report), ranking=ranking,
        measurement=_measurement_rows(report.get("measurement") or {}),
        self_check=self_check_words(report.get("self_check")))


def _share(entry: dict[str, Any], key: str = "gap_share") -> str:
    """A term's share of the gap (or of ``key``) in percent; empty when not given."""
    v = entry.get(key)
    return "" if v is None else f"{v:.0%}"


def _lag_row(lag: dict[str, Any]) -> dict[str, str]:
    return {"name": "torque channel lag", "share": _share(lag),
            "estimate": f"{1000.0 * (lag.get('median_s') or 0.0):.2f} ms (median)"}


def _transients_row(tr: dict[str, Any]) -> dict[str, str]:
    n = sum((tr.get("per_run_samples") or {}).values())
    return {"name": "transients after impacts", "share": _share(tr),
            "estimate": f"{n} samples left out"}


def _torque_zero_row(z: dict[str, Any]) -> dict[str, str]:
    est = ("not readable" if not z.get("runs_read") else
           f"common {z.get('common_Nm', 0.0):+.4f} N·m, scatter "
           f"{(z.get('scatter_Nm') or 0.0):.4f} N·m; {z.get('treated_as', '')}")
    return {"name": "torque zero (re-tare residual, drift)", "share": _share(z),
            "estimate": est}


def _friction_row(f: dict[str, Any]) -> dict[str, str]:
    return {"name": "ordinary friction", "share": _share(f),
            "estimate": f"{f.get('friction_Nm', 0.0):.4f} N·m"}


def _resolution_row(q: dict[str, Any]) -> dict[str, str]:
    return {"name": "resolution", "share": _share(q, "noise_share") + " of the noise",
            "estimate": f"encoder {q.get('twist_arcsec', 0.0):.3g} arcsec, torque "
                        f"{q.get('torque_Nm', 0.0):.3g} N·m"}


def _sample_times_row(t: dict[str, Any]) -> dict[str, str]:
    return {"name": "sample times", "share": "",
            "estimate": f"{1000.0 * (t.get('interval_s') or 0.0):.3g} ms, jitter "
                        f"{1000.0 * (t.get('jitter_s') or 0.0):.3g} ms, "
                        f"{t.get('gaps', 0)} gap(s)"}


_MEASUREMENT_TERMS = (
    ("torque_lag", _lag_row),
    ("impact_transients", _transients_row),
    ("torque_zero", _torque_zero_row),
    ("ordinary_friction", _friction_row),
    ("resolution", _resolution_row),
    ("sample_times", _sample_times_row),
)
"""(key of the report's ``measurement``, its row) in the order of the page's table."""


def _measurement_rows(m: dict[str, Any]) -> list[dict[str, str]]:
    """One row per measuring-system term of the report's ``measurement`` key."""
    rows = []
    for key, row in _MEASUREMENT_TERMS:
        entry = m.get(key) or {}
        if entry:
            rows.append(row(entry))
    return rows


def self_check_words(sc: dict[str, Any] | None) -> str:
    """'on 40 campaigns like this one: right 37, false alarms 0 of 8' (empty without one)."""
    if not sc:
        return ""
    text = (f"On {sc.get('cases', 0)} campaigns like this one: right {sc.get('correct', 0)}, "
            f"false alarms {sc.get('false_alarms', 0)} of {sc.get('nulls', 0)}")
    wrong = [k for k, v in (sc.get("per_effect") or {}).items()
             if isinstance(v, dict) and v.get("wrong")]
    if wrong:
        text += f"; missed or mistaken: {', '.join(sorted(wrong))}"
    return text + "."


def write_html(report: dict[str, Any], diagnosis: Diagnosis, path: str | Path,
               header: dict[str, str] | None = None) -> Path:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(render_html(report, diagnosis, header), encoding="utf-8")
    return p
