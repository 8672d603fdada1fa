"""Issue 33 item 5: what ``rig analyse`` refuses (rig/results/analyse.py ``check_samples``),
from the shipped example run with one reading made absurd: one line naming the column and
the sample, never an internal error."""

from __future__ import annotations

import numpy as np
import pytest

from rig.core.errors import RigError
from rig.results.analyse import analyse_run
from rig.runformat import Run, read_run
from tests.support.paths import REPO

EXAMPLE_RUN = REPO / "rig" / "examples" / "runs" / "pair3-pos000"


def _with(column: str, value: float) -> Run:
    run = read_run(EXAMPLE_RUN)
    values = {c: np.array(run.data[c], dtype=float) for c in
              ("t_s", "torque_Nm", "output_angle_deg")}
    values[column][5] = value
    return Run.from_arrays("absurd", values["t_s"], values["torque_Nm"],
                           values["output_angle_deg"], unit=run.unit, test=run.test,
                           sensors=run.sensors)


@pytest.mark.parametrize(("column", "value", "words"), [
    ("output_angle_deg", 1e300, "output_angle_deg of sample 6 (t = "),
    ("output_angle_deg", -2e9, "output_angle_deg of sample 6 (t = "),
    ("torque_Nm", 1e31, "torque_Nm of sample 6 (t = "),
])
def test_absurd_readings_are_refused_in_one_line(column: str, value: float,
                                                 words: str) -> None:
    with pytest.raises(RigError) as err:
        analyse_run(_with(column, value))
    message = str(err.value)
    assert words in message and "not a reading" in message, message
    assert "\n" not in message


def test_a_rated_torque_of_1e308_is_refused_naming_the_range() -> None:
    with pytest.raises(RigError, match=r"rated torque: expected greater than 0 and at most "
                                       r"1e\+07 N·m \(got 1e\+308\)"):
        analyse_run(read_run(EXAMPLE_RUN), rated_torque_Nm=1e308)


def test_the_example_run_itself_is_analysed() -> None:
    assert analyse_run(read_run(EXAMPLE_RUN)).loop.n_cycles >= 1
