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
  analysis.diagnosis.lag_if_it_helps);
- two nulls read by an output encoder of 2^19 counts per turn (the loaded twist about 9
  counts long) whose calibrated stiffness read 2.2 % and 4.0 % above seed 004 eq. (8) came
  out `unexplained` by the 2 % stiffness gap (now the tolerance includes half a count over
  the loaded twist: analysis.diagnosis.candidates.quantisation_share).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

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
                   "otw-s5-c000": "none", "otw-s5-c004": "none", "otw-s5-c008": "none"}, \
        proc.stdout[-3000:]
    assert summary["false_alarms"] == 0


def test_a_coarse_encoder_widens_the_stiffness_gap_by_half_a_count() -> None:
    """otw-s5-c008 (2^19 counts per turn, a 10 N*m unit): half a count over the loaded twist
    (the amplitude over seed 004 eq. (8)'s stiffness) is about 5.7 % of it; the calibrated
    stiffness reads 4.0 % above eq. (8), inside that tolerance and beyond the flat 2 %."""
    import numpy as np

    from rig.results.diagnose import diagnose_path

    labels = json.loads((DATA / "labels.json").read_text())
    counts = labels["otw-s5-c008"]["true_params"]["encoder_counts_per_rev"]
    assert counts == 2 ** 19
    campaign, diagnosis = diagnose_path(DATA / "cases" / "otw-s5-c008")
    report = diagnosis.to_dict()
    k = report["parameter_error"]["stiffness_Nm_per_arcmin"]
    # the smallest run's amplitude (N*m) gives the shortest loaded twist, the largest share
    amplitude = min(float(np.percentile(np.abs(np.asarray(r.torque_Nm)), 99.5))
                    for r in campaign.runs)
    count_arcmin = 360.0 * 60.0 / counts
    expected = 0.5 * count_arcmin / (amplitude / k["nominal"])
    assert k["quantisation_share"] == pytest.approx(expected, rel=0.05)
    assert k["gap_tolerance"] == pytest.approx(max(0.02, 2 * k["relative_se"], expected),
                                               rel=0.05)
    assert 0.02 < abs(k["ratio"] - 1.0) < k["gap_tolerance"]
    assert report["verdict"] == "none", report["reason"]
