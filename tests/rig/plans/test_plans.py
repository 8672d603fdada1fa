"""Plans: the GB/T step order, loading modes, campaign axes and the duration estimate."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from rig.plans import (
    CampaignAxes,
    LoopParams,
    campaign_plan,
    hysteresis_plan,
    ramp_segments,
    run_label,
)
from rig.plans.estimate import estimate
from rig.plans.steps import (
    BeginRun,
    Checkpoint,
    EndRun,
    LockInput,
    Ramp,
    ReadTorqueZero,
    Sample,
    SetAmbient,
    Settle,
    StepTwist,
    WaitTemperature,
    describe,
)


def _recorded(steps):
    """The steps between BeginRun and EndRun."""
    steps = list(steps)
    begin = next(i for i, s in enumerate(steps) if isinstance(s, BeginRun))
    end = next(i for i, s in enumerate(steps) if isinstance(s, EndRun))
    return steps[:begin], steps[begin:end + 1], steps[end + 1:]


def test_gbt_order_preload_then_loop_minus_zero_plus_zero_minus() -> None:
    p = LoopParams(rated_torque_Nm=10.0, mode="constant_rate", pre_cycles=2, rate_Nm_per_s=5.0)
    before, run, after = _recorded(hysteresis_plan(p).steps())
    assert isinstance(before[0], ReadTorqueZero) and before[0].when == "before"
    # preload: to -T, then two full cycles, ending at -T, unrecorded
    assert [s.target_Nm for s in before if isinstance(s, Ramp)] == [-10, 10, -10, 10, -10]
    assert [s.target_Nm for s in run if isinstance(s, Ramp)] == [0.0, 10.0, 0.0, -10.0]
    assert sum(isinstance(s, Settle) for s in run) == 4  # a hold at each quarter's end
    assert isinstance(run[-2], ReadTorqueZero) and run[-2].when == "after"
    assert isinstance(after[-1], Checkpoint)
    # the loading is recorded with the run
    test = run[0].test
    assert test["rated_torque_Nm"] == 10.0 and test["start_flank"] == -1
    assert test["loading"]["rate_Nm_per_s"] == 5.0 and test["loading"]["dwell_s"] == 0.1
    assert test["loading"]["mode"] == "constant_rate"


def test_equal_torque_levels_include_the_lost_motion_torque_and_settle_at_each() -> None:
    p = LoopParams(rated_torque_Nm=10.0, steps_per_quarter=2, extra_levels_pct=[3.0],
                   dwell_s=0.2, sample_s=0.1)
    _, run, _ = _recorded(hysteresis_plan(p).steps())
    targets = [s.target_Nm for s in run if isinstance(s, Ramp)]
    assert targets == [-5.0, -0.3, 0.0, 0.3, 5.0, 10.0, 5.0, 0.3, 0.0, -0.3, -5.0, -10.0]
    kinds = [type(s) for s in run]
    assert kinds.count(Settle) == len(targets) == kinds.count(Sample)
    assert kinds.count(Checkpoint) == 4  # one per quarter: where a pause takes effect


def test_zero_band_is_crossed_at_the_slow_rate_only() -> None:
    p = LoopParams(rated_torque_Nm=10.0, zero_band_Nm=0.5, zero_rate_Nm_per_s=0.25)
    segs = list(ramp_segments(p, 5.0, -5.0))
    assert [(s.target_Nm, s.rate_Nm_per_s) for s in segs] == [
        (0.5, 20.0), (-0.5, 0.25), (-5.0, 20.0)]
    assert [(s.target_Nm, s.rate_Nm_per_s) for s in ramp_segments(p, 0.0, 0.3)] == [(0.3, 0.25)]
    assert [(s.target_Nm, s.rate_Nm_per_s) for s in ramp_segments(p, 1.0, 3.0)] == [(3.0, 20.0)]


def test_equal_position_mode_steps_in_twist_toward_each_quarter_end() -> None:
    p = LoopParams(rated_torque_Nm=4.0, mode="equal_position", twist_step_arcmin=0.25)
    _, run, _ = _recorded(hysteresis_plan(p).steps())
    twist_steps = [s for s in run if isinstance(s, StepTwist)]
    assert [s.limit_Nm for s in twist_steps] == [0.0, 4.0, 0.0, -4.0]
    assert all(s.delta_arcmin == 0.25 for s in twist_steps)


def test_estimate_of_a_constant_rate_loop_is_the_closed_form() -> None:
    # zero read (0.1 s settle + 0.2 s), preload 0->-T, 1 pre-cycle (4T), settle 0.1 s,
    # loop 4T with a 0.1 s hold at the end of each quarter, zero back (ramp T, 0.1 + 0.2 s)
    p = LoopParams(rated_torque_Nm=10.0, mode="constant_rate", rate_Nm_per_s=10.0,
                   settle_hold_s=0.1, zero_window_s=0.2)
    est = estimate(hysteresis_plan(p).steps())
    ramps = (10 + 40 + 40 + 10) / 10.0
    assert est.total_s == pytest.approx(0.3 + ramps + 0.1 + 4 * 0.1 + 0.3)
    assert est.dwell_s == pytest.approx(1.1)
    assert est.n_runs == 1
    assert est.remaining_s(0) == pytest.approx(est.total_s)
    assert est.remaining_s(est.n_steps) == 0.0


def test_campaign_axes_temperature_outer_positions_amplitudes_repeats() -> None:
    loop = LoopParams(rated_torque_Nm=10.0, mode="constant_rate")
    axes = CampaignAxes(positions_deg=[0, 90], amplitudes_pct=[25, 100], repeats=2,
                        temperatures_C=[20, 40])
    steps = list(campaign_plan(loop, axes).steps())
    labels = [s.label for s in steps if isinstance(s, BeginRun)]
    assert len(labels) == 2 * 2 * 2 * 2
    assert labels[:3] == ["T20C-pos000-a25-r0", "T20C-pos000-a25-r1", "T20C-pos000-a100-r0"]
    assert labels[-1] == "T40C-pos090-a100-r1"
    assert [type(s) for s in steps[:3]] == [SetAmbient, WaitTemperature, LockInput]
    begins = [s for s in steps if isinstance(s, BeginRun)]
    assert begins[2].test["amplitude_pct"] == 100 and begins[2].test["input_angle_deg"] == 0
    # each amplitude's loop goes to its own torque
    ramps = [s.target_Nm for s in steps if isinstance(s, Ramp)]
    assert max(ramps) == 10.0 and 2.5 in ramps


def test_bad_parameters_name_the_field() -> None:
    with pytest.raises(ValidationError, match="amplitude_pct"):
        LoopParams(rated_torque_Nm=10.0, amplitude_pct=150.0)
    with pytest.raises(ValidationError, match="amplitudes_pct"):
        CampaignAxes(amplitudes_pct=[0.0])
    with pytest.raises(ValidationError, match="mode"):
        LoopParams(rated_torque_Nm=10.0, mode="sideways")


def test_listing_describes_every_step() -> None:
    plan = hysteresis_plan(LoopParams(rated_torque_Nm=10.0, steps_per_quarter=1), 45.0)
    lines = plan.listing()
    assert lines[0].strip() == "1  lock input at 45 deg"
    assert any("torque to +10 N*m at 20 N*m/s" in line for line in lines)
    assert run_label(-12.5, 3, 1, 25.5) == "T25p5C-posm12p5-a3-r1"
    with pytest.raises(TypeError):
        describe("not a step")  # type: ignore[arg-type]
