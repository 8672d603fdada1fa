"""The decision layer's policy and the false-alarm floor (issue 31, points 5 and 6).

- every report records the thresholds it was decided by, under ``decision_policy``
  (analysis.diagnosis.policy.DecisionPolicy);
- a false-alarm probability calibrated on B bootstrap draws is never stated below the
  calibration's resolution 1 / (B + 1): before, it read 0.0 and 1e-239 (devset B case
  c7ea1e69eab: 0.0 for the lack of fit, 5.7e-47 for the best candidate);
- the report says how it was calibrated: the method and the number of draws.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from tests.support.paths import TEST_DATA

CASE = TEST_DATA / "devset" / "b" / "cases" / "c7ea1e69eab"


def _faps(obj: Any, path: str = "") -> Iterator[tuple[str, Any]]:
    if isinstance(obj, dict):
        for k, v in obj.items():
            if k == "false_alarm_probability":
                yield f"{path}/{k}", v
            yield from _faps(v, f"{path}/{k}")
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _faps(v, f"{path}[{i}]")


def _rig_diagnose(case: Path, out: Path, *extra: str) -> dict[str, Any]:
    proc = subprocess.run([sys.executable, "-m", "rig", "diagnose", str(case), "--json",
                           str(out), *extra], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(out.read_text())


def test_report_records_the_decision_policy_and_floors_false_alarms(tmp_path: Path) -> None:
    report = _rig_diagnose(CASE, tmp_path / "report.json")
    assert "decision_policy" in report
    from analysis.diagnosis.policy import DecisionPolicy

    assert report["decision_policy"] == DecisionPolicy().to_dict()
    json.dumps(report["decision_policy"], allow_nan=False)
    cal = report["calibration"]
    assert cal["draws"] == cal["replicates"] == 199
    assert cal["false_alarm_resolution"] == 1.0 / (cal["draws"] + 1)
    assert "bootstrap" in cal["method"]
    faps = [(p, v) for p, v in _faps(report) if v is not None]
    # the ranking's, each candidate's calibrated evidence and the lack of fit's
    assert len(faps) >= 3
    for path, value in faps:
        assert value > 0, path
        assert value >= cal["false_alarm_resolution"], (path, value)
    # the verdict of this case is unchanged by the floor (it was decided on the same values)
    assert report["verdict"] == "unexplained"


def test_no_false_alarm_probability_below_the_calibrations_resolution(tmp_path: Path) -> None:
    report = _rig_diagnose(CASE, tmp_path / "report.json")
    faps = [(p, v) for p, v in _faps(report) if v is not None]
    assert len(faps) >= 3
    floor = 1.0 / (report["calibration"]["replicates"] + 1)
    low = [(p, v) for p, v in faps if not v >= floor]
    assert not low, low


def test_a_given_alpha_is_the_policy_recorded() -> None:
    from analysis.diagnosis import ALPHA, diagnose
    from analysis.diagnosis.policy import POLICY, DecisionPolicy
    from rig.results.diagnose import run_input
    from rig.runformat import read_run_or_campaign

    assert ALPHA == POLICY.alpha == DecisionPolicy().alpha
    runs = [run_input(r) for r in read_run_or_campaign(CASE).runs]
    report = diagnose(runs, alpha=0.05, replicates=39).to_dict()
    assert report["decision_policy"]["alpha"] == 0.05
    assert report["calibration"]["alpha"] == 0.05
    assert report["calibration"]["false_alarm_resolution"] == 1.0 / 40
    assert all(v >= 1.0 / 40 for _, v in _faps(report) if v is not None)
