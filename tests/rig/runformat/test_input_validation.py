"""Outside-probe rows 3a-3h and 16 of issue 12: mutated run folders, unit files and campaign
files are refused before anything is computed or moves, in one line naming the file and the
key, with exit code 2 and no traceback; and the readers, fuzzed as whole files, only ever
refuse with the rig's own error.

The mutations start from the shipped example run (rig/examples/runs/pair3-pos000) and the
shipped campaign (examples/campaigns/seed000-pair1.toml): real files, not made by the code
under test.
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from analysis.errors import AnalysisError
from rig.core.errors import RigError
from rig.plans.campaign_file import CampaignError, load_campaign
from rig.results.analyse import analyse_run
from rig.runformat import read_run
from tests.support.paths import REPO as ROOT

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

EXAMPLE_RUN = ROOT / "rig" / "examples" / "runs" / "pair3-pos000"
EXAMPLE_CAMPAIGN = ROOT / "examples" / "campaigns" / "seed000-pair1.toml"
UNIT_FILE = ROOT / "rig" / "examples" / "units" / "seed000-pair1.json"


def _run_copy(tmp: Path, name: str, meta: Callable[[dict], None] | None = None,
              rows: Callable[[list[str]], list[str]] | None = None,
              raw_meta: str | None = None) -> Path:
    folder = tmp / name
    shutil.copytree(EXAMPLE_RUN, folder)
    doc = json.loads((folder / "run.json").read_text())
    if meta is not None:
        meta(doc)
    (folder / "run.json").write_text(raw_meta if raw_meta is not None else json.dumps(doc))
    if rows is not None:
        lines = (folder / "samples.csv").read_text().splitlines(keepends=True)
        (folder / "samples.csv").write_text("".join(rows(lines)))
    return folder


def _set(section: str, key: str, value: object) -> Callable[[dict], None]:
    return lambda doc: doc.setdefault(section, {}).__setitem__(key, value)


def _column(lines: list[str], name: str, value: str, rows: range) -> list[str]:
    k = lines[0].strip().split(",").index(name)
    out = [lines[0]]
    for i, line in enumerate(lines[1:]):
        cells = line.rstrip("\n").split(",")
        if i in rows:
            cells[k] = value
        out.append(",".join(cells) + "\n")
    return out


RUN_CASES: dict[str, tuple[dict, str]] = {
    "3a rated torque {}": (dict(meta=_set("test", "rated_torque_Nm", {})),
                           "test.rated_torque_Nm"),
    "3a rated torque ''": (dict(meta=_set("test", "rated_torque_Nm", "")),
                           "test.rated_torque_Nm"),
    "3b run.json 100,000 levels deep": (dict(raw_meta="[" * 100_000 + "]" * 100_000),
                                        "nested too deeply"),
    "3c encoder counts NaN": (dict(meta=_set("sensors", "encoder_counts_per_rev", math.nan)),
                              "sensors.encoder_counts_per_rev"),
    "3c three torque cells 1e308": (
        dict(rows=lambda L: _column(L, "torque_Nm", "1e308", range(5, 8))), "torque_Nm"),
    "3g three rows": (dict(rows=lambda L: L[:4]), "at least"),
    "3g constant angle": (
        dict(rows=lambda L: _column(L, "output_angle_deg", "123.4", range(len(L)))),
        "never moves"),
    "3h unit kind null": (dict(meta=_set("unit", "kind", None)), "unit.kind"),
}


@pytest.mark.parametrize("case", list(RUN_CASES))
def test_mutated_run_is_refused_naming_file_and_key(case: str, tmp_path: Path) -> None:
    spec, words = RUN_CASES[case]
    folder = _run_copy(tmp_path, "run", **spec)
    with pytest.raises(RigError) as err:
        analyse_run(read_run(folder))
    message = str(err.value)
    assert words in message and str(folder) in message, message
    assert "\n" not in message.strip()


def _campaign(tmp: Path, edit: Callable[[str], str]) -> Path:
    text = EXAMPLE_CAMPAIGN.read_text().replace(
        '"../../rig/examples/units/seed000-pair1.json"', json.dumps(str(UNIT_FILE)))
    path = tmp / "campaign.toml"
    path.write_text(edit(text))
    return path


def _swap(old: str, new: str) -> Callable[[str], str]:
    """The campaign text with ``old`` replaced by ``new``."""
    return lambda text: text.replace(old, new)


CAMPAIGN_CASES: dict[str, tuple[Callable[[str], str], str]] = {
    "3d 10,000 positions": (lambda s: s.replace(
        "positions_deg = [0.0, 90.0, 180.0, 270.0]",
        "positions_deg = [" + ", ".join(f"{i % 360}.0" for i in range(10_000)) + "]"),
        "steps (at most 200000)"),
    "3d 1,000 repeats x 100 cycles": (lambda s: s.replace("repeats = 1", "repeats = 1000")
                                      .replace("\ncycles = 1\n", "\ncycles = 100\n"),
                                      "steps (at most 200000)"),
    "3e unit file /dev/zero": (lambda s: s.replace(json.dumps(str(UNIT_FILE)), '"/dev/zero"'),
                               "/dev/zero: the unit file must be a regular file"),
    "3f steps_per_quarter = true": (_swap("steps_per_quarter = 4", "steps_per_quarter = true"),
                                    "plan.steps_per_quarter"),
    "3f rate_Nm_per_s = true": (_swap("rate_Nm_per_s = 25.0", "rate_Nm_per_s = true"),
                                "plan.rate_Nm_per_s"),
    "3f extra_levels_pct = [true]": (_swap("extra_levels_pct = [3.0]", "extra_levels_pct = [true]"),
                                     "plan.extra_levels_pct.0"),
    "16 profile typo": (_swap('profile = "nabtesco"', 'profile = "harmonic_drive"'),
                        "'harmonic-drive'"),
    "16 cycles = true": (_swap("\ncycles = 1\n", "\ncycles = true\n"), "plan.cycles"),
    "16 extra_levels_pct = [500]": (_swap("extra_levels_pct = [3.0]", "extra_levels_pct = [500]"),
                                    "less than 100"),
    "16 extra_levels_pct = [nan]": (_swap("extra_levels_pct = [3.0]", "extra_levels_pct = [nan]"),
                                    "finite number"),
    "3b TOML 5,000 levels deep": (lambda s: s + "\n[x]\ny = " + "[" * 5000 + "]" * 5000 + "\n",
                                  "nested too deeply"),
}


@pytest.mark.parametrize("case", list(CAMPAIGN_CASES))
def test_mutated_campaign_is_refused_before_anything_moves(case: str, tmp_path: Path) -> None:
    edit, words = CAMPAIGN_CASES[case]
    path = _campaign(tmp_path, edit)
    with pytest.raises(CampaignError) as err:
        load_campaign(path).unit_data()
    assert words in str(err.value), str(err.value)


def test_the_shipped_campaign_still_loads(tmp_path: Path) -> None:
    camp = load_campaign(_campaign(tmp_path, lambda s: s))
    assert camp.unit_data()["serial"] == "seed000-pair1"


@pytest.mark.parametrize("argv", [
    ["campaign", "run", "{campaign}", "--simulated", "--preview"],
    ["analyse", "{run}"],
    ["model", "{unit}"],
])
def test_cli_refuses_in_one_line_with_exit_2(argv: list[str], tmp_path: Path) -> None:
    """The CLI: one line naming the file, exit code 2, no traceback (no rig moves: the
    campaign is refused by its size before the simulated rig is even started)."""
    campaign = _campaign(tmp_path, CAMPAIGN_CASES["3d 1,000 repeats x 100 cycles"][0])
    run = _run_copy(tmp_path, "run", meta=_set("test", "rated_torque_Nm", {}))
    unit = tmp_path / "unit.json"
    unit.write_text(json.dumps({**json.loads(UNIT_FILE.read_text()), "kind": None}))
    args = [a.format(campaign=campaign, run=run, unit=unit) for a in argv]
    res = subprocess.run([sys.executable, "-m", "rig", *args], capture_output=True, text=True,
                         timeout=60, cwd=tmp_path)
    assert res.returncode == 2, (res.stdout, res.stderr)
    assert "Traceback" not in res.stderr + res.stdout
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert lines and lines[0].startswith("rig: error:"), res.stderr
    assert str(tmp_path) in res.stderr or "unit.json" in res.stderr or "run.json" in res.stderr


# ----------------------------------------------------------------------- whole-file fuzzing

JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers(-10**6, 10**6) | st.floats(allow_nan=True)
    | st.text(max_size=5),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner,
                                                                 max_size=3),
    max_leaves=6,
)
RUN_KEYS = [("test", "rated_torque_Nm"), ("test", "ratio"), ("test", "input_angle_deg"),
            ("sensors", "encoder_counts_per_rev"), ("unit", "kind"), ("unit", "z1"),
            ("unit", "module_mm"), ("test", "amplitude_pct"), (None, "unit"), (None, "test")]


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(key=st.sampled_from(RUN_KEYS), value=JSON_VALUES)
def test_fuzzed_run_json_is_analysed_or_refused_never_crashes(tmp_path: Path, key, value
                                                              ) -> None:
    section, name = key
    doc = json.loads((EXAMPLE_RUN / "run.json").read_text())
    (doc if section is None else doc.setdefault(section, {}))[name] = value
    folder = tmp_path / "fuzz"
    shutil.rmtree(folder, ignore_errors=True)
    shutil.copytree(EXAMPLE_RUN, folder)
    (folder / "run.json").write_text(json.dumps(doc))
    try:
        result = analyse_run(read_run(folder)).to_dict()
    except (RigError, AnalysisError):
        return
    json.dumps(result, allow_nan=False, default=str)  # an accepted run gives finite JSON


TOML_VALUES = st.sampled_from(["true", "false", "nan", "inf", "-1", "0", "1e400", "[]",
                               "[true]", '"x"', "{}", "1_000", "3.0", "[nan]", "[500]"])
PLAN_KEYS = ["steps_per_quarter", "rate_Nm_per_s", "cycles", "pre_cycles", "dwell_s",
             "amplitude_pct", "extra_levels_pct", "rated_torque_Nm", "zero_band_Nm"]


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(key=st.sampled_from(PLAN_KEYS), value=TOML_VALUES)
def test_fuzzed_campaign_is_loaded_or_refused_never_crashes(tmp_path: Path, key: str,
                                                            value: str) -> None:
    import re

    def edit(text: str) -> str:
        return re.sub(rf"(?m)^{key} = .*$", f"{key} = {value}", text, count=1)

    try:
        camp = load_campaign(_campaign(tmp_path, edit))
    except CampaignError:
        return
    plan = camp.plan
    for field in ("rate_Nm_per_s", "dwell_s", "rated_torque_Nm", "amplitude_pct"):
        number = getattr(plan, field)
        assert not isinstance(number, bool) and math.isfinite(number)
    assert all(0 < v < 100 for v in plan.extra_levels_pct)
