"""Grading rules of labelled campaigns (rig.validate.labels, rig.validate.cases): the
development sets' graders' semantics on hand-written reports, and malformed labels."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest

from rig.core.errors import RigError
from rig.validate.cases import generator_name, record, summarise_graded, summary_line
from rig.validate.labels import grade, label_from_dict, read_labels
from tests.support.paths import TEST_DATA


def _report(verdict: str, also: tuple[str, ...] = (), candidates: tuple[str, ...] = (),
            shrinks: dict[str, float] | None = None) -> dict:
    ranking = [{"effect": e, "shrink": s} for e, s in (shrinks or {}).items()]
    return {"format": "rig-diagnosis/1", "verdict": verdict, "candidates": list(candidates),
            "also": [{"effect": a} for a in also], "gap_before": {"rms_arcsec": 1.0},
            "ranking": ranking}


def test_set_a_format_defaults_follow_its_grader() -> None:
    """No ``acceptable``: the effect; unexplained may be ambiguous; the shaft may be ambiguous
    naming it, and then carries the shaft's ranking shrink."""
    shaft = label_from_dict("c1", {"effect": "shaft_compliance", "difficulty": "hard"})
    assert shaft.category == "hard"
    g = grade(shaft, _report("ambiguous", candidates=("mesh_stiffness", "shaft_compliance"),
                             shrinks={"shaft_compliance": 0.9}))
    assert g["correct"] and g["shrink"] == 0.9
    assert not grade(shaft, _report("ambiguous", candidates=("mesh_stiffness",)))["correct"]
    oov = label_from_dict("c2", {"effect": "unexplained"})
    assert grade(oov, _report("ambiguous"))["correct"]
    runout = label_from_dict("c3", {"effect": "runout"})
    assert not grade(runout, _report("ambiguous", candidates=("runout",)))["correct"]


def test_set_b_format_acceptable_candidates_also_and_false_alarms() -> None:
    conf = label_from_dict("c4", {"effect": "shaft_compliance", "category": "confounded",
                                  "acceptable": ["shaft_compliance", "ambiguous"],
                                  "ambiguous_candidates_any": ["shaft_compliance"]})
    g = grade(conf, _report("ambiguous", candidates=("shaft_compliance",),
                            shrinks={"shaft_compliance": 0.9}))
    assert g["correct"] and g["shrink"] is None  # set B: no shrink for an ambiguous verdict
    two = label_from_dict("c5", {"effect": "friction", "also": ["runout"],
                                 "acceptable": ["friction"], "category": "two_effects"})
    g = grade(two, _report("friction", also=("runout", "thermal_expansion"),
                           shrinks={"friction": 0.7}))
    assert (g["correct"], g["also_hits"], g["also_reported"], g["also_reported_ok"]) == (
        True, 1, 2, 1)
    assert g["shrink"] == 0.7
    none = label_from_dict("c6", {"effect": "none", "acceptable": ["none"]})
    assert grade(none, _report("none", also=("friction",)))["false_alarm"]
    assert not grade(none, _report("none"))["false_alarm"]


def test_summary_counts_recall_precision_and_median_shrink() -> None:
    two = label_from_dict("c5", {"effect": "friction", "also": ["runout"],
                                 "acceptable": ["friction"], "category": "two_effects"})
    none = label_from_dict("c6", {"effect": "none", "acceptable": ["none"], "category": "trap"})
    recs = [record(two, _report("friction", also=("runout",), shrinks={"friction": 0.8})),
            record(two, _report("runout", shrinks={"runout": 0.5})),
            record(none, _report("none")),
            record(none, {"error": "RigError: boom", "seconds": 0.1})]
    s = summarise_graded("x", recs)
    assert (s["cases"], s["correct"], s["false_alarms"], s["failures"]) == (4, 2, 0, 1)
    assert s["also_recall"] == 0.5 and s["also_precision"] == 1.0
    assert s["median_shrink"] == 0.8
    assert s["confusion"]["friction+runout"] == {"friction+runout": 1, "runout": 1}
    assert s["confusion"]["none"] == {"none": 1, "<crash>": 1}
    assert summary_line(s) == ("x: 2/4 correct, also_recall=0.50, also_precision=1.00, "
                               "false_alarms=0, median_shrink=0.80")


def test_malformed_labels_name_file_line_column_or_key(tmp_path) -> None:
    bad = tmp_path / "labels.json"
    bad.write_text('{"c1": {"effect": "runout",}\n}')
    with pytest.raises(RigError, match=r"labels.json: line 1, column \d+"):
        read_labels(bad)
    bad.write_text(json.dumps({"c1": {"effect": "gremlins"}}))
    with pytest.raises(RigError, match=r"key 'c1'.effect: 'gremlins'"):
        read_labels(bad)
    bad.write_text(json.dumps({"c1": {"effect": "runout", "acceptable": ["maybe"]}}))
    with pytest.raises(RigError, match=r"key 'c1'.acceptable: unknown verdict"):
        read_labels(bad)
    with pytest.raises(RigError, match="cannot read"):
        read_labels(tmp_path / "missing.json")


def test_generator_name_from_the_folder(tmp_path) -> None:
    assert generator_name(tmp_path / "devset-a" / "cases") == "devset-a"
    assert generator_name(tmp_path / "mine") == "mine"


def _rig(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rig", *args], capture_output=True, text=True,
                          timeout=120)


def test_cli_refuses_unpaired_or_malformed_labels_in_one_line(tmp_path) -> None:
    (tmp_path / "cases").mkdir()
    out = _rig("validate-diagnosis", "--cases-dir", str(tmp_path / "cases"))
    assert out.returncode == 2 and "--labels" in out.stderr
    bad = tmp_path / "labels.json"
    bad.write_text("{\n  \"c1\": [}\n")
    out = _rig("validate-diagnosis", "--cases-dir", str(tmp_path / "cases"), "--labels", str(bad))
    assert out.returncode == 2 and "labels.json: line 2, column" in out.stderr
    bad.write_text(json.dumps({"c1": {"effect": "runout"}}))
    out = _rig("validate-diagnosis", "--cases-dir", str(tmp_path / "cases"), "--labels", str(bad))
    assert out.returncode == 2 and "no folder for labelled case(s) c1" in out.stderr


def test_cli_reports_each_generator_apart(tmp_path) -> None:
    """Our generator (one case) beside a labelled folder (one none trap of set B): two summary
    lines and the JSON keyed by generator."""
    src = TEST_DATA / "devset" / "b"
    labels = json.loads((src / "labels.json").read_text())
    shutil.copytree(src / "cases" / "ca1e0aa0a1e", tmp_path / "lab" / "cases" / "ca1e0aa0a1e")
    lab = tmp_path / "lab" / "labels.json"
    lab.write_text(json.dumps({"ca1e0aa0a1e": labels["ca1e0aa0a1e"]}))
    out = _rig("validate-diagnosis", "--with-generator", "--cases", "1", "--cases-dir",
               str(tmp_path / "lab" / "cases"), "--labels", str(lab), "--json",
               str(tmp_path / "s.json"))
    assert out.returncode == 0, out.stderr
    gens = json.loads((tmp_path / "s.json").read_text())["generators"]
    assert set(gens) == {"ours", "lab"} and gens["lab"]["cases"] == gens["ours"]["cases"] == 1
    assert gens["lab"]["results"][0]["truth"] == "none"
    assert "each generator apart:" in out.stdout
    assert "  ours: " in out.stdout and "  lab: " in out.stdout
