"""Issue 33 item 14: the Python API's results table of a run whose twist runs against the
torque (tests/support/reversed_twist.py) shows no figure below zero: the metric is empty (NaN)
and ``error`` says "below zero: no measurement" with the likely cause; never OK."""

from __future__ import annotations

from pathlib import Path

import rig
from tests.support.reversed_twist import write_reversed_twist_run

CAUSE = "the twist runs against the torque: check the output encoder's counting direction"


def test_the_python_api_table_shows_no_figure_below_zero(tmp_path: Path) -> None:
    folder = write_reversed_twist_run(tmp_path / "flipped-run")
    table = rig.open(folder).results()
    row = table.iloc[0]
    for key in ("lost_motion_arcmin", "backlash_arcmin", "stiffness_Nm_per_arcmin",
                "loop_area_J"):
        assert row[key] != row[key] and row[f"{key}_u"] != row[f"{key}_u"], key  # NaN
    assert f"below zero: no measurement ({CAUSE})" in row["error"]
    assert row["verdict"] == "INCOMPLETE"
    assert rig.analyse(folder).to_pandas().iloc[0]["error"] == row["error"]

