"""The [calibration] section of the rig configuration (rig/hardware/calibration.py): validated
strictly
with errors naming file and key, recorded per run, an expired one refused unless overridden,
and the override recorded; ``rig measure --operator/--calibration-override`` on the simulated
rig (``rig sim``, real protocols) end to end."""

from __future__ import annotations

import datetime as dt
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from pydantic import ValidationError

from rig.hardware.calibration import CalibrationExpired, calibration_meta, expired
from rig.hardware.config import RigConfigError, load_rig_config
from rig.plans.campaign_file import CampaignError, campaign_from_mapping
from rig.store import Store
from tests.support.paths import REPO

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

EXAMPLE = REPO / "examples" / "rigs" / "simulated.toml"
TODAY = dt.datetime.now(dt.UTC).date()


def with_calibration(path: Path, table: str, base: Path = EXAMPLE) -> Path:
    path.write_text(base.read_text(encoding="utf-8") + "\n" + table, encoding="utf-8")
    return path


VALID = f"""
[calibration.transducer]
id = "T40B-123456"
certificate = "DAkkS D-K-15070 2026-881"
date = {TODAY - dt.timedelta(days=30)}
due = {TODAY + dt.timedelta(days=335)}
uncertainty = "0.05 % of full scale"

[calibration.encoder]
id = "ENC-7781"
certificate = "C-2"
date = "{TODAY - dt.timedelta(days=400)}"
due = "{TODAY - dt.timedelta(days=1)}"
uncertainty = 0.3
"""


def test_calibration_section_loads_frozen_and_is_recorded(tmp_path: Path):
    config = load_rig_config(with_calibration(tmp_path / "rig.toml", VALID))
    t = config.calibration["transducer"]
    assert t.id == "T40B-123456" and t.due == TODAY + dt.timedelta(days=335)
    assert config.calibration["encoder"].uncertainty == 0.3
    with pytest.raises(ValidationError):
        t.due = TODAY  # frozen like the other config models
    assert expired(config.calibration) == [
        f"calibration of encoder (ENC-7781, certificate C-2) expired on "
        f"{TODAY - dt.timedelta(days=1)}"]
    # refused without a reason, naming the sensor and the way out
    with pytest.raises(CalibrationExpired, match=r"calibration of encoder .* expired .*"
                                                 r"--calibration-override REASON"):
        calibration_meta(config.calibration)
    meta = calibration_meta(config.calibration, "  booked for Monday ", "A. Operator")
    assert [c["sensor"] for c in meta["calibration"]] == ["transducer", "encoder"]
    assert meta["calibration"][0] == {
        "sensor": "transducer", "id": "T40B-123456", "certificate": "DAkkS D-K-15070 2026-881",
        "date": str(TODAY - dt.timedelta(days=30)), "due": str(TODAY + dt.timedelta(days=335)),
        "uncertainty": "0.05 % of full scale"}
    override = meta["calibration_override"]
    assert override["reason"] == "booked for Monday" and override["operator"] == "A. Operator"
    assert override["time"].endswith("Z") and "encoder" in override["expired"][0]
    # nothing expired: no override recorded, even when a reason is given
    assert "calibration_override" not in calibration_meta(
        config.calibration, "not needed", day=TODAY - dt.timedelta(days=2))


