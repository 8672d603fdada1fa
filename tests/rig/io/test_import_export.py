"""``rig import`` and ``rig export`` (issue 13, section 3: other labs' files).

A native run is measured once by the simulated rig (``rig measure --simulated``, a process).
From its samples the tests write, with plain pandas and npTDMS (not our exporter), a
catman-style CSV (``;``, decimal comma, angle in arcsec) and a TDMS file (torque in kN·m,
angle in rad); both import through a map and ``rig analyse`` gives the native run's lost
motion. Exports are read back with pyarrow, scipy.io and pandas.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
import scipy.io as sio
from nptdms import ChannelObject, GroupObject, TdmsWriter

import rig
from rig.runformat import read_run
from rig.store import Store
from tests.support.paths import REPO as ROOT

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

RIG = [sys.executable, "-c", "from rig.cli import main; main()"]
CATMAN_MAP = ROOT / "examples/maps/catman.toml"
EXAMPLE_CAMPAIGN = ROOT / "rig/examples/runs/campaign-pair1-positions"


def _rig(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([*RIG, *args], capture_output=True, text=True, cwd=cwd,
                          timeout=180, env=env)


def _lost_motion(run: Path, cwd: Path) -> float:
    out = cwd / f"analyse-{run.name}.json"
    res = _rig("analyse", str(run), "--json", str(out), cwd=cwd)
    assert res.returncode == 0, res.stderr[-2000:]
    return json.loads(out.read_text())["lost_motion_arcmin"]


@pytest.fixture(scope="module")
def native(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """One run measured by the simulated rig into a store: its folder, unit file and
    lost motion by ``rig analyse``."""
    work = tmp_path_factory.mktemp("native")
    res = _rig("measure", "--simulated", "--store", "S", "--rated-torque", "10",
               "--json", "out.json", cwd=work)
    assert res.returncode == 0, res.stderr[-2000:]
    run_id = json.loads((work / "out.json").read_text())["run_id"]
    folder = Store(work / "S", create=False).get_run(run_id).path
    run = read_run(folder)
    unit = work / "unit.json"
    unit.write_text(json.dumps(run.unit))
    return {"work": work, "store": work / "S", "run_id": run_id, "folder": folder,
            "run": run, "unit": unit, "lost_motion": _lost_motion(folder, work)}


def test_catman_map_is_the_issues(tmp_path: Path) -> None:
    doc = tomllib.loads(CATMAN_MAP.read_text())
    assert doc["delimiter"] == ";" and doc["decimal"] == ","
    assert doc["columns"] == {
        "t_s": "Time [s]", "torque_Nm": "Torque [N*m]",
        "output_angle_deg": {"column": "Angle [arcsec]", "unit": "arcsec"}}
    assert doc["test"]["rated_torque_Nm"] == 10.0


def _write_catman_csv(run, path: Path) -> None:
    """The run as a catman export writes it: time (s), torque (N*m), angle (arcsec), decimal
    commas, ';' between."""
    pd.DataFrame({"Time [s]": run.t_s, "Torque [N*m]": run.torque_Nm,
                  "Angle [arcsec]": run.output_angle_deg * 3600.0}
                 ).to_csv(path, sep=";", decimal=",", index=False)


def test_catman_csv_imports_to_the_native_lost_motion(native: dict, tmp_path: Path) -> None:
    run = native["run"]
    csv = tmp_path / "catman export.csv"
    _write_catman_csv(run, csv)
    assert csv.read_text().splitlines()[1].count(",") == 3  # decimal commas, ';' between
    res = _rig("import", str(csv), "--map", str(CATMAN_MAP), "--unit", str(native["unit"]),
               "--out", "imported", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    imported = read_run(tmp_path / "imported")
    assert imported.n_samples == run.n_samples
    assert imported.meta["source"]["file"] == str(csv)
    assert imported.meta["source"]["map"] == str(CATMAN_MAP)
    assert imported.unit == run.unit and imported.test == {"rated_torque_Nm": 10.0}
    np.testing.assert_allclose(imported.output_angle_deg, run.output_angle_deg,
                               rtol=1e-15, atol=0)
    lost = _lost_motion(tmp_path / "imported", tmp_path)
    assert lost == pytest.approx(native["lost_motion"], rel=1e-6)


def test_tdms_imports_to_the_native_lost_motion(native: dict, tmp_path: Path) -> None:
    run = native["run"]
    tdms = tmp_path / "bench.tdms"
    with TdmsWriter(tdms) as writer:
        writer.write_segment([
            GroupObject("Hysteresis"),
            ChannelObject("Hysteresis", "Time", run.t_s),
            ChannelObject("Hysteresis", "Torque", run.torque_Nm / 1000.0),
            ChannelObject("Hysteresis", "Output angle", np.deg2rad(run.output_angle_deg)),
            ChannelObject("Hysteresis", "Housing", run.temperature_C + 273.15),
        ])
        writer.write_segment([GroupObject("Other"),
                              ChannelObject("Other", "Noise", np.zeros(3))])
    mapping = tmp_path / "tdms.toml"
    mapping.write_text("""
