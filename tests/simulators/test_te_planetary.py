"""Seed 003 measured, not only computed (issue 22 "done when"): the simulated planetary plant
(simulators/plant/planetary.py, the paper train with one drawn unit's errors) turned forward
and back in simulated time under a brake torque, its readings analysed by rig/results/te.py as a
recorded run would be. The unit drawn inside the tolerances measures its plant's truth and
falls inside seed 003's Monte Carlo band, unflagged; the unit made outside them falls above
the band and is flagged."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rig.results.te import analyse_te_run
from rig.runformat import Run
from simulators.clock import ManualClock
from simulators.plant import GearPlant
from simulators.plant.config import PlantConfigError, load_plant_config
from simulators.plant.planetary import draw_unit
from tests.support.paths import REPO as ROOT

INSIDE = ROOT / "simulators" / "planetary_plant.toml"
OUTSIDE = ROOT / "simulators" / "planetary_plant_outside.toml"
BRAKE_NM = 2.0
SPEED = 18000.0  # deg/s of input (3000 rpm): one output revolution (320 input turns) in 6.4 s
DT = 0.002
RATIO = 320.0
COUNTS = 2**23  # both encoders of the simulated rig (rig.encoder_counts_per_rev)


def _read(angle_deg: float) -> float:
    """An encoder's reading (deg): the angle quantised to its counts, as the encoder node."""
    return round(angle_deg / 360.0 * COUNTS) * 360.0 / COUNTS


def _turn(plant: GearPlant, clock: ManualClock, speed: float, seconds: float, code: int,
          rows: list) -> None:
    plant.turn_input(speed)
    for k in range(int(round(seconds / DT))):
        clock.advance(DT)
        snap = plant.snapshot()
        rows.append((_read(snap.input_angle_deg), _read(snap.output_angle_deg),
                     code if k * DT >= 0.2 else 0))
    plant.stop_input()


def _measure(path: Path) -> tuple[Run, GearPlant]:
    """A TE run through the plant: forward (the output turns +, the brake pushes it -),
    reverse, 1.06 output revolutions each, the first 0.2 s of each turn not counted."""
    config = load_plant_config(path)
    clock = ManualClock()
    plant = GearPlant(config, clock)
    rows: list[tuple] = []
    plant.command_torque(-BRAKE_NM)
    clock.advance(0.2)
    plant.snapshot()
    _turn(plant, clock, SPEED, 6.8, 1, rows)
    plant.command_torque(BRAKE_NM)
    clock.advance(0.2)
    _turn(plant, clock, -SPEED, 6.8, -1, rows)
    data = np.array(rows, dtype=float)
    t = np.arange(len(rows)) * DT
    run = Run.from_arrays(
        path.stem, t, np.where(data[:, 2] >= 0, -BRAKE_NM, BRAKE_NM), data[:, 1],
        input_angle_deg=data[:, 0], unit=dict(config.unit),
        test={"kind": "transmission_error", "ratio": RATIO, "input_speed_rpm": SPEED / 6.0,
              "brake_torque_Nm": BRAKE_NM, "directions": ["forward", "reverse"],
              "output_revolutions": 1.0, "rated_torque_Nm": 20.0},
        sensors={"encoder_counts_per_rev": COUNTS, "input_encoder_counts_per_rev": COUNTS},
        extra_meta={"status": "completed"}, extra_columns={"direction": data[:, 2]})
    return run, plant


def _truth_pp(plant: GearPlant, item) -> dict[str, float]:
    """The plant's true peak-to-peak over the very output revolution each direction's curve
    was analysed on (its ``span_deg``)."""
    out = {}
    for code, name in ((1, "forward"), (-1, "reverse")):
        truth = plant.true_transmission_error(
            BRAKE_NM, output_window_deg=item.result.curves[code].span_deg)
        out[name] = truth[name]["pp_arcsec"]
    return out


def _print_figures(label: str, m: dict, truth: dict, pred) -> None:
    """The figures of docs/transmission-error.md
    (``pytest tests/simulators/test_te_planetary.py -s``)."""
    batch = pred.band["te_pp_arcsec"]
    print(f"\n{label}: measured pp forward {m['te_pp_forward_arcsec']:.2f} reverse "
          f"{m['te_pp_reverse_arcsec']:.2f} arcsec; truth {truth['forward']:.2f} / "
          f"{truth['reverse']:.2f}; band P0.5-P99.5 {batch[0]:.1f}-{batch[1]:.1f}, median unit "
          f"{pred.metrics['te_pp_arcsec']:.1f}; hysteresis {m['te_hysteresis_arcmin']:.3f}'")


