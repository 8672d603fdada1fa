"""The diagnosis on campaigns recorded over the wire (tests/data/otw/README.md): the rig's
own dynamics and artefacts, through the real sequencer, drivers and protocols.

- a null whose only "evidence" was a candidate that closes 2 % of a gap barely above the
  noise came out `unexplained` (now such evidence does not count for "there is a gap":
  analysis.diagnosis, docs/diagnosis.md step 5);
- a bearing clearance of the same recording schedule, which must still be found;
- a null whose first block after a play crossing had landed on the other flank while its
  torque was still inside the noise band came out `unexplained` (now that block may lie
  anywhere up to the other flank: analysis.diagnosis.data.landed_blocks);
- a null whose runs crossed the play with less friction than the campaign's one estimate
  came out `unexplained` on the points just before each crossing (now a run's friction may
  be lower by up to the ordinary friction: analysis.diagnosis.fit.run_chain);
- a null whose torque lag (7 ms) the check "does the lag help the null model" refused for 3 of
  4 runs, because that check's null kept the campaign's friction exact, came out
  `unexplained` on the branches the lag separates (now the check uses the diagnosis' null:
  analysis.diagnosis.lag_if_it_helps).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from tests.support.paths import TEST_DATA

DATA = TEST_DATA / "otw"


def test_recorded_campaigns_are_diagnosed_as_their_labels(tmp_path: Path) -> None:
    out = tmp_path / "summary.json"
    proc = subprocess.run(
        [sys.executable, "-m", "rig", "validate-diagnosis", "--jobs", "1", "--verbose",
         "--cases-dir", str(DATA / "cases"), "--labels", str(DATA / "labels.json"),
         "--json", str(out)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    summary = json.loads(out.read_text())
    got = {r["case"]: r["verdict"] for r in summary["results"]}
    assert got == {"otw-s2-c024": "none", "otw-s2-c005": "bearing_clearance",
                   "otw-s3-c020": "none", "otw-s4-c022": "none",
                   "otw-s5-c000": "none"}, \
        proc.stdout[-3000:]
    assert summary["false_alarms"] == 0
