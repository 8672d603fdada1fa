"""``rig validate-diagnosis --like CAMPAIGN`` (issue 20, point 3): labelled campaigns with a
campaign's own design and measuring system, diagnosed blind (rig/validate/like.py)."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from analysis.diagnosis.data import resolution_of
from analysis.loop.branches import white_noise_std
from rig.runformat import read_campaign
from rig.validate.like import (
    IN_VOCABULARY,
    NULL_EVERY,
    design_of,
    effect_params,
    like_campaign,
    plan,
)
from simulators.plant.geometry import reference_nominal
from tests.support.paths import TEST_DATA

DEVSET = TEST_DATA / "devset"
#: A small development-set campaign: 3 runs at one position and three temperatures.
SMALL = DEVSET / "a" / "cases" / "c0090888245"


def test_generated_campaigns_share_the_source_design() -> None:
    """Same runs, sample times, sample counts, positions, temperatures and unit data; the
    torque channel is the measured one (an offset of the reading added when that is the
    withheld effect); the twist carries the measured noise on the measured encoder grid."""
    src = read_campaign(SMALL)
    design = design_of(src)
    assert design.twist_resolution_deg > 0 and design.twist_noise_arcmin > 0
    rng = np.random.default_rng(1)
    for kind in ("none", "torque_sensor_offset", "thermal_expansion"):
        params = None if kind == "none" else effect_params(design, kind, 4.0, rng)
        camp = like_campaign(design, kind, params, rng)
        assert [r.run_id for r in camp.runs] == [r.run_id for r in src.runs]
        for a, b in zip(src.runs, camp.runs, strict=True):
            assert b.n_samples == a.n_samples
            np.testing.assert_array_equal(b.t_s, a.t_s)
            np.testing.assert_array_equal(b.temperature_C, a.temperature_C)
            assert b.test == a.test and b.unit == a.unit and b.sensors == a.sensors
            assert np.median(b.input_angle_deg) == pytest.approx(a.test["input_angle_deg"],
                                                                 abs=1e-3)
            shift = params["offset_Nm"] if kind == "torque_sensor_offset" else 0.0
            np.testing.assert_allclose(b.torque_Nm, a.torque_Nm + shift, atol=1e-9)
            q = resolution_of(b.output_angle_deg)
            assert q == pytest.approx(design.twist_resolution_deg, rel=1e-6)
            sigma = max(white_noise_std(b.output_angle_deg * 60.0), q * 60.0 / math.sqrt(12))
            assert sigma == pytest.approx(design.twist_noise_arcmin, rel=0.3)
            assert b.meta["generator"]["kind"] == kind


def test_effect_sizes_follow_the_measured_noise_and_the_design() -> None:
    """Friction and offset shift a flank by m sigma; one position cannot show runout or tooth
    spacing (left out, with the reason); a null every NULL_EVERY-th case."""
    design = design_of(read_campaign(SMALL))
    k = reference_nominal(design.unit).stiffness_Nm_per_arcmin
    rng = np.random.default_rng(0)
    fr = effect_params(design, "friction", 3.0, rng)
    assert fr["coulomb_torque_Nm"] / k == pytest.approx(3.0 * design.twist_noise_arcmin)
    assert effect_params(design, "runout", 3.0, rng) is None
    assert effect_params(design, "tooth_spacing_error", 3.0, rng) is None
    thermal = effect_params(design, "thermal_expansion", 3.0, rng)
    assert thermal is not None and thermal["coefficient_um_per_K"] != 0.0
    kinds, why = plan(design, 10, 0)
    assert set(why) == {"runout", "tooth_spacing_error"}
    assert [k for k, _ in kinds].count("none") == 10 // NULL_EVERY
    effects = {k for k, _ in kinds} - {"none"}
    assert effects <= set(IN_VOCABULARY) - set(why) and len(effects) >= 5
    assert all(2.0 <= m <= 8.0 for k, m in kinds if k != "none")


@pytest.mark.timeout(600)
def test_cli_like_writes_the_confusion(tmp_path) -> None:
    """``rig validate-diagnosis --like CAMPAIGN --cases 2 --jobs 2 --json F``: two labelled
    campaigns diagnosed blind; the confusion per effect, false alarms, nulls, smallest size
    found, the design's estimates and the time in the JSON and the summary line printed."""
    out = subprocess.run([sys.executable, "-m", "rig", "validate-diagnosis", "--like",
                          str(SMALL), "--cases", "2", "--jobs", "2", "--json",
                          str(tmp_path / "like.json")], capture_output=True, text=True,
                         timeout=580)
    assert out.returncode == 0, out.stderr
    s = json.loads((tmp_path / "like.json").read_text())
    assert {"cases", "correct", "false_alarms", "nulls", "per_effect", "smallest_found",
            "seconds", "design", "untestable", "results"} <= set(s)
    assert s["cases"] == 2 and len(s["results"]) == 2
    assert sum(d["n"] for d in s["per_effect"].values()) == 2
    assert set(s["smallest_found"]) == set(s["per_effect"]) - {"none"}
    assert s["design"]["runs"] == 3 and s["design"]["samples"] == [969, 969, 969]
    assert all(r["verdict"] is not None for r in s["results"]), s["results"]
    assert f"on 2 campaigns like this one: right {s['correct']}" in out.stdout


def test_like_rejects_a_missing_campaign(tmp_path) -> None:
    out = subprocess.run([sys.executable, "-m", "rig", "validate-diagnosis", "--like",
                          str(tmp_path / "nothing"), "--cases", "1"], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 2
    assert str(tmp_path / "nothing") in out.stderr and len(out.stderr.strip().splitlines()) == 1
