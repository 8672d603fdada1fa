"""Issue 33 item 5 at the command line: ``rig measure`` and ``rig campaign run`` refuse a
number outside its physical range (rig/core/ranges.py) in one line naming the option or the
file's key and the range, and a plan longer than 8 h unless confirmed (``--confirm-long``,
a campaign file's ``confirm_long = true``). Only previews: nothing moves."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from rig.cli import app
from rig.core.errors import RigError

CAMPAIGN = """
name = "t1"
[unit]
z_internal = 45
z_external = 40
module_mm = 1.0
[plan]
rated_torque_Nm = RATED
dwell_s = DWELL
steps_per_quarter = 4
[axes]
positions_deg = [0.0, 90.0]
"""


def _invoke(*args: str) -> tuple[int, str]:
    """Exit code and the one-line error (``rig: error: ...`` as main() prints it)."""
    res = CliRunner().invoke(app, list(args))
    if isinstance(res.exception, RigError):
        return 2, str(res.exception)
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    return res.exit_code, res.output


@pytest.mark.parametrize(("args", "expected"), [
    (["--dwell", "1e9"], "--dwell: expected from 0 to 3600 s (got 1000000000.0)"),
    (["--rate", "1e-300"], "--rate: expected from 0.001 to 100000 N·m/s (got 1e-300)"),
    (["--rated-torque", "1e308"], "--rated-torque: expected greater than 0 and at most 1e+07 "
                                  "N·m (got 1e+308)"),
    (["--max-lost-motion", "1e300"], "--max-lost-motion: expected greater than 0 and at most "
                                     "10000 arcmin (got 1e+300)"),
    (["--position", "1e300"], "--position: expected from -3600 to 3600 deg (got 1e+300)"),
    (["--test", "transmission-error", "--speed", "1e-9"],
     "--speed: expected from 1 to 6000 rpm (got 1e-09)"),
    (["--test", "transmission-error", "--speed", "0.01"],
     "--speed: expected from 1 to 6000 rpm (got 0.01)"),
])
def test_measure_refuses_absurd_options(args: list[str], expected: str) -> None:
    code, text = _invoke("measure", "--preview", *args)
    assert (code, text) == (2, expected)


def test_measure_refuses_a_long_plan_unless_confirmed() -> None:
    code, text = _invoke("measure", "--preview", "--dwell", "3600", "--steps", "10")
    assert code == 2 and text.startswith("the plan would take about 44 h, more than 8 h: "
                                         "confirm it with --confirm-long"), text
    code, text = _invoke("measure", "--preview", "--dwell", "3600", "--steps", "10",
                         "--confirm-long")
    assert code == 0 and "1 run, about 158" in text, text


def _campaign(tmp_path: Path, rated: str = "10.0", dwell: str = "0.1", extra: str = "") -> Path:
    path = tmp_path / "c.toml"
    path.write_text(extra + CAMPAIGN.replace("RATED", rated).replace("DWELL", dwell),
                    encoding="utf-8")
    return path


def test_campaign_refuses_a_long_plan_unless_the_flag_or_the_file_confirms(tmp_path) -> None:
    long = _campaign(tmp_path, dwell="1800.0")
    code, text = _invoke("campaign", "run", str(long), "--preview")
    assert code == 2 and "more than 8 h: confirm it with --confirm-long (or confirm_long = " \
        f"true in {long})" in text, text
    code, text = _invoke("campaign", "run", str(long), "--preview", "--confirm-long")
    assert code == 0 and "2 runs, about" in text, text
    confirmed = _campaign(tmp_path, dwell="1800.0", extra="confirm_long = true\n")
    code, text = _invoke("campaign", "run", str(confirmed), "--preview")
    assert code == 0 and "2 runs, about" in text, text


def test_campaign_with_a_rated_torque_of_1e308_is_refused_in_one_line(tmp_path) -> None:
    """It previewed as "about nan s" and its real run ended in an internal error: now the
    file is refused before anything (the simulated rig included) starts."""
    path = _campaign(tmp_path, rated="1e308")
    res = subprocess.run([sys.executable, "-m", "rig", "campaign", "run", str(path),
                          "--simulated", "--store", str(tmp_path / "store")],
                         capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert res.returncode == 2, res.stderr
    assert res.stderr.strip() == (f"rig: error: {path}: plan.rated_torque_Nm: expected "
                                  "greater than 0 and at most 1e+07 N·m (got 1e+308)")
    assert not (tmp_path / "store").exists()


def test_measure_te_speed_of_a_hundredth_rpm_is_refused_before_the_rig_starts(tmp_path):
    """A 13-hour run at 0.01 rpm started: now exit 2, one line, nothing started."""
    res = subprocess.run([sys.executable, "-m", "rig", "measure", "--simulated", "--test",
                          "transmission-error", "--speed", "0.01",
                          "--store", str(tmp_path / "store")],
                         capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert res.returncode == 2, res.stderr
    assert res.stderr.strip() == ("rig: error: --speed: expected from 1 to 6000 rpm "
                                  "(got 0.01)")


UNIT = "rig/examples/units/seed000-pair1.json"


@pytest.mark.parametrize(("args", "expected"), [
    # rig batch: 1e11 units ended in "internal error: MemoryError ... 745 GiB"
    (["batch", UNIT, "-n", "100000000000"],
     "Invalid value for '--samples' / '-n': expected from 1 to 1e+06 units (got 100000000000)"),
    # ... 1e308 N·m printed a table of 2.15e+304 arcmin, and -5 % a band below zero
    (["batch", UNIT, "--rated-torque", "1e308"],
     "Invalid value for '--rated-torque': expected greater than 0 and at most 1e+07 N·m "
     "(got 1e+308)"),
    (["batch", UNIT, "--percent", "-5"],
     "Invalid value for '--percent': expected greater than 0 and at most 100 % of rated "
     "(got -5.0)"),
    (["batch", UNIT, "--seed", "-1"],
     "Invalid value for '--seed': expected from 0 to 9.22337e+18 (got -1)"),
    (["model", UNIT, "--rated-torque", "nan"],
     "Invalid value for '--rated-torque': expected greater than 0 and at most 1e+07 N·m "
     "(got nan)"),
    (["model", UNIT, "--pct", "inf"],
     "Invalid value for '--pct': expected greater than 0 and at most 100 % of rated (got inf)"),
    (["montecarlo", "-n", "0"],
     "Invalid value for '--samples' / '-n': expected from 2 to 1e+07 samples (got 0)"),
    (["montecarlo", "--window-revs", "inf"],
     "Invalid value for '--window-revs': expected greater than 0 and at most 100 output "
     "revolutions (got inf)"),
    (["rotor", "--elements", "100000"],
     "Invalid value for '--elements': expected from 1 to 96 elements (got 100000)"),
    (["rotor", "--disc-at", "2"],
     "Invalid value for '--disc-at': expected from 0 to 1 of the shaft's length (got 2.0)"),
    # click's own min/max let NaN through (every comparison with NaN is false)
    (["diagnose", "rig/examples", "--alpha", "nan"],
     "Invalid value for '--alpha': expected from 1e-06 to 0.5 (got nan)"),
    (["sim", "--sync-period", "nan"],
     "Invalid value for '--sync-period': expected from 0.0005 to 1 s (got nan)"),
    (["te-calibrate", "a", "b", "--indexed-by", "1e9"],
     "Invalid value for '--indexed-by': expected from -360 to 360 deg (got 1000000000.0)"),
])
def test_model_and_statistics_commands_refuse_absurd_options(args: list[str],
                                                             expected: str) -> None:
    """Issue 33 item 5, the commands that were left: one line naming the option and its
    range (rig/core/ranges.py), exit 2, before any work starts."""
    from tests.support.paths import REPO

    res = subprocess.run([sys.executable, "-m", "rig", *args], capture_output=True, text=True,
                         timeout=60, cwd=REPO, env={**os.environ, "COLUMNS": "200"})
    assert res.returncode == 2, res.stdout[-500:] + res.stderr[-500:]
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and expected in lines[0], res.stderr
    assert "Traceback" not in res.stderr and res.stdout == ""
