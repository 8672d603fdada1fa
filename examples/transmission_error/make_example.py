"""The example of docs/transmission-error.md: a seed 000 pair 1 unit's TE run, made from the
seed 000 model (numerics only, no rig), analysed as ``rig analyse`` does, drawn into
docs/img/te-example.png; prints the figures the document quotes.

    python examples/transmission_error/make_example.py [RUN_FOLDER]

The unit: pair 1 of seed 000 (Table 3 runouts 22 and 15 um, phases 35 and -60 deg), tooth
positions from single pitch deviations drawn within grade 7 / grade 6 (seed 0), a 20 arcsec
encoder-mounting eccentricity that the rig's calibration (found by the reversal) removes.
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from analysis.transmission import model_internal as mi
from analysis.transmission.synthetic import synthetic_te
from rig.reports.te_plots import plot_te
from rig.results.te import analyse_te_run, reversal_calibration
from rig.runformat import Run, read_run, write_run

ROOT = Path(__file__).resolve().parents[2]
UNIT = json.loads((ROOT / "rig/examples/units/seed000-pair1.json").read_text())


def make_unit() -> dict:
    rng = np.random.default_rng(0)
    unit = {**UNIT, "serial": "P1-TE-EXAMPLE", "runout_phase_deg": 35.0,
            "runout_internal_phase_deg": -60.0}
    unit["pitch_internal_um"] = [round(float(v), 3) for v in mi.positions_from_single_pitch(
        rng.uniform(-5.0, 5.0, 45))[0]]
    unit["pitch_external_um"] = [round(float(v), 3) for v in mi.positions_from_single_pitch(
        rng.uniform(-3.5, 3.5, 40))[0]]
    return unit


def make_run(unit: dict, run_id: str, *, index_deg: float = 0.0, seed: int = 0,
             calibration: list | None = None) -> Run:
    geo = mi.geometry_from_unit(unit)
    errors = mi.unit_errors(geo, unit)

    def te(out, inp, d):
        return mi.unit_curves(geo, errors, inp)[d][0]

    from analysis.models.nominal import reference_nominal_model

    ref = reference_nominal_model({k: v for k, v in unit.items()
                                   if k in mi.InternalGeometry.__dataclass_fields__
                                   or k in UNIT})
    hyst = ref.play_arcmin + 2.0 * 1.0 / ref.stiffness_Nm_per_arcmin
    s = synthetic_te(te, ratio=geo.ratio, samples_per_output_rev=40_000, noise_arcsec=0.3,
                     hysteresis_arcsec=60.0 * hyst, ecc_amplitude_arcsec=20.0,
                     ecc_phase_deg=50.0, index_deg=index_deg, seed=seed)
    meta = {"status": "completed", "limits": {"te_pp_max_arcsec": 600.0,
                                              "te_hysteresis_max_arcmin": 8.0}}
    if calibration:
        meta["calibration"] = calibration
    return Run.from_arrays(
        run_id, s.t_s, s.torque_Nm, s.output_angle_deg, input_angle_deg=s.input_angle_deg,
        unit=unit, extra_meta=meta,
        test={"kind": "transmission_error", "ratio": geo.ratio, "input_speed_rpm": 60.0,
              "brake_torque_Nm": 1.0, "brake_torque_fraction": 0.1,
              "directions": ["forward", "reverse"], "output_revolutions": 1.1,
              "rated_torque_Nm": 10.0, "temperature_C": 20.0},
        sensors={"encoder_counts_per_rev": 2**23, "input_encoder_counts_per_rev": 2**17},
        extra_columns={"direction": s.direction.astype(float)})


def main(argv: list[str]) -> None:
    unit = make_unit()
    cal = reversal_calibration(make_run(unit, "cal-0"), make_run(unit, "cal-180",
                                                                 index_deg=180.0, seed=1))
    entry = {"sensor": "encoder", "id": "ENC-EXAMPLE", "certificate": "reversal example",
             "date": "2026-11-26", "due": "2027-11-26", "uncertainty": "see eccentricity",
             **{k: round(v, 3) for k, v in cal.items() if k.startswith("eccentricity")}}
    folder = Path(argv[0]) if argv else Path(tempfile.mkdtemp()) / "te-example"
    write_run(make_run(unit, "te-example", seed=2, calibration=[entry]), folder)
    item = analyse_te_run(read_run(folder))
    png = plot_te(item, ROOT / "docs/img/te-example.png",
                  title="Seed 000 pair 1: transmission error", limit_arcsec=600.0)
    d = item.to_dict()
    m = d["metrics"]
    print(f"run folder: {folder}; picture: {png.relative_to(ROOT)}")
    print(f"calibration (reversal): {json.dumps({k: round(v, 2) for k, v in cal.items()})}")
    for key in ("te_pp_arcsec", "te_pp_forward_arcsec", "te_pp_reverse_arcsec",
                "te_total_Fi_arcsec", "te_tooth_fi_arcsec", "te_hysteresis_arcmin"):
        band = (d["model"].get("band") or {}).get(key)
        print(f"{key}: {m[key]:.2f} ± {m[key + '_u']:.2f}  model {d['model'][key]:.2f}"
              + (f"  band [{band[0]:.1f}, {band[1]:.1f}]" if band else ""))
    for o in sorted((o for o in m["te_orders"] if o["direction"] == "forward"),
                    key=lambda o: -o["amplitude_arcsec"])[:5]:
        print(f"order {o['order']:g} per {o['per']}: {o['amplitude_arcsec']:.2f} arcsec "
              f"at {o['phase_deg']:.1f} deg")
    print(f"flagged: {d['comparison']['flagged']}")


if __name__ == "__main__":
    main(sys.argv[1:])
