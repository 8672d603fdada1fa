"""A campaign over several amplitudes and repeats runs end to end on the simulated rig."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support.paths import REPO as ROOT

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

RIG = [sys.executable, "-c", "from rig.cli import main; main()"]
CAMPAIGN = f"""
name = "axes"
[unit]
file = "{ROOT / 'rig/examples/units/seed000-pair1.json'}"
[plan]
rated_torque_Nm = 10.0
steps_per_quarter = 2
extra_levels_pct = [3.0]
dwell_s = 0.0
pre_cycles = 0
zero_band_Nm = 0.3
zero_rate_Nm_per_s = 0.6
[axes]
positions_deg = [0.0]
amplitudes_pct = [50.0, 100.0]
repeats = 2
[simulation.plant.effects.friction]
enabled = true
model = "lugre"
coulomb_torque_Nm = 0.02
static_torque_Nm = 0.03
viscous_Nms_per_arcmin = 0.002
"""


def test_amplitudes_and_repeats_make_one_run_each(tmp_path: Path) -> None:
    camp = tmp_path / "axes.toml"
    camp.write_text(CAMPAIGN)
    out = tmp_path / "axes.json"
    res = subprocess.run(
        [*RIG, "campaign", "run", str(camp), "--simulated", "--store", str(tmp_path / "s"),
         "--json", str(out)],
        capture_output=True, text=True, timeout=300, cwd=tmp_path,
    )
    assert res.returncode == 0, res.stderr[-3000:]
    doc = json.loads(out.read_text())
    runs = doc["runs"]
    assert len(runs) == 4 and all(r["status"] == "completed" for r in runs)
    assert sorted(r["amplitude_pct"] for r in runs) == [50.0, 50.0, 100.0, 100.0]
    lost = [r["lost_motion_arcmin"] for r in runs]
    # the lost motion at ±3 % does not depend on the loop amplitude or the repeat (same
    # position, same unit): all four agree within a few hundredths of an arcmin
    assert max(lost) - min(lost) < 0.05, lost
    # the ±100 % runs give a stiffness; the ±50 % runs cannot (they never reach rated torque)
    with_k = [r for r in runs if r["stiffness_Nm_per_arcmin"] is not None]
    assert len(with_k) == 2, [r.get("errors") for r in runs]
    assert doc["lost_motion_arcmin"]["n"] == 4
