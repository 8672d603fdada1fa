"""The decision layer reads top to bottom (issue 31, point 5).

- no function in analysis/diagnosis/ is over 120 lines (def to the end of its body: before,
  ``diagnose`` was 382, ``describe_params`` 145, ``_attribute`` 128, ``prepare_run`` 152);
- the verdict is set in one place: only :func:`analysis.diagnosis.decide.decide` makes a
  ``Decision``, by the first of an ordered list of named rules, each with its physical
  reason; nothing assigns a report's ``verdict`` after the report is built;
- the package's modules are split by what they are: design, candidates, decide, report.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "analysis" / "diagnosis"
MOST_LINES = 120


def _functions(path: Path) -> list[tuple[str, int]]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return [(node.name, node.end_lineno - node.lineno + 1) for node in ast.walk(tree)
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
            and node.end_lineno is not None]


def test_no_function_in_the_diagnosis_package_is_over_120_lines() -> None:
    long = [(p.name, name, n) for p in sorted(PACKAGE.glob("*.py"))
            for name, n in _functions(p) if n > MOST_LINES]
    assert not long, long


def test_the_package_is_split_into_design_candidates_decide_and_report() -> None:
    for module in ("design", "candidates", "decide", "report", "policy"):
        assert (PACKAGE / f"{module}.py").is_file(), module


def test_the_verdict_is_set_in_one_place_by_ordered_named_rules() -> None:
    from analysis.diagnosis import decide as decide_module

    rules = decide_module.RULES
    names = [r.name for r in rules]
    assert len(names) == len(set(names))
    assert all(len(r.reason) > 40 for r in rules), "each rule states its physical reason"
    # the rules' order: no gap first (flanks, a series compliance, none), then what the
    # attribution among the candidates gives
    assert names.index("within_noise") < names.index("series_compliance_takes_the_gap")
    assert names[-1] == "effect_explains"
    makers = []
    assigns = []
    for path in sorted(PACKAGE.glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for fn in ast.walk(tree):
            if not isinstance(fn, ast.FunctionDef):
                continue
            for node in ast.walk(fn):
                if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                        and node.func.id == "Decision"):
                    makers.append((path.name, fn.name))
                if isinstance(node, ast.Assign):
                    for target in node.targets:
                        if (isinstance(target, ast.Subscript)
                                and isinstance(target.slice, ast.Constant)
                                and target.slice.value == "verdict"):
                            assigns.append((path.name, fn.name))
    assert makers == [("decide.py", "decide")]
    assert assigns == [], "a report's verdict is never assigned after it is built"
