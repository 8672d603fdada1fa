"""Labels of a labelled folder of campaigns and the grading of one diagnosis report.

The labels file is the development sets' ``labels.json``: a JSON object ``{case_id: label}``,
each label an object with

- ``effect`` (required): the true effect, one of :data:`VOCAB`, ``none`` or ``unexplained``;
- ``acceptable``: verdicts counted correct (default: see :func:`read_labels`);
- ``ambiguous_candidates_any``: an ``ambiguous`` verdict counts only if the report's
  ``candidates`` name one of these;
- ``also``: the smaller second effects present (two-effect cases), expected under ``also``;
- ``category`` (or ``difficulty``): the group the case is reported in;
- ``expected_min_shrink``, ``true_params``: shown, never used to judge.

Grading follows the development sets' graders (``grade_a.py`` / ``grade_b.py``):

- correct: the verdict is acceptable (``ambiguous`` with a named candidate as above);
- a false alarm: a ``none`` case with any other verdict or any ``also`` entry;
- ``also`` recall: labelled ``also`` effects listed under the report's ``also``;
  precision: reported ``also`` entries (on labelled two-effect cases) that name an effect truly
  present and are not the verdict itself;
- shrink of a correct verdict: the report's ranking shrink of the verdict's effect. A label
  without ``acceptable`` (set A's format) counts a correct ``ambiguous`` verdict with the
  labelled effect's ranking shrink, as set A's grader does.

Nothing here is read by the diagnosis: the labels meet the report only after it is written.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rig.core.errors import RigError

VOCAB = ("backlash", "mesh_stiffness", "friction", "stiffness_nonlinearity", "runout",
         "bearing_clearance", "thermal_expansion", "torque_sensor_offset", "shaft_compliance",
         "tooth_spacing_error")
VERDICTS = frozenset(VOCAB) | {"none", "unexplained", "ambiguous"}
TRUTHS = frozenset(VOCAB) | {"none", "unexplained"}


@dataclass(frozen=True)
class Label:
    """One case's answer (see the module docstring)."""

    case_id: str
    effect: str
    acceptable: tuple[str, ...]
    candidates_any: tuple[str, ...] = ()
    also: tuple[str, ...] = ()
    category: str = "-"
    expected_min_shrink: float | None = None
    #: set A's convention: a correct ``ambiguous`` verdict carries the labelled effect's shrink
    shrink_of_effect: bool = False
    extra: dict[str, Any] = field(default_factory=dict, compare=False)

    @property
    def key(self) -> str:
        """The truth as reported in the confusion: ``effect[+also...]``."""
        return self.effect + "".join("+" + a for a in self.also)


def _strings(value: Any, where: str) -> tuple[str, ...]:
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise RigError(f"{where}: expected a list of strings, got {value!r}")
    return tuple(value)


def label_from_dict(case_id: str, raw: Any, where: str = "labels") -> Label:
    """One label from its JSON object; a malformed one raises RigError naming the key."""
    at = f"{where}: key {case_id!r}"
    if not isinstance(raw, dict):
        raise RigError(f"{at}: a label must be a JSON object, got {type(raw).__name__}")
    effect = raw.get("effect")
    if effect not in TRUTHS:
        raise RigError(f"{at}.effect: {effect!r} is not one of {', '.join(sorted(TRUTHS))}")
    if "acceptable" in raw:
        acceptable = _strings(raw["acceptable"], f"{at}.acceptable")
        unknown = [v for v in acceptable if v not in VERDICTS]
        if unknown:
            raise RigError(f"{at}.acceptable: unknown verdict(s) {', '.join(unknown)}")
        cands = _strings(raw.get("ambiguous_candidates_any", []), f"{at}.ambiguous_candidates_any")
        shrink_of_effect = False
    else:
        # set A's grader: the effect itself; out of vocabulary may honestly be ambiguous; the
        # shaft may be ambiguous naming it (one loop cannot tell it from the mesh stiffness)
        acceptable = (effect,)
        cands = ()
        if effect == "unexplained":
            acceptable = ("unexplained", "ambiguous")
        elif effect == "shaft_compliance":
            acceptable = ("shaft_compliance", "ambiguous")
            cands = ("shaft_compliance",)
        shrink_of_effect = True
    also = _strings(raw.get("also") or [], f"{at}.also")
    bad = [a for a in also if a not in VOCAB]
    if bad:
        raise RigError(f"{at}.also: unknown effect(s) {', '.join(bad)}")
    ems = raw.get("expected_min_shrink")
    if ems is not None and not (isinstance(ems, int | float) and not isinstance(ems, bool)):
        raise RigError(f"{at}.expected_min_shrink: expected a number or null, got {ems!r}")
    category = raw.get("category") or raw.get("difficulty") or "-"
    if not isinstance(category, str):
        raise RigError(f"{at}.category: expected a string, got {category!r}")
    return Label(case_id, effect, acceptable, cands, also, category,
                 None if ems is None else float(ems), shrink_of_effect,
                 {k: v for k, v in raw.items() if k == "true_params"})