group = "Hysteresis"
[columns]
t_s = "Time"
torque_Nm = { column = "Torque", unit = "kN*m" }
output_angle_deg = { column = "Output angle", unit = "rad" }
temperature_C = { column = "Housing", unit = "K" }
[test]
rated_torque_Nm = 10.0
input_angle_deg = 0.0
[sensors]
encoder_counts_per_rev = 8388608
""")
    res = _rig("import", str(tdms), "--map", str(mapping), "--unit", str(native["unit"]),
               "--out", "imported", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    imported = read_run(tmp_path / "imported")
    assert imported.meta["source"]["format"] == "tdms"
    assert imported.sensors == {"encoder_counts_per_rev": 8388608}
    np.testing.assert_allclose(imported.temperature_C, run.temperature_C, atol=1e-9)
    lost = _lost_motion(tmp_path / "imported", tmp_path)
    assert lost == pytest.approx(native["lost_motion"], rel=1e-6)


def test_import_into_a_store_is_a_finished_run(native: dict, tmp_path: Path) -> None:
    run = native["run"]
    csv = tmp_path / "catman.csv"
    _write_catman_csv(run, csv)
    res = _rig("import", str(csv), "--map", str(CATMAN_MAP), "--unit", str(native["unit"]),
               "--into", "store", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    (info,) = Store(tmp_path / "store", create=False).list_runs()
    assert info.status == "completed" and info.n_samples == run.n_samples
    assert (info.path / "samples.parquet").is_file()
    stored = read_run(info.path)
    assert stored.meta["source"]["file"] == str(csv)
    assert stored.meta["result"]["lost_motion_arcmin"] == pytest.approx(
        native["lost_motion"], rel=1e-6)


PASSWORD = "Imp0rtPW-s3cret"


@pytest.mark.parametrize("form", ["userinfo", "postgres scheme", "query"])
def test_import_into_postgresql_never_prints_the_password(native: dict, tmp_path: Path,
                                                          pg_url: str, form: str) -> None:
    """Issue 33 item 2: ``rig import --into postgresql://user:PW@...`` printed the password
    on success. The throw-away cluster trusts every connection, so the password is carried
    but not needed: the run is stored and the line names the store with ``***``."""
    rest = pg_url.removeprefix("postgresql://postgres@")
    into = {"userinfo": f"postgresql://postgres:{PASSWORD}@{rest}",
            "postgres scheme": f"postgres://postgres:{PASSWORD}@{rest}",
            "query": f"{pg_url}{'&' if '?' in pg_url else '?'}password={PASSWORD}"}[form]
    csv = tmp_path / "catman.csv"
    _write_catman_csv(native["run"], csv)
    res = _rig("import", str(csv), "--map", str(CATMAN_MAP), "--unit", str(native["unit"]),
               "--into", into, "--samples", str(tmp_path / "samples"), cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert PASSWORD not in res.stdout + res.stderr
    assert "***" in res.stdout and "-> run " in res.stdout
    (info,) = Store(pg_url, samples=tmp_path / "samples").list_runs()
    assert info.status == "completed"


def test_export_run_formats_read_back(native: dict, tmp_path: Path) -> None:
    run = native["run"]
    for fmt, out in (("csv", "run-folder"), ("parquet", "run.parquet"), ("mat", "run.mat"),
                     ("xlsx", "run.xlsx")):
        res = _rig("export", native["run_id"], "--store", str(native["store"]),
                   "--format", fmt, "--out", out, cwd=tmp_path)
        assert res.returncode == 0, res.stderr
    # issue 21 item 20: every sample export carries the twist_arcmin of .to_pandas(), last
    twist = rig.open(native["folder"]).to_pandas()["twist_arcmin"].to_numpy()
    assert abs(float(np.median(twist))) < 5.0  # centred on the loop, not the encoder's zero
    columns = [*run.columns, "twist_arcmin"]
    back = read_run(tmp_path / "run-folder")
    assert back.columns == columns and back.meta == run.meta
    for name in run.columns:  # bit for bit
        assert back.data[name].tobytes() == run.data[name].tobytes(), name
    np.testing.assert_array_equal(back.data["twist_arcmin"], twist)
    # a run that holds the column (this folder) exports it once, recomputed
    res = _rig("export", str(tmp_path / "run-folder"), "--format", "parquet", "--out",
               "again.parquet", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    again = pq.read_table(tmp_path / "again.parquet")
    assert again.column_names == columns
    np.testing.assert_array_equal(again.column("twist_arcmin").to_numpy(), twist)

    table = pq.read_table(tmp_path / "run.parquet")
    assert table.column_names == columns
    for name in run.columns:
        np.testing.assert_array_equal(table.column(name).to_numpy(), run.data[name])
    np.testing.assert_array_equal(table.column("twist_arcmin").to_numpy(), twist)
    assert json.loads(table.schema.metadata[b"run.json"]) == run.meta

    mat = sio.loadmat(tmp_path / "run.mat")
    for name in run.columns:
        np.testing.assert_array_equal(mat[name].ravel(), run.data[name])
    np.testing.assert_array_equal(mat["twist_arcmin"].ravel(), twist)
    assert json.loads(str(mat["meta_json"][0])) == run.meta
    assert [str(c[0]) for c in mat["columns"].ravel()] == columns

    sheets = pd.read_excel(tmp_path / "run.xlsx", sheet_name=None)
    assert list(sheets["samples"].columns) == columns
    for name in run.columns:  # openpyxl writes 16 significant digits ("%.16g")
        np.testing.assert_allclose(sheets["samples"][name].to_numpy(float), run.data[name],
                                   rtol=1e-15, atol=0)
    np.testing.assert_allclose(sheets["samples"]["twist_arcmin"].to_numpy(float), twist,
                               rtol=1e-15, atol=0)
    meta = dict(zip(sheets["meta"]["key"], sheets["meta"]["value"], strict=True))
    assert meta["run_id"] == run.run_id and meta["test.rated_torque_Nm"] == 10.0


def test_reimported_export_keeps_every_column_and_the_metrics(native: dict,
                                                              tmp_path: Path) -> None:
    """Issue 21 item 20: an export imported again (``rig import`` of its samples.csv) keeps
    every column (the rig's torque command, step ...; the analysis uses the command), so
    ``rig analyse`` gives the same numbers, within 1e-9 relative."""
    run = native["run"]
    res = _rig("export", native["run_id"], "--store", str(native["store"]), "--format", "csv",
               "--out", "exported", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    mapping = tmp_path / "rig-export.toml"
    mapping.write_text(f"""
[columns]
t_s = "t_s"
torque_Nm = "torque_Nm"
output_angle_deg = "output_angle_deg"
[test]
rated_torque_Nm = {run.test["rated_torque_Nm"]!r}
start_flank = {run.test["start_flank"]!r}
[sensors]
encoder_counts_per_rev = {run.sensors["encoder_counts_per_rev"]!r}
""")
    for how in (["--out", "again"], ["--into", "store"]):
        res = _rig("import", str(tmp_path / "exported" / "samples.csv"), "--map", str(mapping),
                   "--unit", str(native["unit"]), *how, cwd=tmp_path)
        assert res.returncode == 0, res.stderr
    again = read_run(tmp_path / "again")
    assert again.columns == [*run.columns, "twist_arcmin"]
    for name in run.columns:
        assert again.data[name].tobytes() == run.data[name].tobytes(), name
    before = json.loads(_analyse_text(native["folder"], tmp_path))
    (info,) = Store(tmp_path / "store", create=False).list_runs()
    stored = read_run(info.path).meta["result"]
    for after in (json.loads(_analyse_text(tmp_path / "again", tmp_path)), stored):
        for key in ("lost_motion_arcmin", "backlash_arcmin", "stiffness_Nm_per_arcmin",
                    "stiffness_loading_Nm_per_arcmin", "loop_area_J", "torque_offset_Nm"):
            if key not in after:
                continue
            if before[key] is None:
                assert after[key] is None, key
            else:
                assert after[key] == pytest.approx(before[key], rel=1e-9, abs=0), key
        for key, value in before["uncertainty"].items():
            assert after["uncertainty"][key] == pytest.approx(value, rel=1e-9, abs=0), key


def _analyse_text(run: Path, cwd: Path) -> str:
    out = cwd / f"analyse-{run.name}.json"
    res = _rig("analyse", str(run), "--json", str(out), cwd=cwd)
    assert res.returncode == 0, res.stderr[-2000:]
    return out.read_text()


def test_export_campaign_results_table(tmp_path: Path) -> None:
    analysed = tmp_path / "analyse.json"
    res = _rig("analyse", str(EXAMPLE_CAMPAIGN), "--json", str(analysed), cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    expected = {r["run_id"]: r for r in json.loads(analysed.read_text())["runs"]}
    for fmt in ("csv", "xlsx", "parquet", "mat"):
        res = _rig("export", str(EXAMPLE_CAMPAIGN), "--format", fmt, "--out",
                   f"table.{fmt}", cwd=tmp_path)
        assert res.returncode == 0, res.stderr
    frames = {"csv": pd.read_csv(tmp_path / "table.csv"),
              "xlsx": pd.read_excel(tmp_path / "table.xlsx", sheet_name="results"),
              "parquet": pq.read_table(tmp_path / "table.parquet").to_pandas()}
    for fmt, frame in frames.items():
        rel = 1e-15 if fmt == "xlsx" else 0  # openpyxl writes 16 significant digits
        assert len(frame) == 4, fmt
        assert sorted(frame["input_angle_deg"]) == [0.0, 90.0, 180.0, 270.0], fmt
        for _, row in frame.iterrows():
            want = expected[row["run_id"]]
            for column, value in (
                    ("lost_motion_arcmin", want["lost_motion_arcmin"]),
                    ("lost_motion_arcmin_u", want["uncertainty"]["lost_motion_arcmin"]),
                    ("model_lost_motion_arcmin", want["model"]["lost_motion_arcmin"])):
                assert row[column] == pytest.approx(value, rel=rel, abs=0), (fmt, column)
        assert {"label", "amplitude_pct", "temperature_C", "backlash_arcmin_u",
                "stiffness_Nm_per_arcmin", "outcome"} <= set(frame.columns), fmt
    mat = sio.loadmat(tmp_path / "table.mat")
    np.testing.assert_array_equal(mat["lost_motion_arcmin"].ravel(),
                                  frames["csv"]["lost_motion_arcmin"].to_numpy())
    # issue 21 item 20: the table's run_id keeps its name (no run_id_2)
    assert "run_id_2" not in mat
    assert [str(c[0]) for c in mat["run_id"].ravel()] == list(frames["csv"]["run_id"])
    assert [str(c[0]) for c in mat["variables"].ravel()] == list(frames["csv"].columns)


def _one_line_error(res: subprocess.CompletedProcess) -> str:
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    return lines[0]


@pytest.mark.parametrize(("change", "named"), [
    (("rated_torque_Nm", "rated_torqe_Nm"), ["bad.toml", "test", "rated_torqe_Nm",
                                              "rated_torque_Nm"]),
    (('unit = "arcsec"', 'unit = "arcsecs"'), ["bad.toml", "columns.output_angle_deg",
                                                "'arcsecs'", "arcmin"]),
    (("decimal", "decimal_mark"), ["bad.toml", "decimal_mark"]),
    (("Angle [arcsec]", "Angle [arcmin]"), ["data.csv", "'Angle [arcmin]'", "output_angle_deg",
                                            "'Angle [arcsec]'"]),
])
def test_bad_map_is_one_line_naming_file_and_key(tmp_path: Path, change: tuple[str, str],
                                                 named: list[str]) -> None:
    (tmp_path / "data.csv").write_text(
        "Time [s];Torque [N*m];Angle [arcsec]\n0,0;1,5;3600,0\n0,1;2,5;3601,0\n")
    (tmp_path / "unit.json").write_text((ROOT / "rig/examples/units/seed000-pair1.json")
                                        .read_text())
    (tmp_path / "bad.toml").write_text(CATMAN_MAP.read_text().replace(*change))
    line = _one_line_error(_rig("import", "data.csv", "--map", "bad.toml", "--unit",
                                "unit.json", "--out", "x", cwd=tmp_path))
    for word in named:
        assert word in line, line
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(("row", "named"), [
    ("0,1;2,x;3601,0", "data.csv:3:2: column 'Torque [N*m]'"),
    ("0,1;2.5;3601,0", "data.csv:3:2: column 'Torque [N*m]'"),
    ("0,0;2,5;3601,0", "data.csv:3:1: column 'Time [s]'"),
    ("0,1;;3601,0", "data.csv:3:2: column 'Torque [N*m]'"),
])
def test_bad_value_names_file_line_and_column(tmp_path: Path, row: str, named: str) -> None:
    (tmp_path / "data.csv").write_text(
        f"Time [s];Torque [N*m];Angle [arcsec]\n0,0;1,5;3600,0\n{row}\n")
    (tmp_path / "unit.json").write_text((ROOT / "rig/examples/units/seed000-pair1.json")
                                        .read_text())
    line = _one_line_error(_rig("import", "data.csv", "--map", str(CATMAN_MAP), "--unit",
                                "unit.json", "--out", "x", cwd=tmp_path))
    assert named in line, line


def test_tdms_time_from_waveform_timing(tmp_path: Path) -> None:
    """No t_s channel: the time is the torque channel's waveform timing; a missing channel
    is one line listing the group's channels."""
    n, dt = 200, 0.002
    torque = 10.0 * np.sin(np.linspace(0.0, 2.0 * np.pi, n))
    wf = {"wf_increment": dt, "wf_start_offset": 0.5}
    with TdmsWriter(tmp_path / "wave.tdms") as writer:
        writer.write_segment([
            ChannelObject("G", "Torque", torque, properties=wf),
            ChannelObject("G", "Angle", np.full(n, 30.0), properties=wf),
        ])
    (tmp_path / "unit.json").write_text((ROOT / "rig/examples/units/seed000-pair1.json")
                                        .read_text())
    mapping = tmp_path / "wave.toml"
    mapping.write_text('[columns]\ntorque_Nm = "Torque"\n'
                       'output_angle_deg = { column = "Angle", unit = "arcmin" }\n'
                       '[test]\nrated_torque_Nm = 10.0\n')
    res = _rig("import", "wave.tdms", "--map", "wave.toml", "--unit", "unit.json",
               "--out", "run", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    run = read_run(tmp_path / "run")
    np.testing.assert_allclose(run.t_s, 0.5 + dt * np.arange(n), rtol=1e-12)
    np.testing.assert_array_equal(run.output_angle_deg, np.full(n, 0.5))
    mapping.write_text(mapping.read_text().replace('"Angle"', '"Angel"'))
    line = _one_line_error(_rig("import", "wave.tdms", "--map", "wave.toml", "--unit",
                                "unit.json", "--out", "run2", cwd=tmp_path))
    assert "wave.tdms" in line and "'Angel'" in line and "['Torque', 'Angle']" in line, line
