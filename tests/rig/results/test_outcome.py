"""OK / not OK / incomplete with the limits in every record (issue 11, defects 3 and 4).

Runs are measured on the simulated rig over the real protocols (``rig measure`` as a process;
the Python API with a session for the locked input); the verdict is read back from run.json
and ``--json``. A campaign's (``rig campaign run``: campaign.json and every run.json) is read
from the tiny campaign tests/rig/commands/test_measure_cli.py measures once for its exit codes.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from rig.measurement.service import measure_plan, open_session, plant_config_for, run_meta
from rig.plans import LoopParams, hysteresis_plan
from rig.plans.campaign_file import SimulationSection
from rig.results.outcome import campaign_outcome, run_outcome
from rig.store import Store
from tests.support.paths import REPO as ROOT

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

RIG = [sys.executable, "-c", "from rig.cli import main; main()"]
UNIT = json.loads((ROOT / "rig/examples/units/seed000-pair1.json").read_text())


def _rig(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([*RIG, *args], capture_output=True, text=True, cwd=cwd, timeout=180)


@pytest.mark.parametrize(("run", "limits", "expected"), [
    ({"status": "completed", "lost_motion_arcmin": 2.0}, {"lost_motion_arcmin_max": 3.0},
     "ok"),
    ({"status": "completed", "lost_motion_arcmin": 4.0}, {"lost_motion_arcmin_max": 3.0},
     "not_ok"),
    ({"status": "aborted", "reason": "E-stop"}, {"lost_motion_arcmin_max": 3.0}, "incomplete"),
    ({"status": "aborted", "reason": "E-stop"}, {}, "incomplete"),
    ({"status": "completed", "lost_motion_arcmin": None,
      "errors": {"lost_motion_arcmin": "no loop"}}, {"lost_motion_arcmin_max": 3.0},
     "incomplete"),
    # a 50 % run cannot measure the stiffness (50..100 % of the rated torque): not applicable
    ({"status": "completed", "stiffness_Nm_per_arcmin": None, "amplitude_pct": 50.0,
      "lost_motion_arcmin": 2.0},
     {"stiffness_Nm_per_arcmin_min": 20.0, "lost_motion_arcmin_max": 3.0}, "ok"),
    ({"status": "completed", "stiffness_Nm_per_arcmin": 10.0, "amplitude_pct": 100.0},
     {"stiffness_Nm_per_arcmin_min": 20.0}, "not_ok"),
    # fault-matrix row 7: what a late torque channel produced never passes, limits or not
    ({"status": "completed", "stiffness_Nm_per_arcmin": -66.8, "backlash_arcmin": -2.64,
      "lost_motion_arcmin": 1.0}, {"lost_motion_arcmin_max": 3.0}, "incomplete"),
    ({"status": "completed", "backlash_arcmin": -2.64, "uncertainty": {"backlash_arcmin": 0.1}},
     {}, "incomplete"),
    # a play of zero measured a hair below zero, within its uncertainty, is a measurement
    ({"status": "completed", "backlash_arcmin": -0.01, "uncertainty": {"backlash_arcmin": 0.01},
      "lost_motion_arcmin": 0.5}, {"lost_motion_arcmin_max": 3.0}, "ok"),
])
def test_run_outcome_rules(run, limits, expected):
    assert run_outcome(run, limits)[0] == expected


def test_campaign_outcome_rules():
    assert campaign_outcome(["ok", "ok"], "completed") == "ok"
    assert campaign_outcome(["ok", "not_ok"], "aborted") == "not_ok"  # a known failure
    assert campaign_outcome(["ok", "incomplete"], "completed") == "incomplete"
    assert campaign_outcome(["ok"], "aborted") == "incomplete"
    assert campaign_outcome([], "completed") == "incomplete"


# OK / NOT OK with the limits in every record of a campaign run from the CLI: read from the
# tiny campaign measured once in tests/rig/commands/test_measure_cli.py
# (test_every_record_carries_limits_and_outcome there).


def test_part_amplitude_run_stiffness_not_applicable(tmp_path: Path):
    out = tmp_path / "run.json"
    res = _rig("measure", "--simulated", "--store", str(tmp_path / "store"), "--rated-torque",
               "10", "--amplitude", "50", "--steps", "2", "--pre-cycles", "0",
               "--min-stiffness", "20", "--max-lost-motion", "9", "--json", str(out),
               cwd=tmp_path)
    doc = json.loads(out.read_text())
    assert res.returncode == 0, (res.stdout[-1500:], res.stderr[-1500:])
    assert doc["outcome"] == "ok" and doc["failures"] == []
    # the flank impact at the play crossing dips the measured torque by more than 5 % of a
    # part amplitude; the branches follow the command, so the lost motion is still measured
    assert 3.5 < doc["lost_motion_arcmin"] < 5.5
    assert any("stiffness" in n and "not applicable" in n for n in doc["not_applicable"])
    stored = json.loads((Path(doc["path"]) / "run.json").read_text())
    assert stored["outcome"] == "ok"
    assert stored["limits"]["stiffness_Nm_per_arcmin_min"] == 20.0


def test_an_estopped_run_is_incomplete_and_a_locked_input_names_the_run(tmp_path: Path):
    """No --position: the input locked by hand at 90 deg is measured and recorded (the run is
    pos090, test.input_angle_deg 90), and an E-stop leaves the run incomplete, not FAIL."""
    store = Store(tmp_path / "store")
    loop = LoopParams(rated_torque_Nm=10.0, steps_per_quarter=2, dwell_s=0.0, pre_cycles=0,
                      extra_levels_pct=[3.0])
    limits = {"lost_motion_arcmin_max": 9.0}
    from rig.engine import EngineOptions

    plant = plant_config_for(UNIT, SimulationSection(plant={"effects": {"friction": {
        "enabled": True, "model": "lugre", "viscous_Nms_per_arcmin": 0.002}}}))
    with open_session(simulated=True, plant=plant) as session:
        session.io.lock_input(90.0, 30.0)  # as an operator would before a single run
        _, outcomes = measure_plan(session, store, hysteresis_plan(loop), run_meta(
            UNIT, session), options=EngineOptions(limits=limits, profile="nabtesco"))
        (done,) = outcomes
        started = threading.Event()
        box = {}

        def on_engine(engine):
            box["engine"] = engine

        def progress(event):
            if event.kind == "run_started":
                started.set()

        thread = threading.Thread(target=lambda: box.setdefault("result", measure_plan(
            session, store, hysteresis_plan(loop), run_meta(UNIT, session),
            options=EngineOptions(limits=limits, profile="nabtesco"), progress=progress,
            on_engine=on_engine)),
            daemon=True)
        thread.start()
        assert started.wait(60)
        box["engine"].estop("operator E-stop")
        thread.join(60)
    run_json = json.loads((done.path / "run.json").read_text())
    assert run_json["label"].startswith("pos090-") and done.label.startswith("pos090-")
    assert run_json["test"]["input_angle_deg"] == pytest.approx(90.0, abs=0.05)
    assert run_json["outcome"] == "ok" and run_json["limits"]["lost_motion_arcmin_max"] == 9.0
    (stopped,) = box["result"][1]
    stopped_json = json.loads((stopped.path / "run.json").read_text())
    assert stopped.status == "aborted" and stopped.outcome == "incomplete"
    assert stopped_json["outcome"] == "incomplete" and stopped_json["status"] == "aborted"


def test_a_late_torque_channel_is_found_from_the_loop_alone():
    """Fault-matrix row 7 without a cross-check sensor: the shipped example run with its
    torque column delayed (the transducer's stream late) gives a channel lag from the loaded
    flanks (analysis.channels.lag.channel_lag_samples), and the run has no verdict."""
    import numpy as np

    from rig.results.analyse import analyse_run
    from rig.runformat import read_run

    run = read_run(ROOT / "rig/examples/runs/pair3-pos000")
    assert analyse_run(run).to_dict()["channel_lag_s"] == 0.0
    limits = {"lost_motion_arcmin_max": 9.0}
    assert run_outcome({**analyse_run(run).to_dict(), "status": "completed"}, limits)[0] == "ok"
    torque = run.torque_Nm.copy()
    for delay_s in (0.03, 0.8):
        run.data["torque_Nm"] = np.interp(run.t_s - delay_s, run.t_s, torque)
        doc = analyse_run(run).to_dict()
        assert doc["channel_lag_s"] >= 0.02, doc["channel_lag_s"]
        outcome, why, _ = run_outcome({**doc, "status": "completed"}, limits)
        assert outcome == "incomplete" and "late" in why[0], why


# ------------------------------------------------------------------ issue 21 items 3, 13, 14

NAN, INF = float("nan"), float("inf")


@pytest.mark.parametrize(("value", "limits", "expected"), [
    (NAN, {"lost_motion_arcmin_max": 3.0}, "incomplete"),  # NaN > 3 is False: never inside
    (INF, {"lost_motion_arcmin_max": 3.0}, "incomplete"),
    (-INF, {"lost_motion_arcmin_max": 3.0}, "incomplete"),
    (None, {"lost_motion_arcmin_max": 3.0}, "incomplete"),
    ("2.0", {"lost_motion_arcmin_max": 3.0}, "incomplete"),  # a string is no measurement
    (2.0, {"lost_motion_arcmin_max": 3.0}, "ok"),
    (2.0, {}, "no_limits"),
    (2.0, None, "no_limits"),
    (2.0, {"lost_motion_arcmin_max": None, "backlash_arcmin_max": None}, "no_limits"),
    (NAN, {}, "no_limits"),  # nothing to judge it against
])
def test_a_metric_that_is_not_a_finite_number_is_never_inside_a_limit(value, limits,
                                                                       expected):
    outcome, causes, _ = run_outcome({"status": "completed", "label": "p0",
                                      "result": {"lost_motion_arcmin": value}}, limits)
    assert outcome == expected
    if expected == "incomplete":
        assert len(causes) == 1 and causes[0].startswith("run p0: lost_motion_arcmin")
    if value is not None and expected == "incomplete" and not isinstance(value, str):
        assert "not a finite number" in causes[0], causes


def test_a_nan_beside_a_failed_limit_is_still_not_ok():
    run = {"status": "completed", "lost_motion_arcmin": 4.0, "backlash_arcmin": NAN}
    outcome, causes, _ = run_outcome(run, {"lost_motion_arcmin_max": 3.0,
                                           "backlash_arcmin_max": 2.0})
    assert outcome == "not_ok" and len(causes) == 2


def test_campaign_outcome_without_limits():
    assert campaign_outcome(["no_limits", "no_limits"], "completed") == "no_limits"
    assert campaign_outcome(["no_limits"], "aborted") == "incomplete"
    assert campaign_outcome(["no_limits", "incomplete"], "completed") == "incomplete"


def test_one_vocabulary_and_the_filter_words():
    from rig.results.outcome import OUTCOME_WORDS, OUTCOMES, outcome_word, parse_outcome

    assert OUTCOMES == ("ok", "not_ok", "incomplete", "no_limits")
    assert [outcome_word(o) for o in OUTCOMES] == ["OK", "NOT OK", "INCOMPLETE", "NO LIMITS"]
    assert "FAIL" not in OUTCOME_WORDS.values() and "PASS" not in OUTCOME_WORDS.values()
    for text, code in (("NOT OK", "not_ok"), ("not ok", "not_ok"), ("Not_OK", "not_ok"),
                       ("ok", "ok"), ("No Limits", "no_limits"), ("no_limits", "no_limits"),
                       (" INCOMPLETE ", "incomplete")):
        assert parse_outcome(text) == code, text
    for bad in ("FAIL", "pass", "", None, 1):
        with pytest.raises(ValueError, match="outcome must be one of ok, not_ok, incomplete, "
                                             "no_limits"):
            parse_outcome(bad)


@pytest.mark.parametrize(("meta", "expected"), [
    # written before "no_limits" existed: an "ok" with no limit set reads NO LIMITS
    ({"status": "completed", "outcome": "ok", "limits": None,
      "result": {"lost_motion_arcmin": 4.0}}, "no_limits"),
    ({"status": "completed", "outcome": "ok",
      "limits": {"lost_motion_arcmin_max": None, "backlash_arcmin_max": None,
                 "stiffness_Nm_per_arcmin_min": None},
      "result": {"lost_motion_arcmin": 4.0}}, "no_limits"),
    # an "ok" stored beside a NaN metric and a limit: never OK
    ({"status": "completed", "outcome": "ok", "limits": {"lost_motion_arcmin_max": 3.0},
      "result": {"lost_motion_arcmin": NAN}}, "incomplete"),
    ({"status": "completed", "outcome": "ok", "limits": {"lost_motion_arcmin_max": 3.0},
      "result": {"lost_motion_arcmin": 2.0}}, "ok"),
    ({"status": "completed", "outcome": "not_ok", "limits": {"lost_motion_arcmin_max": 3.0},
      "result": {"lost_motion_arcmin": 4.0}}, "not_ok"),
    # none recorded (an imported run): judged now
    ({"status": "completed", "result": {"lost_motion_arcmin": 2.0}}, "no_limits"),
    ({"result": {"lost_motion_arcmin": 2.0}, "limits": {"lost_motion_arcmin_max": 1.0}},
     "not_ok"),
    ({"status": "running"}, None),
    ({"status": "completed", "outcome": "pass"}, "pass"),  # another lab's own word
])
def test_older_and_foreign_records_are_read_in_the_one_vocabulary(meta, expected):
    from rig.results.outcome import recorded_outcome

    assert recorded_outcome(meta) == expected


def test_an_old_campaign_ok_without_limits_reads_no_limits():
    from rig.results.outcome import recorded_campaign_outcome

    assert recorded_campaign_outcome("ok", {"lost_motion_arcmin_max": None},
                                     ["no_limits", "no_limits"], "completed") == "no_limits"
    assert recorded_campaign_outcome("ok", {"lost_motion_arcmin_max": 3.0},
                                     ["ok", "incomplete"], "completed") == "incomplete"
    assert recorded_campaign_outcome("not_ok", {}, [], "completed") == "not_ok"
    assert recorded_campaign_outcome(None, {}, ["no_limits"], "completed") == "no_limits"
    assert recorded_campaign_outcome(None, {}, [], "running") is None


def test_a_run_without_limits_is_no_limits_everywhere(tmp_path: Path):
    """Issue 21 item 13: no limits set is neither OK nor NOT OK: ``rig measure`` says NO
    LIMITS (exit 0: nothing failed), run.json records "no_limits", ``rig runs`` shows it."""
    out = tmp_path / "run.json"
    res = _rig("measure", "--simulated", "--store", str(tmp_path / "store"), "--rated-torque",
               "10", "--steps", "2", "--pre-cycles", "0", "--json", str(out), cwd=tmp_path)
    assert res.returncode == 0, (res.stdout[-1500:], res.stderr[-1500:])
    assert "outcome: NO LIMITS (no limits set)" in res.stderr
    assert not re.search(r"outcome: OK|FAIL", res.stdout + res.stderr)
    doc = json.loads(out.read_text())
    assert doc["outcome"] == "no_limits" and doc["failures"] == []
    stored = json.loads((Path(doc["path"]) / "run.json").read_text())
    assert stored["outcome"] == "no_limits"
    assert all(v is None for v in stored["limits"].values())
    res = _rig("runs", "--store", str(tmp_path / "store"), cwd=tmp_path)
    row = next(line for line in res.stdout.splitlines() if doc["run_id"] in line)
    assert "NO LIMITS" in row and f"{doc['lost_motion_arcmin']:.3f}" in row, row


@pytest.mark.parametrize(("plant_kind", "unit_kind", "expected"), [
    ("internal_involute", "beveloid", "incomplete"),
    ("beveloid", None, "incomplete"),
    ("cycloid", "cycloid", "ok"),
    (None, "beveloid", "ok"),  # a real rig: no simulated plant
])
def test_a_run_measured_on_another_kind_of_plant_is_never_ok(plant_kind, unit_kind, expected):
    """Issue 33 item 10: the simulated devices' plant of another unit kind than the run's
    unit: INCOMPLETE in one line, even where a record says "ok"."""
    from rig.results.outcome import recorded_outcome

    unit = {"serial": "B-1"} | ({"kind": unit_kind} if unit_kind else {})
    meta = {"status": "completed", "label": "r1", "unit": unit, "outcome": "ok",
            "limits": {"lost_motion_arcmin_max": 3.0}, "result": {"lost_motion_arcmin": 2.0}}
    if plant_kind is not None:
        meta["simulation"] = {"plant_kind": plant_kind, "plant": {}}
    outcome, causes, _ = run_outcome(meta, meta["limits"])
    assert outcome == expected and recorded_outcome(meta) == expected
    if expected == "incomplete":
        words = {"internal_involute": "internal involute pair"}
        line = (f"run r1: measured on a simulated {words.get(plant_kind, plant_kind)} plant, "
                f"the unit is a {words.get(unit_kind or 'internal_involute', unit_kind)}")
        assert causes == [line]
