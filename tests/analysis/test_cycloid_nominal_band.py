"""The cycloid unit's nominal model against seed 002 and against its own batch band (issue 33
item 17): the nominal (1.664 arcmin) lay outside the printed band (2.403 .. 3.831 arcmin).

Neither number is wrong; they are different quantities. The nominal is a perfect unit, its
play averaged over the mesh phases, and it follows seed 002's closed forms (eqs. 9-12). The
band is each unit's worst crank position, where runouts, crank-bearing clearances and the
thinnest tooth pair only add. The tests pin the nominal to the seed's numbers, state the
relation (the worst-position band lies above the nominal by the one-sided terms; without
them, and at one random position, the batch brackets the nominal) and check that the
outputs (campaign band, `rig model`) say so."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from analysis.models.by_kind import nominal_model_for_unit
from analysis.models.cycloid_batch import Seed002Tolerances, cycloid_batch
from analysis.models.seed002_clearance import PAPER_ROTATION_SIDE_CLEARANCE_MM
from analysis.models.seed002_cycloid import CompoundCycloidPair, flank_angle_rad
from rig.plans.campaign_file import batch_band
from tests.support.paths import REPO

UNIT_FILE = REPO / "rig" / "examples" / "units" / "cycloid-seed002.json"
UNIT = json.loads(UNIT_FILE.read_text())
ARCMIN_PER_RAD = 10800.0 / math.pi


@pytest.fixture(scope="module")
def nominal():
    model, _ = nominal_model_for_unit(UNIT, 10.0)
    return model


@pytest.fixture(scope="module")
def batch():
    return cycloid_batch(UNIT, samples=4000)


def test_nominal_follows_seed002_closed_forms(nominal):
    """Per side at the pitch point, eqs. 9-12: ``Delta1 cot(chi) - 2 Delta2`` with
    ``tan(chi) = 2 h1 / (1 - 4 f1 h1)`` and the paper's 2 Delta2 = 0.004 mm (Fig. 7 text:
    'clearance change is twice Delta2'): 16 * 0.76 / 0.6 - 4 = 16.27 um. The assembled play
    never falls below both sides at that clearance; the mean over the mesh phases is pinned."""
    pair = CompoundCycloidPair(UNIT["module_mm"], UNIT["z_internal"], UNIT["z_external"],
                               UNIT["height_coeff"], UNIT["shape_coeff"],
                               UNIT["eccentricity_mm"])
    cot_chi = (1 - 4 * UNIT["shape_coeff"] * UNIT["height_coeff"]) / (2 * UNIT["height_coeff"])
    assert cot_chi == pytest.approx(1.0 / math.tan(flank_angle_rad(pair)))
    side_um = (1000 * UNIT["shift_modification_mm"] * cot_chi
               - 1000 * PAPER_ROTATION_SIDE_CLEARANCE_MM)
    assert side_um == pytest.approx(16.267, abs=1e-3)
    assert nominal.side_clearance_pitch_um == pytest.approx(side_um, rel=2e-3)
    pitch_play = 2 * side_um / 1000 / pair.pitch_radius_external_mm * ARCMIN_PER_RAD
    assert pitch_play < nominal.play_min_arcmin <= nominal.play_arcmin <= nominal.play_max_arcmin
    assert nominal.play_arcmin == pytest.approx(float(np.mean(nominal.play_phases_arcmin)))
    assert nominal.lost_motion_arcmin(10.0, 3.0) == pytest.approx(1.664, abs=5e-4)


def test_worst_position_band_lies_above_the_nominal_by_one_sided_terms(nominal, batch):
    lost = nominal.lost_motion_arcmin(10.0, 3.0)
    low, high = batch.band_arcmin()
    assert (low, high) == pytest.approx((2.403, 3.831), abs=0.02)
    assert lost < low  # the stated relation: a perfect unit lies below the worst position
    # the centred terms alone (eccentricity error, shift, rotation) bracket the nominal
    centred = cycloid_batch(UNIT, Seed002Tolerances(
        runout_gear1_max_um=0.0, runout_gear2_max_um=0.0, pitch_deviation_um=0.0,
        crank_bearing_clearance_max_um=(0.0, 0.0)), samples=4000)
    c_low, c_high = centred.band_arcmin()
    assert c_low < lost < c_high


def test_the_batch_at_one_random_position_brackets_the_nominal(nominal, batch):
    lost = nominal.lost_motion_arcmin(10.0, 3.0)
    low, high = batch.position_band_arcmin()
    assert low < lost < high
    # its centre sits above the nominal by the bearings' 2 cot(chi) E[sum u_r] / 2 (+0.22')
    cot_chi = 0.76 / 0.6
    bearings_arcmin = 2 * cot_chi * 2.0 / (1000 * 78.0) * ARCMIN_PER_RAD
    assert float(np.mean(batch.position_arcmin)) - lost == pytest.approx(
        bearings_arcmin, abs=0.05)


def test_the_campaign_band_says_how_band_and_nominal_relate():
    band = batch_band(UNIT, 10.0, 3.0, samples=2000)
    assert band is not None
    assert "worst crank position" in band["nominal_relation"]
    assert "lies below it" in band["nominal_relation"]
    low, high = band["position_band_95_arcmin"]
    assert low < 1.664 < high


def test_rig_model_prints_the_cycloid_nominal_and_its_bands(tmp_path):
    out = tmp_path / "model.json"
    res = subprocess.run(
        [sys.executable, "-c", "from rig.cli import main; main()", "model", str(UNIT_FILE),
         "--json", str(out)], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    doc = json.loads(out.read_text())
    assert doc["kind"] == "cycloid"
    assert doc["lost_motion_arcmin"] == pytest.approx(1.664, abs=5e-4)
    assert doc["batch"]["band_95_arcmin"][0] > doc["lost_motion_arcmin"]
    text = " ".join(res.stdout.split())
    assert "worst position" in text and "one random position" in text
    assert "lies below it" in text
