"""Issue 33 item 14: a loop whose twist runs against the torque (an output encoder counting
the other way round) is no measurement: every view says "below zero: no measurement" with the
likely cause, from one place (rig/results/outcome.py), and its verdict is never OK."""

from __future__ import annotations

from rig.results.analyse import analyse_run
from rig.results.outcome import (
    AGAINST_TORQUE,
    BELOW_ZERO,
    below_zero_keys,
    below_zero_note,
    below_zero_text,
    run_outcome,
)
from tests.support.reversed_twist import LIMITS, reversed_twist_run


def test_a_reversed_loop_is_named_with_its_cause_and_never_ok() -> None:
    run = reversed_twist_run()
    d = {**analyse_run(run).to_dict(), "status": "completed"}
    assert d["lost_motion_arcmin"] < 0 and d["stiffness_Nm_per_arcmin"] < 0  # the test data
    assert below_zero_keys(d) == ["lost_motion_arcmin", "backlash_arcmin",
                                  "stiffness_Nm_per_arcmin", "loop_area_J"]
    assert below_zero_note(d) == ("lost motion, backlash, stiffness, loop area below zero: no "
                                  "measurement (the twist runs against the torque: check the "
                                  "output encoder's counting direction)")
    outcome, causes, _ = run_outcome(d, LIMITS)  # limits every figure would meet taken as is
    assert outcome == "incomplete"
    assert causes and all(AGAINST_TORQUE in c for c in causes), causes


def test_the_certificate_words_are_the_results_words() -> None:
    """One place: the certificate prints what rig/results/outcome.py words."""
    from rig.reports import certificate

    assert certificate.below_zero_text is below_zero_text
    assert below_zero_text("lost_motion_arcmin", -0.5, 0.01, ".3f", "") == BELOW_ZERO
    assert below_zero_text("lost_motion_arcmin", -0.5, 0.01, ".3f", "",
                           against_torque=True) == f"{BELOW_ZERO} ({AGAINST_TORQUE})"
    # a stiffness below zero is never "below resolution": no gear unit has one
    assert below_zero_text("stiffness_Nm_per_arcmin", -0.01, 1.0, ".2f", "") == BELOW_ZERO
    assert below_zero_note({"lost_motion_arcmin": 4.1, "loop_area_J": 1e-4}) is None
