"""Issue 33 item 5 in the Python API: ``rig.connect(...).measure`` and ``.campaign`` refuse a
number outside its physical range (rig/core/ranges.py) and a plan longer than 8 h unless
``confirm_long``, before anything moves (no simulated rig is started: these raise first)."""

from __future__ import annotations

from pathlib import Path

import pytest

import rig
from rig.core.errors import RigError

CAMPAIGN = {"name": "long", "unit": {"z_internal": 45, "z_external": 40, "module_mm": 1.0},
            "plan": {"rated_torque_Nm": 10.0, "dwell_s": 1800.0, "steps_per_quarter": 4},
            "axes": {"positions_deg": [0.0, 90.0]}}


@pytest.mark.parametrize(("kwargs", "words"), [
    (dict(rated_torque_Nm=10.0, dwell_s=1e9),
     "dwell_s: expected from 0 to 3600 s (got 1000000000.0)"),
    (dict(rated_torque_Nm=1e308), "rated_torque_Nm: expected greater than 0 and at most 1e+07"),
    (dict(rated_torque_Nm=10.0, position_deg=1e300),
     "position_deg: expected from -3600 to 3600 deg (got 1e+300)"),
    (dict(rated_torque_Nm=10.0, dwell_s=3600.0, steps_per_quarter=10),
     "more than 8 h: confirm it with confirm_long=True"),
])
def test_measure_refuses_before_anything_moves(tmp_path: Path, kwargs: dict,
                                               words: str) -> None:
    with rig.connect(simulated=True, store=tmp_path / "s") as r, \
            pytest.raises(RigError) as err:
        r.measure(**kwargs)
    assert words in str(err.value), str(err.value)


def test_a_long_campaign_needs_confirm_long(tmp_path: Path) -> None:
    with rig.connect(simulated=True, store=tmp_path / "s") as r, \
            pytest.raises(RigError, match="more than 8 h: confirm it with confirm_long=True"):
        r.campaign(CAMPAIGN)
