"""The TE analysis against the simulated plant's truth (issue 22 "done when", without the
sequencer): the plant (simulators/plant, te-rig's kinematic error, tooth pitch deviations,
runout and encoder eccentricity) turned forward and back in simulated time under a brake
torque, its output and input readings analysed by rig/results/te.py as a recorded run would be, and
compared with ``GearPlant.true_transmission_error``."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.ndimage import maximum_filter1d, minimum_filter1d

from analysis.transmission import model_internal as mi
from rig.results.te import analyse_te_run, reversal_calibration
from rig.runformat import Run
from simulators.clock import ManualClock
from simulators.plant import GearPlant
from simulators.plant.config import load_plant_config
from tests.support.paths import REPO

UNITS = REPO / "rig/examples/units"
BRAKE_NM = 2.0
SPEED = 720.0  # deg/s of input: one output revolution in 4 s
DT = 0.0005


def _config(pair: int, *, offset_deg: float = 0.0, ecc_arcsec: float = 0.0):
    unit = json.loads((UNITS / f"seed000-pair{pair}.json").read_text())
    return (load_plant_config().nominal().with_changes(unit=unit)
            .with_effect("kinematic_error", beta_deg=30.0, internal_phase_deg=-50.0)
            .with_effect("runout", beta_deg=30.0, internal_phase_deg=-50.0)
            .with_effect("tooth_spacing_error", thickness_error_um_rms=0.0,
                         pitch_error_um_rms=2.0, transition_fraction=0.5)
            .with_changes(rig={"output_offset_deg": offset_deg,
                               "encoder_eccentricity_arcsec": ecc_arcsec,
                               "encoder_eccentricity_phase_deg": 40.0}))


def _turn(plant, clock, speed, seconds, code, rows):
    plant.turn_input(speed)
    for k in range(int(round(seconds / DT))):
        clock.advance(DT)
        snap = plant.snapshot()
        rows.append((clock.now_s(),
                     snap.input_angle_deg, snap.output_angle_deg,
                     code if k * DT >= 0.1 else 0))
    plant.stop_input()


def _measure(config, run_id: str, calibration=None) -> tuple[Run, dict]:
    """A TE run through the plant: forward (brake +), reverse (brake -), 1.1 output
    revolutions each, the first 0.1 s of each turn marked as turning round (direction 0)."""
    clock = ManualClock()
    plant = GearPlant(config, clock)
    truth = plant.true_transmission_error(BRAKE_NM)
    rows: list[tuple] = []
    plant.command_torque(BRAKE_NM)  # forward: the output turns negative, the brake pushes +
    clock.advance(0.2)
    plant.snapshot()
    _turn(plant, clock, SPEED, 4.5, 1, rows)
    plant.command_torque(-BRAKE_NM)
    clock.advance(0.2)
    _turn(plant, clock, -SPEED, 4.5, -1, rows)
    data = np.array(rows, dtype=float)
    t = np.arange(len(rows)) * DT
    meta = {"status": "completed"}
    if calibration:
        meta["calibration"] = calibration
    run = Run.from_arrays(
        run_id, t, np.where(data[:, 3] >= 0, BRAKE_NM, -BRAKE_NM), data[:, 2],
        input_angle_deg=data[:, 1], unit={**config.unit, "kind": "internal_involute"},
        test={"kind": "transmission_error", "ratio": -8.0, "input_speed_rpm": SPEED / 6.0,
              "brake_torque_Nm": BRAKE_NM, "directions": ["forward", "reverse"],
              "output_revolutions": 1.1, "rated_torque_Nm": 10.0,
              "coupling_index_deg": config.rig.output_offset_deg % 360.0},
        sensors={}, extra_meta=meta, extra_columns={"direction": data[:, 3]})
    return run, truth


def _direct(truth: dict) -> tuple[float, float]:
    """F'_i and f'_i computed directly on the truth's curves (5760 points per revolution,
    a 9 deg window = 144 points)."""
    fi_total, fi_tooth = 0.0, 0.0
    for name in ("forward", "reverse"):
        te = truth[name]["te_arcsec"]
        w = te.size // 40 + 1
        fi_total = max(fi_total, float(np.ptp(te)))
        fi_tooth = max(fi_tooth, float(np.max(maximum_filter1d(te, w, mode="wrap")
                                             - minimum_filter1d(te, w, mode="wrap"))))
    return fi_total, fi_tooth


@pytest.mark.parametrize("pair", [1, 2, 3, 4])
def test_te_measured_through_the_plant_matches_its_truth(pair: int) -> None:
    run, truth = _measure(_config(pair), f"pair{pair}")
    item = analyse_te_run(run, model_samples=300)
    m = item.result.metrics
    assert abs(m["te_pp_arcsec"] - truth["te_pp_arcsec"]) <= max(
        0.05 * truth["te_pp_arcsec"], 2.0)
    fi_total, fi_tooth = _direct(truth)
    assert m["te_total_Fi_arcsec"] == pytest.approx(fi_total, rel=0.05)
    assert m["te_tooth_fi_arcsec"] == pytest.approx(fi_tooth, rel=0.05)
    assert m["te_hysteresis_arcmin"] == pytest.approx(truth["te_hysteresis_arcmin"], rel=0.05)
    orders = {(o["per"], o["order"], o["direction"]): o for o in item.result.orders_list()}
    for t in truth["te_orders"]:
        if t["order"] == 8:  # once per input turn: cos(8 theta_out + q) = cos(theta_in - q)
            got = orders[("input_rev", 1, t["direction"])]
            phase = -t["phase_deg"]
        else:
            got = orders[("output_rev", t["order"], t["direction"])]
            phase = t["phase_deg"]
        assert got["amplitude_arcsec"] == pytest.approx(t["amplitude_arcsec"], rel=0.10)
        assert abs((got["phase_deg"] - phase + 180.0) % 360.0 - 180.0) < 10.0, t


def test_the_seed000_model_is_the_plants_truth_and_pair1_is_inside_its_band() -> None:
    config = _config(1)
    truth = GearPlant(config, ManualClock()).true_transmission_error(BRAKE_NM)
    unit = {**config.unit, "kind": "internal_involute", "runout_phase_deg": 30.0,
            "runout_internal_phase_deg": -50.0,
            "pitch_internal_um": truth["injected"]["pitch_internal_um"],
            "pitch_external_um": truth["injected"]["pitch_external_um"]}
    geo = mi.geometry_from_unit(unit)
    errors = mi.unit_errors(geo, unit)
    for name, s in (("forward", 1), ("reverse", -1)):
        mine = mi.unit_curves(geo, errors, truth[name]["input_angle_deg"])[s][0]
        # the plant hands the load over linearly near each pitch boundary; the model steps
        near = np.abs(mine - truth[name]["te_arcsec"])
        assert np.median(near) < 1.0
    run, _ = _measure(config, "pair1-band")
    item = analyse_te_run(run, model_samples=400)
    assert item.comparison is not None and item.comparison["flagged"] == []
    assert item.comparison["metrics"]["te_pp_arcsec"]["inside"] is True


def test_a_20_arcsec_encoder_eccentricity_is_separated_and_removed() -> None:
    ecc = 20.0
    a, _ = _measure(_config(1, ecc_arcsec=ecc), "cal-0")
    b, _ = _measure(_config(1, offset_deg=180.0, ecc_arcsec=ecc), "cal-180")
    cal = reversal_calibration(a, b)
    assert cal["eccentricity_arcsec"] == pytest.approx(ecc, abs=1.0)
    # the plant's E sin(reading + 40 deg) is E cos(reading - 50 deg)
    assert cal["eccentricity_phase_deg"] == pytest.approx(-50.0, abs=3.0)
    entry = {"sensor": "encoder", "id": "ENC", "certificate": "reversal", "date": "2026-11-26",
             "due": "2027-11-26", "uncertainty": "-",
             **{k: v for k, v in cal.items() if k.startswith("eccentricity")}}
    run, truth = _measure(_config(1, ecc_arcsec=ecc), "after", calibration=[entry])
    item = analyse_te_run(run, with_model=False)
    m = item.result.metrics
    assert abs(m["te_pp_arcsec"] - truth["te_pp_arcsec"]) <= max(
        0.05 * truth["te_pp_arcsec"], 2.0)
    order1 = [o for o in item.result.orders_list() if o["per"] == "output_rev"
              and o["order"] == 1]
    assert all(o["amplitude_arcsec"] < 1.0 for o in order1)  # not in the unit's TE
    raw = analyse_te_run(_measure(_config(1, ecc_arcsec=ecc), "raw")[0], with_model=False)
    assert max(o["amplitude_arcsec"] for o in raw.result.orders_list()
               if o["per"] == "output_rev" and o["order"] == 1) == pytest.approx(ecc, abs=1.0)
    assert math.isfinite(item.result.uncertainty["te_pp_arcsec"])
