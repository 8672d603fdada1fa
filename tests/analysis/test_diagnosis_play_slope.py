"""Torque inside the free play (analysis.diagnosis.play_slope), on loops written from the
definition of a dead zone (seed 000 Fig. 6: flanks of stiffness k either side of a free play,
nothing carried between), not from the project's plant: a spring beside the gear tilts the
flat middle by its own stiffness, friction only shifts it by one level per direction."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.diagnosis.play_slope import PlayTilt, play_core, play_slope

K_MESH = 36.0  # N*m/arcmin
PLAY = 4.0  # arcmin


def _loop(k_parallel: float, friction_Nm: float, seed: int, cycles: int = 2,
          samples: int = 4000, dahl_arcmin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(torque N*m, twist arcmin) of a twist-driven triangle sweep through the play and
    +-0.4 arcmin onto each flank: the gear carries k (|theta| - play/2) beyond a flank and
    nothing inside; a spring k_parallel beside it, a Coulomb friction of the moving output,
    the torque channel's noise (0.01 N*m) and the encoder's (0.002 arcmin). ``dahl_arcmin``:
    the friction rises from the other direction's level over this travel after a reversal
    (Dahl's exponential rise) instead of switching at once."""
    rng = np.random.default_rng(seed)
    reach = PLAY / 2 + 0.4
    phase = np.linspace(0.0, cycles, samples)
    theta = reach * (2.0 * np.abs(2.0 * (phase % 1.0) - 1.0) - 1.0) + 123.4
    x = theta - 123.4
    gear = K_MESH * np.sign(x) * np.maximum(np.abs(x) - PLAY / 2, 0.0)
    moving = np.sign(np.gradient(x))
    friction = friction_Nm * moving
    if dahl_arcmin > 0:
        travel = np.abs(x - (-reach * moving))  # from the last reversal
        friction = friction * (1.0 - 2.0 * np.exp(-travel / dahl_arcmin))
    torque = gear + k_parallel * x + friction
    return (torque + rng.normal(0.0, 0.01, x.size),
            theta + rng.normal(0.0, 0.002, x.size))


@pytest.mark.parametrize("share", [0.01, 0.03])
def test_a_parallel_spring_is_read_as_its_stiffness(share: float) -> None:
    """The slope inside the play is the spring's stiffness, to 3 %, far beyond its error."""
    runs = [(*_loop(share * K_MESH, 0.05, seed), K_MESH, 0.002) for seed in range(3)]
    for side in (1, -1):  # both halves of the crossings
        ps = play_slope(runs, side=side)
        assert ps is not None and ps.runs == 3
        assert ps.slope_Nm_per_arcmin == pytest.approx(share * K_MESH, rel=0.03)
        assert ps.z > 20.0
        assert ps.coverage > 0.8


def test_a_friction_rising_after_a_start_tilts_one_half_only() -> None:
    """A friction of 0.5 N*m that builds up over 1 arcmin of travel after a reversal (Dahl)
    rises with the twist mostly on the half of the crossing just after the flank it left:
    2 * 0.5 (e^-1.2 - e^-2.4) / 1.2 arcmin = 0.18 N*m/arcmin there (0.49 % of the mesh),
    0.053 past the centre; the weaker half (what the diagnosis decides on) stays
    within 0.2 % of the mesh stiffness."""
    runs = [(*_loop(0.0, 0.5, seed, dahl_arcmin=1.0), K_MESH, 0.002) for seed in range(3)]
    tilt = PlayTilt(play_slope(runs, side=-1), play_slope(runs, side=1))
    assert tilt.behind is not None and tilt.ahead is not None
    assert tilt.behind.slope_Nm_per_arcmin > 0.002 * K_MESH
    assert abs(tilt.ahead.slope_Nm_per_arcmin) < 0.002 * K_MESH
    weak = tilt.weaker()
    assert weak is tilt.ahead


@pytest.mark.parametrize("friction", [0.0, 0.05, 0.5])
def test_friction_alone_gives_no_slope(friction: float) -> None:
    """A Coulomb friction of any size shifts the play's torque by one level per direction of
    motion: the slope stays within 0.1 % of the mesh stiffness."""
    runs = [(*_loop(0.0, friction, seed), K_MESH, 0.002) for seed in range(3)]
    for side in (1, -1):
        ps = play_slope(runs, side=side)
        assert ps is not None
        assert abs(ps.slope_Nm_per_arcmin) < 0.001 * K_MESH


def test_the_core_is_the_middle_of_the_measured_play() -> None:
    """The play's centre and width come from the loaded branches brought to zero torque:
    the sweep's centre (123.4 arcmin) and 0.3 of the 4 arcmin play, to the noise."""
    torque, twist = _loop(0.0, 0.0, 7, samples=8000)
    # the sweep only reaches 14 N*m: its branches at 20-50 % of that amplitude
    centre, half = play_core(torque, twist, K_MESH)  # type: ignore[misc]
    assert centre == pytest.approx(123.4, abs=0.01)
    assert half == pytest.approx(0.3 * PLAY, abs=0.01)


def test_too_few_samples_in_the_play_read_nothing() -> None:
    """A loop that jumps the play (no samples inside it) gives no statistic."""
    torque, twist = _loop(0.0, 0.0, 3)
    outside = np.abs(twist - 123.4) > PLAY / 2
    assert play_slope([(torque[outside], twist[outside], K_MESH, 0.002)]) is None
