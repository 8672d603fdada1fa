"""docs/reliability.md's fault matrix, generated from the tests' results.

``python -m bench.fault_matrix`` runs the fault tests (``tests/rig/engine/test_fault_phases.py`` and
every ``tests/**/test_fault_matrix*.py``) with a JUnit XML report and writes the table between
the markers ``<!-- fault-matrix:begin -->`` and ``<!-- fault-matrix:end -->`` of
docs/reliability.md: fault x phase -> outcome, time to safe state, samples kept, message,
and whether the test passed. Rows come from each test's ``record_property`` values (fault,
phase, outcome, safe_s, samples_kept, message); a test without them gives a row with its
name and result.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

__all__ = ["main", "matrix_rows", "render_table"]

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "reliability.md"
BEGIN, END = "<!-- fault-matrix:begin -->", "<!-- fault-matrix:end -->"
COLUMNS = ("fault", "phase", "outcome", "safe_s", "samples_kept", "message")


def matrix_rows(junit_xml: Path) -> list[dict[str, str]]:
    """One row per test case of the JUnit report: its properties and its result."""
    rows = []
    for case in ET.parse(junit_xml).getroot().iter("testcase"):
        props = {p.get("name", ""): p.get("value", "")
                 for p in case.iter("property")}
        failed = case.find("failure") is not None or case.find("error") is not None
        skipped = case.find("skipped") is not None
        row = {c: props.get(c, "") for c in COLUMNS}
        if not row["fault"]:
            row["fault"] = case.get("name", "")
        row["test"] = "skipped" if skipped else "FAILED" if failed else "passed"
        rows.append(row)
    return rows


def _cell(text: str, width: int = 140) -> str:
    text = " ".join(str(text).split()).replace("|", "\\|")
    return text if len(text) <= width else text[: width - 3] + "..."


def render_table(rows: list[dict[str, str]]) -> str:
    """The markdown table of the matrix."""
    head = ("| fault | phase | outcome | to safe state (s) | samples kept | message | test |\n"
            "|---|---|---|---|---|---|---|\n")
    body = "".join(
        f"| {_cell(r['fault'], 60)} | {_cell(r['phase'], 30)} | {_cell(r['outcome'], 40)} | "
        f"{r['safe_s']} | {r['samples_kept']} | {_cell(r['message'])} | {r['test']} |\n"
        for r in rows)
    return head + body


def main() -> int:
    tests = ["tests/rig/engine/test_fault_phases.py", *sorted(
        str(p.relative_to(ROOT)) for p in (ROOT / "tests").rglob("test_fault_matrix*.py"))]
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "faults.xml"
        proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                               "-o", "junit_family=xunit1", f"--junitxml={report}", *tests],
                              cwd=ROOT)
        rows = matrix_rows(report)
    text = DOC.read_text(encoding="utf-8")
    if BEGIN not in text or END not in text:
        raise SystemExit(f"{DOC}: the markers {BEGIN} and {END} are missing")
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    DOC.write_text(f"{head}{BEGIN}\n{render_table(rows)}{END}{tail}", encoding="utf-8")
    print(f"{len(rows)} rows written to {DOC} (pytest exit {proc.returncode})")
    return proc.returncode


if __name__ == "__main__":
    sys.exit(main())
