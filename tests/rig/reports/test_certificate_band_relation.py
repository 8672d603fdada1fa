"""The certificate of a cycloid unit says how its nominal model and its batch band relate
(issue 33 item 17): the band is the worst crank position, above a perfect unit."""

from __future__ import annotations

import json
import shutil

from rig.reports.certificate import Subject, certificate_context, render_certificate
from tests.support.hostile import page_text
from tests.support.paths import REPO

RUN = REPO / "rig" / "examples" / "runs" / "pair1-pos000"
CYCLOID = REPO / "rig" / "examples" / "units" / "cycloid-seed002.json"


def test_a_cycloid_runs_certificate_states_nominal_and_band(tmp_path):
    folder = tmp_path / "run"
    shutil.copytree(RUN, folder)
    meta = json.loads((folder / "run.json").read_text())
    meta["unit"] = {**json.loads(CYCLOID.read_text()), "serial": "CY-1"}
    (folder / "run.json").write_text(json.dumps(meta))
    text = " ".join(page_text(render_certificate(certificate_context(Subject(folder, None))))
                    .split())
    assert "worst position, 95 %): 2.40" in text
    assert "Nominal and band: the band is each unit's worst crank position" in text
    assert "lies below it by their size; at one random position the batch spans" in text
