"""Transmission error analysis speed (issue 22): 1,000,000 samples (a forward and a reverse
output revolution of the seed 000 pair) through :func:`analysis.transmission.analyse_te`
(curves, figures, orders, uncertainties; target 5 s), and the seed 000 model's Monte Carlo
band of 1,000 units beside it. The data are tests' synthetic TE (analysis.transmission
.synthetic): the model's own curve of a unit inside seed 000 Table 1, 2^23 / 2^17-count
encoders, 0.2 arcsec noise. ``pp_error_arcsec``: measured minus true peak-to-peak.

``cpu_s`` and the load average before the run tell a slow machine from a slow program. The
acquisition's sustained sample rate is measured by the acquisition side (issue 22 item 1)."""

from __future__ import annotations

import os
import resource
import time
from collections.abc import Iterator

import numpy as np

from analysis.transmission import analyse_te
from analysis.transmission import model_internal as mi
from analysis.transmission.model import internal_prediction
from analysis.transmission.synthetic import synthetic_te

UNIT = {"kind": "internal_involute", "z_internal": 45, "z_external": 40, "module_mm": 1.0,
        "runout_internal_mm": 0.018, "runout_external_mm": 0.012, "runout_phase_deg": 35.0}
TARGET_S = 5.0
MODEL_TARGET_S = 5.0


def run() -> Iterator[dict]:
    geo = mi.geometry_from_unit(UNIT)
    errors = mi.unit_errors(geo, UNIT)

    def te(out, inp, d):
        return mi.unit_curves(geo, errors, inp)[d][0]

    n_per_rev = 500_000
    s = synthetic_te(te, ratio=geo.ratio, revolutions=1.0, margin=0.0,
                     samples_per_output_rev=n_per_rev, noise_arcsec=0.2, turn_samples=0)
    truth = max(float(np.ptp(c)) for c in mi.unit_curves(
        geo, errors, mi.input_angles_deg(geo, per_mesh=16)).values())
    kin = geo.kinematics()
    w = synthetic_te(te, ratio=geo.ratio, samples_per_output_rev=5_000)
    analyse_te(w.output_angle_deg, w.input_angle_deg, w.direction, kin)  # warm up
    load_before = os.getloadavg()[0]
    cpu_start, start = time.process_time(), time.perf_counter()
    result = analyse_te(s.output_angle_deg, s.input_angle_deg, s.direction, kin,
                        output_counts_per_rev=2**23, input_counts_per_rev=2**17)
    elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    yield {"name": "te_analysis_1M_samples", "value": round(elapsed, 3), "unit": "s",
           "target": TARGET_S, "ok": elapsed < TARGET_S, "samples": int(s.t_s.size),
           "cpu_s": round(cpu, 3), "load_avg_1min_before": round(load_before, 2),
           "pp_arcsec": round(result.metrics["te_pp_arcsec"], 2),
           "pp_error_arcsec": round(result.metrics["te_pp_arcsec"] - truth, 3),
           "peak_rss_MiB": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)}
    start = time.perf_counter()
    pred = internal_prediction(UNIT, samples=1000)
    elapsed = time.perf_counter() - start
    yield {"name": "te_model_band_1000_units", "value": round(elapsed, 3), "unit": "s",
           "target": MODEL_TARGET_S, "ok": elapsed < MODEL_TARGET_S,
           "band_pp_arcsec": [round(v, 1) for v in (pred.band or {})["te_pp_arcsec"]]}