def read_labels(path: str | Path) -> dict[str, Label]:
    """Read a ``labels.json``; malformed JSON names the file, line and column."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise RigError(f"{p}: cannot read the labels: {exc.strerror or exc}") from exc
    try:
        raw = json.loads(text)
    except json.JSONDecodeError as exc:
        raise RigError(f"{p}: line {exc.lineno}, column {exc.colno}: {exc.msg}") from exc
    if not isinstance(raw, dict):
        raise RigError(f"{p}: expected a JSON object {{case_id: label}}, got {type(raw).__name__}")
    return {cid: label_from_dict(cid, lab, str(p)) for cid, lab in raw.items()}


def _names(entries: Any) -> list[str]:
    if not isinstance(entries, list):
        return []
    out = []
    for e in entries:
        if isinstance(e, dict) and isinstance(e.get("effect"), str):
            out.append(e["effect"])
        elif isinstance(e, str):
            out.append(e)
    return out


def _finite(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)


def ranking_shrink(report: dict[str, Any], effect: str) -> float | None:
    """The shrink the report's ranking gives ``effect`` (from gap_after / gap_before when the
    entry has no ``shrink``), as the graders read it; None when not ranked."""
    gb = (report.get("gap_before") or {}).get("rms_arcsec")
    for e in report.get("ranking") or []:
        if isinstance(e, dict) and e.get("effect") == effect:
            if _finite(e.get("shrink")):
                return float(e["shrink"])
            ga = e.get("gap_after")
            ga = ga.get("rms_arcsec") if isinstance(ga, dict) else None
            if _finite(ga) and _finite(gb) and gb > 0:
                return 1.0 - ga / gb
    return None


def grade(label: Label, report: dict[str, Any]) -> dict[str, Any]:
    """Grade one ``rig-diagnosis/1`` report against its label: verdict, also, candidates,
    correct, false_alarm, also_hits / also_reported / also_reported_ok, shrink (of a correct
    verdict, else None)."""
    verdict = report.get("verdict")
    also = _names(report.get("also") or [])
    cands = _names(report.get("candidates") or [])
    ok = verdict in label.acceptable
    if ok and verdict == "ambiguous" and label.candidates_any:
        ok = bool(set(cands) & set(label.candidates_any))
    shrink = None
    if ok:
        if verdict in VOCAB:
            shrink = ranking_shrink(report, verdict)
        elif verdict == "ambiguous" and label.shrink_of_effect and label.effect in VOCAB:
            shrink = ranking_shrink(report, label.effect)
    present = {label.effect, *label.also}
    hits = sum(1 for a in label.also if a in also)
    rep_ok = sum(1 for a in also if a in present and a != verdict) if label.also else 0
    return {
        "verdict": verdict, "also": also, "candidates": cands, "correct": ok,
        "false_alarm": label.effect == "none" and (verdict != "none" or bool(also)),
        "also_hits": hits, "also_reported": len(also) if label.also else 0,
        "also_reported_ok": rep_ok, "shrink": shrink,
    }
