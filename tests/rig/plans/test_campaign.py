"""Campaign files: the shipped seed 000 campaigns load, errors name file and key, results."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from rig.measurement.service import plant_config_for
from rig.plans.campaign_file import (
    CampaignError,
    Limits,
    load_campaign,
    runout_signature,
    summarise,
)
from tests.support.campaigns import MINIMAL
from tests.support.paths import REPO as ROOT

SHIPPED = sorted(p for p in (ROOT / "examples" / "campaigns").glob("seed000-pair*.toml")
                 if not p.stem.endswith("-te"))  # the loop campaigns (-te: transmission error)


def test_the_four_seed000_campaigns_load_and_build_their_plants() -> None:
    assert [p.name for p in SHIPPED] == [f"seed000-pair{k}.toml" for k in (1, 2, 3, 4)]
    distances = []
    for path in SHIPPED:
        camp = load_campaign(path)
        unit = camp.unit_data()
        assert unit["serial"] == camp.name and unit["z_internal"] == 45
        distances.append(unit["center_distance_mm"])
        plant = plant_config_for(unit, camp.simulation, camp.source)
        assert plant.effects.runout.enabled
        assert plant.unit["runout_internal_mm"] == unit["runout_internal_mm"] > 0
        assert len(camp.axes.positions_deg) >= 3  # enough for the once-per-rev fit
        plan = camp.build_plan()
        assert sum(1 for _ in plan.steps()) > 0
    assert distances == [2.5, 2.5, 2.5222, 2.5135]


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "c.toml"
    path.write_text(text, encoding="utf-8")
    return path


GOOD = MINIMAL


def test_errors_name_the_file_and_the_key(tmp_path: Path) -> None:
    camp = load_campaign(_write(tmp_path, GOOD))
    assert camp.plan.rated_torque_Nm == 10.0 and camp.unit_data()["z_internal"] == 45
    bad_value = GOOD.replace("rated_torque_Nm = 10.0", "rated_torque_Nm = -1")
    with pytest.raises(CampaignError, match=r"c\.toml: plan\.rated_torque_Nm: .*greater than 0"):
        load_campaign(_write(tmp_path, bad_value))
    with pytest.raises(CampaignError, match=r"c\.toml: plan\.dwel: Extra inputs"):
        load_campaign(_write(tmp_path, GOOD + "dwel = 1\n"))
    with pytest.raises(CampaignError, match=r"c\.toml:3:8: TOML syntax error"):
        load_campaign(_write(tmp_path, 'name = "x"\n[unit]\nfile = \n'))
    with pytest.raises(CampaignError, match=r"c\.toml: unit\.file: cannot read .*nope\.json"):
        load_campaign(_write(tmp_path, GOOD.replace("[unit]", '[unit]\nfile = "nope.json"')))
    (tmp_path / "u.json").write_text('{"a": 1,\n "b": }')
    with pytest.raises(CampaignError, match=r"u\.json:2:7: .*named by .*unit\.file"):
        load_campaign(_write(tmp_path, GOOD.replace("[unit]", '[unit]\nfile = "u.json"')))
    with pytest.raises(CampaignError, match=r"limits\.lost_motion_arcmin_max"):
        load_campaign(_write(tmp_path, GOOD + "[limits]\nlost_motion_arcmin_max = 0\n"))


def test_runout_signature_recovers_a_known_sine() -> None:
    angles = [0, 60, 120, 180, 240, 300]
    values = [4.0 + 2.0 * math.cos(math.radians(a - 200.0)) for a in angles]
    sig = runout_signature(angles, values)
    assert sig["mean"] == pytest.approx(4.0)
    assert sig["amplitude"] == pytest.approx(2.0)
    assert sig["phase_deg"] == pytest.approx(200.0)
    assert sig["residual_rms"] == pytest.approx(0.0, abs=1e-12)
    assert runout_signature([0, 360, 720], [1.0, 2.0, 3.0]) is None  # one angle mod 360


def _run(label: str, angle: float, lm: float | None, status: str = "completed") -> dict:
    return {"run_id": label, "label": label, "status": status, "reason": None,
            "input_angle_deg": angle, "lost_motion_arcmin": lm, "backlash_arcmin": 1.0,
            "stiffness_Nm_per_arcmin": 28.0, "errors": {}, "model": {"lost_motion_arcmin": 4.3}}


def test_summary_statistics_and_pass_fail_causes() -> None:
    runs = [_run("a", 0, 2.0), _run("b", 90, 4.0), _run("c", 180, 6.0), _run("d", 270, 4.0)]
    s = summarise(runs, Limits(lost_motion_arcmin_max=5.0, stiffness_Nm_per_arcmin_min=20.0))
    lm = s["lost_motion_arcmin"]
    assert (lm["mean"], lm["min"], lm["max"]) == (4.0, 2.0, 6.0)
    assert lm["std"] == pytest.approx(float(np.std([2, 4, 6, 4], ddof=1)))
    assert s["runout_signature"]["amplitude"] == pytest.approx(2.0)
    assert s["runout_signature"]["phase_deg"] == pytest.approx(180.0)
    assert s["model"] == {"lost_motion_arcmin": 4.3}
    assert not s["passed"]
    assert s["failures"] == ["run c: lost_motion_arcmin = 6 is above the limit 5"]
    s = summarise(runs, Limits())
    assert s["passed"] and s["failures"] == []
    aborted = [*runs[:1], {**_run("e", 0, None, "aborted"), "reason": "E-stop"}]
    s = summarise(aborted, Limits())
    assert not s["passed"] and s["failures"] == ["run e: aborted: E-stop"]
    unmeasured = _run("f", 0, None)
    unmeasured["errors"] = {"lost_motion_arcmin": "no samples"}
    assert Limits(lost_motion_arcmin_max=1.0).check(unmeasured) == [
        "run f: lost_motion_arcmin unavailable (no samples)"]
