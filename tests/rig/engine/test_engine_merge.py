"""Channel merging: the encoder is the master clock, torque interpolated, nothing invented."""

from __future__ import annotations

import math

import pytest

from rig.engine.merge import ChannelMerger, ControlLog, ControlState
from rig.engine.safety import (
    PlanRejected,
    TorqueLimitExceeded,
    check_command,
    check_measured,
    preflight,
)
from rig.plans.steps import LockInput, Ramp, SetAmbient, StepTwist


def test_torque_is_interpolated_linearly_at_each_encoder_time() -> None:
    m = ChannelMerger()
    # torque T(t) = 2 t + 1 at 500 Hz, encoder at 1 kHz offset by 0.3 ms
    for k in range(11):
        m.add_torque(k * 0.002, 2 * k * 0.002 + 1.0)
    for k in range(20):
        m.add_output(0.0003 + k * 0.001, 0.01 * k)
    rows = m.pop_rows()
    assert len(rows) == 20
    for row in rows:
        assert row.torque_Nm == pytest.approx(2 * row.t_mono_s + 1.0, abs=1e-12)
        assert math.isnan(row.input_angle_deg) and math.isnan(row.temperature_C)


def test_rows_wait_for_a_later_torque_sample_and_early_ones_are_dropped() -> None:
    m = ChannelMerger()
    m.add_output(0.5, 1.0)  # before any torque: can never be interpolated
    m.add_torque(1.0, 5.0)
    m.add_output(1.5, 2.0)
    rows = m.pop_rows()
    assert rows == [] and m.dropped_before_torque == 1 and m.pending == 1
    m.add_torque(2.0, 7.0)
    m.set_temperature(23.5)
    m.add_input(1.0, 90.0)
    (row,) = m.pop_rows()
    assert (row.t_mono_s, row.torque_Nm, row.output_angle_deg) == (1.5, 6.0, 2.0)
    assert row.input_angle_deg == 90.0  # held: the input is locked
    assert row.temperature_C == 23.5


def test_out_of_order_torque_stamps_are_ignored() -> None:
    m = ChannelMerger()
    m.add_torque(1.0, 1.0)
    m.add_torque(0.9, 100.0)
    m.add_torque(2.0, 3.0)
    m.add_output(1.5, 0.0)
    assert m.pop_rows()[0].torque_Nm == pytest.approx(2.0)


def test_commanded_torque_beyond_the_limit_is_refused() -> None:
    assert check_command(9.99, 10.0) == 9.99
    for bad in (10.01, -11.0, float("nan"), float("inf")):
        with pytest.raises(TorqueLimitExceeded, match="refused"):
            check_command(bad, 10.0)
    assert check_measured(10.0, 10.0, "transducer") is None
    assert "transducer measured +10.5" in check_measured(10.5, 10.0, "transducer")


def test_preflight_names_each_bad_step() -> None:
    steps = [Ramp(5.0), Ramp(-12.0), StepTwist(0.5, 11.0, 1.0), LockInput(90.0), SetAmbient(40)]
    with pytest.raises(PlanRejected) as err:
        preflight(steps, 10.0, has_input_motor=False, has_climate=False)
    text = str(err.value)
    assert "step 2 (torque to -12 N*m step): -12 N*m is beyond the torque limit +-10" in text
    assert "step 3" in text and "step 4" in text and "no input motor" in text
    assert "no climate chamber" in text
    preflight(steps[:1], 10.0, has_input_motor=False, has_climate=False)


def test_a_row_merged_late_gets_the_control_state_of_its_measurement() -> None:
    """Issue 21 item 11: a busy PC merges rows late; each row still gets the setpoint, step
    and sample window in force when it was measured, not when it was merged."""
    log = ControlLog()
    assert log.at(5.0) is None
    log.set(1.0, ControlState(0.0, 1, 0))
    log.set(2.0, ControlState(2.5, 2, 0))
    log.set(2.0, ControlState(2.5, 2, 0))  # no change: nothing logged
    log.set(3.0, ControlState(2.5, 3, 1))
    log.set(2.9, ControlState(-1.0, 4, 0))  # a time that went back holds from the last one
    assert log.at(0.5) == ControlState(0.0, 1, 0)  # before the log: its earliest state
    assert log.at(1.99) == ControlState(0.0, 1, 0)
    assert log.at(2.0) == ControlState(2.5, 2, 0)
    assert log.at(2.95) == ControlState(2.5, 2, 0)
    assert log.at(3.0) == ControlState(-1.0, 4, 0)
    old = ControlLog(keep_s=10.0)
    for k in range(100):
        old.set(float(k), ControlState(float(k), k + 1, 0))
    assert old.at(95.5).setpoint_Nm == 95.0 and old.at(0.0).setpoint_Nm >= 88.0