def test_the_in_tolerance_unit_measures_its_truth_inside_the_seed003_band() -> None:
    run, plant = _measure(INSIDE)
    item = analyse_te_run(run)
    m = item.result.metrics
    truth = _truth_pp(plant, item)
    for name in ("forward", "reverse"):
        got = m[f"te_pp_{name}_arcsec"]
        assert abs(got - truth[name]) <= max(0.05 * truth[name], 2.0), (name, got, truth)
    pred = item.prediction
    assert pred is not None and pred.name.startswith("seed 003")
    low, high = pred.band["te_pp_arcsec"]
    _print_figures("inside", m, truth, pred)
    assert low < m["te_pp_arcsec"] < high
    cmp = item.comparison
    assert cmp is not None
    assert cmp["metrics"]["te_pp_arcsec"]["inside"] is True
    assert cmp["flagged"] == []
    # the hysteresis is the train's play plus both flanks' windup under the brake
    full = plant.true_transmission_error(BRAKE_NM,
                                         output_window_deg=item.result.curves[1].span_deg)
    assert m["te_hysteresis_arcmin"] == pytest.approx(full["te_hysteresis_arcmin"], rel=0.05)
    # the largest lines (stage III: once per output turn, the planet's 2.71) at their truth
    lines = {round(o["frequency_per_output_rev"], 6): o for o in full["te_orders"]}
    fits = {(round(o["frequency_per_output_rev"], 6), o["direction"]): o
            for o in item.result.orders_list()}
    for f in (1.0, round(84 / 31, 6)):
        for direction in ("forward", "reverse"):
            got = fits[(f, direction)]
            assert got["amplitude_arcsec"] == pytest.approx(lines[f]["amplitude_arcsec"],
                                                            rel=0.10)
            gap = (got["phase_deg"] - lines[f]["phase_deg"] + 180.0) % 360.0 - 180.0
            assert abs(gap) < 10.0, (f, direction, got, lines[f])


def test_the_unit_made_outside_the_tolerances_falls_above_the_band_and_is_flagged() -> None:
    run, plant = _measure(OUTSIDE)
    item = analyse_te_run(run)
    m = item.result.metrics
    truth = _truth_pp(plant, item)
    _print_figures("outside", m, truth, item.prediction)
    for name in ("forward", "reverse"):
        assert abs(m[f"te_pp_{name}_arcsec"] - truth[name]) <= max(0.05 * truth[name], 2.0)
    verdict = item.comparison["metrics"]["te_pp_arcsec"]
    assert verdict["inside"] is False and verdict["side"] == "above" and verdict["flag"] is True
    assert "te_pp_arcsec" in item.comparison["flagged"]
    assert m["te_pp_arcsec"] > item.prediction.band["te_pp_arcsec"][1]


def test_the_planetary_plant_records_every_injected_value() -> None:
    config = load_plant_config(INSIDE)
    plant = GearPlant(config, ManualClock())
    drawn = draw_unit(6)
    truth = plant.true_transmission_error(BRAKE_NM)
    sources = truth["injected"]["sources"]
    assert len(sources) == 20
    for name, value in drawn["errors_um"].items():
        assert sources[name]["value_um"] == value
        assert sources[name]["phase_deg"] == drawn["phases_deg"].get(name)
        assert abs(sources[name]["times_bound"]) <= 1.0  # inside seed 003's tolerances
    # the plant's output angle is the input's / 320 plus the twist: seed 003 eq. (11)
    params = plant.true_parameters()
    assert params["kind"] == "planetary" and params["ratio"] == -RATIO
    assert params["injected"]["sources"] == sources
    from simulators.plant.truth import generator_block

    block = generator_block(config, rated_torque_Nm=20.0)
    assert block["kind"] == "planetary"
    assert block["injected"]["planetary"]["errors_um"] == drawn["errors_um"]
    # the output turns with the input
    clock = ManualClock()
    moving = GearPlant(config, clock)
    moving.command_torque(-BRAKE_NM)
    moving.turn_input(3600.0)
    clock.advance(1.0)
    snap = moving.snapshot()
    assert snap.output_angle_deg == pytest.approx(snap.input_angle_deg / RATIO, abs=0.2)


def test_a_bad_planetary_table_is_named() -> None:
    config = load_plant_config(INSIDE)
    with pytest.raises(PlantConfigError, match=r"planetary\.errors_um\.E_x_I: no such seed 003"):
        config.with_changes(planetary={"errors_um": {"E_x_I": 3.0}})
    with pytest.raises(PlantConfigError, match=r"planetary\.phases_deg\.f_s_I: a tooth error"):
        config.with_changes(planetary={"phases_deg": {"f_s_I": 3.0}})
    with pytest.raises(PlantConfigError, match=r"unit\.backlash_um"):
        config.with_changes(unit={"backlash_um": [20.0]})
    with pytest.raises(ValueError, match=r"effects\.runout\.enabled: not for a planetary"):
        GearPlant(config.with_effect("runout"), ManualClock())


def test_the_in_tolerance_unit_reads_within_1pct_of_its_truth() -> None:
    # issue 32 item 1: without the 1-degree bins (which read 1.2 % low: the stage I sun's
    # 280 per turn and the stage II sun's 35 smoothed) every peak-to-peak is within 1 %
    run, plant = _measure(INSIDE)
    item = analyse_te_run(run, with_model=False)
    m, u = item.result.metrics, item.result.uncertainty
    truth = _truth_pp(plant, item)
    for name in ("forward", "reverse"):
        key = f"te_pp_{name}_arcsec"
        assert abs(m[key] - truth[name]) <= max(0.01 * truth[name], 2.0 * u[key]), (
            name, m[key], truth[name], u[key])
        assert abs(m[key] - truth[name]) <= 0.01 * truth[name]
