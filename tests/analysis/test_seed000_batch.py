"""Lost motion of a production batch (seed 003's Monte Carlo method on the seed 000 pair)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from analysis.errors import AnalysisError
from analysis.models.seed000_batch import (
    Seed000Tolerances,
    lost_motion_batch,
    play_over_positions_um,
    shaft_angles_rad,
)
from analysis.models.seed000_geometry import backlash_arcmin_from_um
from analysis.models.seed000_unit import InternalPairUnit
from rig.examples import UNITS_DIR

PAIR1 = json.loads((UNITS_DIR / "seed000-pair1.json").read_text())
UNIT, _ = InternalPairUnit.from_mapping(PAIR1)
TAN_A = math.tan(math.radians(20.0))


def test_worst_position_play_reproduces_table3_pair1() -> None:
    """Pair 1's measured values (E_M = 0.077 mm, F_r 0.022/0.015 mm): the maximum of eq. (4)'s
    play over the shaft angle and the phase beta is Table 3's design value 6'20"."""
    theta = shaft_angles_rad(UNIT, 256)
    assert theta.size == 8 * 256  # eq. (4) repeats after Z2 / (Z1 - Z2) = 8 crank revolutions
    play = play_over_positions_um(
        UNIT, theta, m_value_deviation_mm=0.077, eccentric_distance_mm=2.5,
        eccentricity_internal_mm=0.011, eccentricity_external_mm=0.0075,
        beta_rad=np.linspace(0.0, 2 * math.pi, 73),
    )
    worst = backlash_arcmin_from_um(float(play.max()), 1.0, 45)
    print(f"\npair 1 worst-position play: paper 6'20\" = 6.3333', ours {worst:.4f}'")
    assert worst == pytest.approx(6.0 + 20.0 / 60.0, abs=10.0 / 3600.0 * 60.0)


def test_batch_stays_inside_the_tolerance_bounds() -> None:
    """Every sampled unit lies between the all-best and all-worst tolerance corners."""
    tol = Seed000Tolerances()
    result = lost_motion_batch(UNIT, tol, samples=4000, seed=3, lost_motion_pct=0.0)
    best_um = TAN_A * (23 + 17)  # thinnest play: smallest M deviations, no runout, no clearance
    worst_um = TAN_A * ((53 + 38) + 2 * (2 + 6 + 23 / 2 + 16 / 2))  # all corners against it
    lo = backlash_arcmin_from_um(best_um - TAN_A * 2 * 2, 1.0, 45)  # eccentric error +2 um
    hi = backlash_arcmin_from_um(worst_um, 1.0, 45)
    assert lo <= result.worst_position_arcmin.min() and result.worst_position_arcmin.max() <= hi
    assert np.all(result.random_position_arcmin <= result.worst_position_arcmin + 1e-12)
    assert result.interference_fraction == 0.0  # at the standard center distance nothing binds
    print(f"\nbatch of pair 1's design: {result.to_dict()['worst_position_arcmin']}")


def test_compensation_lowers_the_batch_and_shows_its_binding_risk() -> None:
    """Eq. (9) per unit puts the largest center distance at zero play: the lost motion falls to
    the runout term (at most 2 tan(a) (F_r1 + F_r2) plus the error), and units whose eccentric
    distance came out long bind slightly (the risk seed 000 warns of)."""
    plain = lost_motion_batch(UNIT, samples=4000, seed=5)
    comp = lost_motion_batch(UNIT, samples=4000, seed=5, compensate=True)
    assert np.median(comp.worst_position_arcmin) < 0.6 * np.median(plain.worst_position_arcmin)
    bound_um = 2 * TAN_A * ((23 + 16) + 2 + 6 + 6)  # runout span + eccentric error + bearings
    assert comp.worst_position_arcmin.max() <= backlash_arcmin_from_um(bound_um, 1.0, 45) + 0.03
    assert 0.2 < comp.interference_fraction < 0.8
    assert comp.interference_max_um <= 2 * TAN_A * 2 + 1e-9  # only the +2 um eccentric error


def test_seed_reproducible_and_chunking_invisible() -> None:
    a = lost_motion_batch(UNIT, samples=3000, seed=11, chunk=3000)
    b = lost_motion_batch(UNIT, samples=3000, seed=11, chunk=3000)
    np.testing.assert_array_equal(a.worst_position_arcmin, b.worst_position_arcmin)
    with pytest.raises(AnalysisError):
        lost_motion_batch(UNIT, samples=1)
    with pytest.raises(AnalysisError):
        Seed000Tolerances(m_value_internal_um=(53.0, 23.0))


def test_rig_batch_command(tmp_path: Path) -> None:
    out = tmp_path / "batch.json"
    res = subprocess.run(
        [sys.executable, "-m", "rig", "batch", str(UNITS_DIR / "seed000-pair1.json"),
         "--samples", "2000", "--json", str(out)],
        capture_output=True, text=True, timeout=120,
    )
    assert res.returncode == 0, res.stderr
    d = json.loads(out.read_text())
    assert d["samples"] == 2000 and len(d["band_95_arcmin"]) == 2
    assert d["band_95_arcmin"][0] < d["worst_position_arcmin"]["median"] < d["band_95_arcmin"][1]
