"""Batch band and compensation advice of each unit kind (issue 23 item 3): a cycloid batch
over seed 002's modification budget, a beveloid batch over seed 001's installation budget."""

from __future__ import annotations

import json

import numpy as np
import pytest

from analysis.models.beveloid_batch import (
    Seed001InstallationBudget,
    beveloid_advice,
    beveloid_batch,
)
from analysis.models.by_kind import nominal_model_for_unit
from analysis.models.cycloid_batch import Seed002Tolerances, cycloid_advice, cycloid_batch
from rig.plans.campaign_file import batch_band
from tests.support.paths import REPO

UNITS = REPO / "rig" / "examples" / "units"


def unit(name: str) -> dict:
    return json.loads((UNITS / f"{name}.json").read_text())


def test_cycloid_batch_spreads_around_the_design_by_the_budget():
    u = unit("cycloid-seed002")
    model, _ = nominal_model_for_unit(u, 10.0)
    batch = cycloid_batch(u, samples=4000)
    low, high = batch.band_arcmin()
    # a perfect unit sits at the design's worst mesh phase; at its worst crank position a
    # real one adds its runouts, bearing clearances and thickest tooth pair
    assert model.play_max_arcmin < float(np.median(batch.worst_arcmin)) < high
    assert low > 0.5 * model.play_max_arcmin
    # without tolerances the batch is the design's worst phase plus the elastic term
    exact = cycloid_batch(u, Seed002Tolerances(0, 0, 0, (0, 0), (0,), (0, 0), (0, 0)),
                          samples=100)
    assert exact.band_arcmin() == pytest.approx(
        (model.play_max_arcmin + 0.6 / model.stiffness_Nm_per_arcmin,) * 2, rel=1e-6)
    # a tighter runout grade narrows the band
    tight = cycloid_batch(u, Seed002Tolerances(runout_gear1_max_um=4.0,
                                               runout_gear2_max_um=4.0), samples=4000)
    assert np.ptp(tight.band_arcmin()) < 0.7 * np.ptp(batch.band_arcmin())
    assert tight.band_arcmin()[1] < batch.band_arcmin()[1] - 0.5


def test_cycloid_advice_sets_the_rotation_for_the_binding_share():
    u = unit("cycloid-seed002")
    advice = cycloid_advice(u, samples=4000, binding=0.025)
    assert advice["binding_fraction"] == pytest.approx(0.025, abs=0.005)
    more = cycloid_batch(u, samples=4000, rotation_mm=advice["rotation_modification_mm"] + 0.001)
    assert more.interference_fraction > 2.5 * 0.025  # 4 um less play: more units bind
    assert np.mean(more.worst_arcmin) < advice["band_95_arcmin"][1]


def test_beveloid_batch_and_axial_position_advice():
    u = unit("beveloid-seed001")
    model, _ = nominal_model_for_unit(u, 10.0)
    batch = beveloid_batch(u, samples=4000)
    low, high = batch.band_arcmin()
    assert low < model.lost_motion_arcmin(10.0, 3.0) < high
    none = beveloid_batch(u, Seed001InstallationBudget((0, 0), (0, 0), (0, 0), 0, 0, (0,)),
                          samples=50)
    assert none.band_arcmin()[0] == pytest.approx(model.lost_motion_arcmin(10.0, 3.0), rel=1e-6)
    advice = beveloid_advice(u, samples=4000)
    assert advice["binding_fraction"] == pytest.approx(0.025, abs=0.005)
    # the example unit's -0.1 mm leaves margin: the advice moves the gear further out
    assert advice["axial_shift_mm"] < u["axial_shift_mm"]
    assert "-77.0 um of play per mm" in advice["what"]


@pytest.mark.parametrize("name, kind", [("cycloid-seed002", "cycloid"),
                                        ("beveloid-seed001", "beveloid")])
def test_campaign_batch_band_of_each_kind(name, kind):
    band = batch_band(unit(name), 10.0, 3.0, samples=2000)
    assert band is not None and band["kind"] == kind
    assert band["advice"]["band_95_arcmin"][0] < band["advice"]["band_95_arcmin"][1]
    assert batch_band({**unit(name), "module_mm": "x"}, 10.0, 3.0) is None