@pytest.mark.parametrize(("table", "message"), [
    ('[calibration.transducer]\nid = "T"\ncertificate = "C"\ndate = 2026-02-01\n'
     'due = 2026-01-01\nuncertainty = 1.0\n',
     "calibration.transducer: due (2026-01-01) is before date (2026-02-01)"),
    ('[calibration.transducer]\nid = "T"\ncertificate = "C"\ndate = 2026-02-01\n'
     'due = "2027-13-01"\nuncertainty = 1.0\n',
     "calibration.transducer.due: must be an ISO date (YYYY-MM-DD)"),
    ('[calibration.transducer]\nid = "T"\ncertificate = "C"\ndate = 2026-02-01T08:00:00\n'
     'due = 2027-01-01\nuncertainty = 1.0\n',
     "calibration.transducer.date: must be a date (YYYY-MM-DD) without a time"),
    ('[calibration.transducer]\nid = "T"\ncertificate = "C"\ndate = 2026-02-01\n'
     'due = 2027-01-01\nuncertainty = true\n',
     'calibration.transducer.uncertainty: must be text ("0.05 % FS") or a number'),
    ('[calibration.transducer]\nid = 7\ncertificate = "C"\ndate = 2026-02-01\n'
     'due = 2027-01-01\nuncertainty = 1.0\n',
     "calibration.transducer.id: Input should be a valid string"),
    ('[calibration.transducer]\nid = "T"\ndate = 2026-02-01\ndue = 2027-01-01\n'
     'uncertainty = 1.0\n', "calibration.transducer.certificate: Field required"),
    ('[calibration.transducer]\nid = "T"\ncertificate = "C"\ndate = 2026-02-01\n'
     'due = 2027-01-01\nuncertainty = 1.0\nlab = "x"\n',
     "calibration.transducer.lab: Extra inputs are not permitted"),
])
def test_bad_calibration_names_file_and_key(tmp_path: Path, table: str, message: str):
    path = with_calibration(tmp_path / "rig.toml", table)
    with pytest.raises(RigConfigError) as info:
        load_rig_config(path)
    assert str(info.value).startswith(f"{path}: ")
    assert message in str(info.value)


def test_campaign_calibration_override_key():
    base = {"name": "c", "unit": {"z_internal": 45, "z_external": 40, "module_mm": 1.0},
            "plan": {"rated_torque_Nm": 10.0}}
    camp = campaign_from_mapping({**base, "calibration_override": "booked"}, "c.toml")
    assert camp.calibration_override == "booked"
    with pytest.raises(CampaignError, match="c.toml: calibration_override"):
        campaign_from_mapping({**base, "calibration_override": ""}, "c.toml")


def _cli(*args: str, cwd: Path, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", "from rig.cli import main; main()", *args],
                          capture_output=True, text=True, cwd=cwd, timeout=timeout,
                          env={**os.environ, "PYTHONPATH": str(REPO)})


def test_measure_refuses_expired_calibration_before_opening_the_rig(tmp_path: Path):
    # the example's ports are not served: refused before anything is opened
    rig = with_calibration(tmp_path / "rig.toml", VALID)
    done = _cli("measure", "--rig", str(rig), "--store", str(tmp_path / "store"), cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert "calibration of encoder" in done.stderr and "--calibration-override" in done.stderr
    assert not (tmp_path / "store" / "runs").exists() or not any(
        (tmp_path / "store" / "runs").iterdir())


def test_measure_with_override_records_it_on_the_simulated_rig(tmp_path: Path):
    sim = subprocess.Popen(
        [sys.executable, "-c", "from rig.cli import main; main()", "sim", "--rig-config",
         str(tmp_path / "sim.toml"), "--sync-period", "0.004", "--stream-rate", "250"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(REPO)})
    try:
        written = Path(json.loads(sim.stdout.readline())["rig_config"])
        rig = with_calibration(tmp_path / "rig.toml", VALID, base=written)
        done = _cli("measure", "--rig", str(rig), "--store", str(tmp_path / "store"),
                    "--steps", "1", "--operator", "B. Tester", "--serial", "SN-7",
                    "--calibration-override", "encoder checked against the reference",
                    cwd=tmp_path)
    finally:
        sim.send_signal(signal.SIGINT)
        sim.wait(timeout=30)
    assert done.returncode == 0, done.stderr
    run = Store(tmp_path / "store").list_runs()[0]
    meta = Store(tmp_path / "store").load_run(run.run_id).meta
    assert meta["operator"] == "B. Tester" and meta["unit"]["serial"] == "SN-7"
    assert {c["sensor"] for c in meta["calibration"]} == {"transducer", "encoder"}
    assert meta["calibration_override"]["reason"] == "encoder checked against the reference"
    assert meta["calibration_override"]["operator"] == "B. Tester"
    assert "unknown unit key" not in done.stderr
