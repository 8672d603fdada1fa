"""The production-batch band shown beside campaign results (seed 000 tolerances)."""

from __future__ import annotations

import json

from analysis.models.seed000_batch import lost_motion_batch
from analysis.models.seed000_unit import InternalPairUnit
from rig.examples import UNITS_DIR
from rig.plans.campaign_file import batch_band

PAIR1 = json.loads((UNITS_DIR / "seed000-pair1.json").read_text())


def test_band_is_the_central_95_percent_of_the_batch() -> None:
    band = batch_band(PAIR1, 10.0, 3.0, samples=3000)
    assert band is not None
    unit, _ = InternalPairUnit.from_mapping(PAIR1)
    batch = lost_motion_batch(unit, samples=3000, seed=0, rated_torque_Nm=10.0)
    assert band["band_95_arcmin"] == list(batch.band_arcmin(0.95))
    low, high = band["band_95_arcmin"]
    inside = (batch.worst_position_arcmin >= low) & (batch.worst_position_arcmin <= high)
    assert abs(inside.mean() - 0.95) < 0.01


def test_no_band_for_units_the_batch_model_cannot_use() -> None:
    assert batch_band({"kind": "cycloid", "z_internal": 40}, 10.0, 3.0) is None
    partial = {k: v for k, v in PAIR1.items() if k != "pin_diameter_mm"}
    assert batch_band(partial, 10.0, 3.0) is None
