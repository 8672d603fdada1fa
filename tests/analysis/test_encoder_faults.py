"""Issue 33 item 1: a frozen or jumping encoder leaves the loop without a verdict.

The loops here are made from the closed forms of :mod:`analysis.loop.synthetic` (free play,
Coulomb friction on a spring: seed 000 Fig. 6), read by an encoder of 2^23 counts with
noise from none to 0.3 arcsec rms, the faults put in as the simulated encoder's backdoor
does (a reading that keeps its count, a count offset that stays). The recorded campaigns of
tests/data (another generator: a rig's contact dynamics, drive lag and ripple, stick-slip
friction) must give no finding at all.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from analysis.loop import analyse_loop
from analysis.loop.branches import white_noise_std
from analysis.loop.encoder_faults import find_encoder_faults
from analysis.loop.synthetic import flank, friction_twist
from rig.results.analyse import analyse_run
from rig.results.outcome import run_outcome
from rig.runformat import read_run
from tests.support.paths import TEST_DATA as DATA

CPR = 2**23
COUNT_ARCMIN = 21600.0 / CPR
RATED, K, PLAY = 10.0, 29.0, 4.5
ARCSEC = 1.0 / 60.0


def _torque(dwell: int = 25, rate_Nm_per_row: float = 0.1) -> np.ndarray:
    """0 -> +T -> -T -> 0 at 25 N*m/s in 4 ms rows, with a dwell at each tip."""
    n = int(RATED / rate_Nm_per_row)
    up = np.linspace(0, RATED, n, endpoint=False)
    down = np.linspace(RATED, -RATED, 2 * n, endpoint=False)
    back = np.linspace(-RATED, 0, n + 1)
    return np.concatenate([up, np.full(dwell, RATED), down, np.full(dwell, -RATED), back])


def _read(torque: np.ndarray, noise_arcsec: float, friction_Nm: float = 0.2,
          seed: int = 1) -> np.ndarray:
    """Output angle (deg) of a unit with play and friction, read in whole counts."""
    twist = friction_twist(torque, friction_Nm, K) + 0.5 * PLAY * flank(torque)
    rng = np.random.default_rng(seed)
    counts = np.round((twist + noise_arcsec * ARCSEC * rng.standard_normal(torque.size))
                      / COUNT_ARCMIN)
    return counts * COUNT_ARCMIN / 60.0


def _findings(torque: np.ndarray, angle_deg: np.ndarray) -> list:
    twist = angle_deg * 60.0
    loop = analyse_loop(np.arange(torque.size) * 0.004, torque, twist, rated_torque_Nm=RATED,
                        twist_resolution_arcmin=COUNT_ARCMIN)
    m = loop.metrics
    return find_encoder_faults(
        torque, twist, angle_deg, loop.branches.sample_direction(), rated_torque_Nm=RATED,
        stiffness_Nm_per_arcmin=K, count_arcmin=COUNT_ARCMIN,
        twist_noise_arcmin=white_noise_std(twist), torque_noise_Nm=white_noise_std(torque),
        torque_offset_Nm=m["torque_offset_Nm"].value if "torque_offset_Nm" in m else 0.0,
        play_arcmin=PLAY)


NOISES = [0.0, 0.05, 0.3]


@pytest.mark.parametrize("friction_share", [0.002, 0.02, 0.05])
@pytest.mark.parametrize("noise", NOISES)
def test_healthy_loops_have_no_finding(noise: float, friction_share: float) -> None:
    torque = _torque()
    assert _findings(torque, _read(torque, noise, friction_share * RATED)) == []


def _top(torque: np.ndarray) -> int:
    return int(np.argmax(torque >= RATED))


@pytest.mark.parametrize("noise", NOISES)
def test_a_short_freeze_at_the_top_is_found(noise: float) -> None:
    """The reading kept from 90 % of +T on the way up through the dwell to 8 % of rated
    down (0.44 s): the stiffness it gives is several % too high."""
    torque = _torque()
    angle = _read(torque, noise)
    start = int(np.argmax(torque >= 0.9 * RATED))
    stop = _top(torque) + 25 + 8
    angle[start:stop] = angle[start]
    found = _findings(torque, angle)
    assert [f.kind for f in found][:1] == ["freeze"], found
    assert found[0].start <= start + 1 and found[0].stop >= stop - 2
    assert "frozen encoder reading" in found[0].describe(np.arange(torque.size) * 0.004)


@pytest.mark.parametrize("counts", [1000, -1000, 2500, -3000])
@pytest.mark.parametrize("noise", NOISES)
@pytest.mark.parametrize("where", ["unloading", "top", "negative"])
def test_a_position_jump_is_found(noise: float, counts: int, where: str) -> None:
    """A count offset that stays, on the unloading flank at +60 %, during the dwell at +T, or
    at -60 % of rated on the way down."""
    torque = _torque()
    angle = _read(torque, noise)
    at = {"unloading": int(np.argmax((torque < 0.6 * RATED) & (np.arange(torque.size)
                                                              > _top(torque)))),
          "top": _top(torque) + 10,
          "negative": int(np.argmax(torque < -0.6 * RATED))}[where]
    angle[at:] += counts * COUNT_ARCMIN / 60.0
    found = _findings(torque, angle)
    steps = [f for f in found if f.kind == "step"]
    assert steps and steps[0].stop == at, found
    assert steps[0].seen_arcmin == pytest.approx(counts * COUNT_ARCMIN, abs=0.02)
    text = steps[0].describe(np.arange(torque.size) * 0.004)
    assert "position jump that no torque explains" in text and f"samples {at}-{at + 1}" in text


def test_a_jump_against_the_motion_inside_the_play_is_found() -> None:
    """Inside the zero band the output crosses its play; a step back further than the play
    is no rebound."""
    torque = _torque()
    angle = _read(torque, 0.0)
    at = int(np.argmax((np.abs(torque) < 0.02 * RATED) & (np.arange(torque.size)
                                                          > _top(torque))))
    angle[at:] += 2500 * COUNT_ARCMIN / 60.0  # the unloading twist goes down: this is back
    assert any(f.kind == "step" and f.stop == at for f in _findings(torque, angle))


def _otw_runs() -> list[Path]:
    return sorted(p.parent for p in (DATA / "otw").rglob("run.json"))


def test_recorded_rig_dynamics_give_no_finding() -> None:
    """Campaigns of the offline rig generator (flank impacts and their rebound, drive lag,
    ripple, stick-slip friction, quantised torque): no run is called an encoder fault."""
    runs = _otw_runs()
    assert len(runs) >= 20
    for path in runs:
        analysis = analyse_run(read_run(path))
        assert analysis.encoder_faults == [], (path.name, analysis.encoder_faults)


def test_a_jump_in_a_recorded_run_leaves_it_without_a_verdict(tmp_path: Path) -> None:
    """The same recorded run, its output reading offset by 2,500 counts from the middle of
    its unloading on: INCOMPLETE, naming the output encoder and the samples."""
    run = read_run(_otw_runs()[0])
    clean = analyse_run(run).to_dict()
    assert run_outcome({"status": "completed", **clean}, {"lost_motion_arcmin_max": 100})[0] \
        == "ok"
    cpr = float(run.sensors["encoder_counts_per_rev"])
    at = int(np.argmax(run.torque_Nm)) + 40
    run.output_angle_deg[at:] += 2500 * 360.0 / cpr
    got = analyse_run(run).to_dict()
    outcome, why, _ = run_outcome({"status": "completed", **got},
                                  {"lost_motion_arcmin_max": 100})
    assert outcome == "incomplete", why
    assert "output encoder" in why[0] and "position jump" in why[0] and "no verdict" in why[0]
    assert f"samples {at}-{at + 1}" in why[0]
