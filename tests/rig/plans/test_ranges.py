"""Issue 33 item 5: every number of a campaign file and a plan has a physical range
(rig/core/ranges.py), checked where it enters, refused in one line naming the file, the key
and the range; and a plan's expected duration is bounded."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from rig.core.errors import RigError
from rig.core.ranges import PLAN_CONFIRM_S, PLAN_MAX_S
from rig.plans import CampaignAxes, LoopParams, TEParams
from rig.plans.campaign_file import CampaignError, load_campaign
from rig.plans.estimate import check_duration, estimate
from tests.support.campaigns import MINIMAL
from tests.support.paths import REPO

GOOD = MINIMAL + "[axes]\npositions_deg = [0.0]\n"
TE = GOOD.replace('name = "t1"', 'name = "t1"\ntest = "transmission_error"') + \
    "[te]\nratio = -8.0\n"

CASES = {
    "rated torque 1e308": (GOOD.replace("rated_torque_Nm = 10.0", "rated_torque_Nm = 1e308"),
                           "plan.rated_torque_Nm: expected greater than 0 and at most 1e+07 "
                           "N·m (got 1e+308)"),
    "position 1e300": (GOOD.replace("positions_deg = [0.0]", "positions_deg = [1e300]"),
                       "axes.positions_deg.0: expected from -3600 to 3600 deg (got 1e+300)"),
    "dwell 1e9": (GOOD.replace("[axes]", "dwell_s = 1e9\n[axes]"),
                  "plan.dwell_s: expected from 0 to 3600 s (got 1000000000.0)"),
    "rate 1e-300": (GOOD.replace("[axes]", "rate_Nm_per_s = 1e-300\n[axes]"),
                    "plan.rate_Nm_per_s: expected from 0.001 to 100000 N·m/s (got 1e-300)"),
    "temperature -300": (GOOD + "temperatures_C = [-300.0]\n",
                         "axes.temperatures_C.0: expected from -40 to 150 °C (got -300.0)"),
    "TE speed 1e-9": (TE + "input_speed_rpm = 1e-9\n",
                      "te.input_speed_rpm: expected from 1 to 6000 rpm (got 1e-09)"),
    "TE speed 0.01": (TE + "input_speed_rpm = 0.01\n",
                      "te.input_speed_rpm: expected from 1 to 6000 rpm (got 0.01)"),
    "lost motion limit 1e300": (GOOD + "[limits]\nlost_motion_arcmin_max = 1e300\n",
                                "limits.lost_motion_arcmin_max: expected greater than 0 and at "
                                "most 10000 arcmin (got 1e+300)"),
    "torque limit 1e31": ("torque_limit_Nm = 1e31\n" + GOOD,
                          "torque_limit_Nm: expected greater than 0 and at most 1e+07 N·m "
                          "(got 1e+31)"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_absurd_campaign_numbers_are_refused_naming_file_key_and_range(case: str,
                                                                       tmp_path: Path) -> None:
    text, expected = CASES[case]
    path = tmp_path / "c.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(CampaignError) as err:
        load_campaign(path)
    assert str(err.value) == f"{path}: {expected}"


def test_the_shipped_campaigns_stay_in_range_and_take_less_than_a_shift() -> None:
    for path in sorted((REPO / "examples" / "campaigns").glob("*.toml")):
        est = estimate(load_campaign(path).build_plan().steps())
        assert 0 < est.total_s < PLAN_CONFIRM_S, path
        check_duration(est, confirmed=False, how="--confirm-long")


@pytest.mark.parametrize("params", [
    dict(rate_Nm_per_s=1e-3, rated_torque_Nm=1e7, steps_per_quarter=2),
    dict(rated_torque_Nm=10.0, dwell_s=3600.0, steps_per_quarter=200),
])
def test_plans_built_from_in_range_numbers_have_a_finite_bounded_estimate(params) -> None:
    """Whatever the ranges allow, the estimate is a finite number, and beyond
    PLAN_MAX_S no confirmation lets the plan run."""
    from rig.plans import hysteresis_plan

    est = estimate(hysteresis_plan(LoopParams(**params)).steps())
    assert math.isfinite(est.total_s) and est.total_s > PLAN_MAX_S
    with pytest.raises(RigError, match="more than the most a plan may take"):
        check_duration(est, confirmed=True, how="--confirm-long")


def test_a_long_plan_runs_only_when_confirmed() -> None:
    from rig.plans import hysteresis_plan

    est = estimate(hysteresis_plan(LoopParams(rated_torque_Nm=10.0, dwell_s=3600.0,
                                              steps_per_quarter=4)).steps())
    assert PLAN_CONFIRM_S < est.total_s < PLAN_MAX_S
    with pytest.raises(RigError, match=r"about \d+ h, more than 8 h: confirm it with --c"):
        check_duration(est, confirmed=False, how="--c")
    check_duration(est, confirmed=True, how="--c")


def test_te_speed_of_a_hundredth_rpm_is_refused_in_the_parameters() -> None:
    with pytest.raises(ValueError, match="input_speed_rpm"):
        TEParams(rated_torque_Nm=10.0, ratio=-8.0, input_speed_rpm=0.01)
    with pytest.raises(ValueError, match="positions_deg"):
        CampaignAxes(positions_deg=[math.inf])
