"""Issue 21 items 2 and 8: run ids are names wherever they enter, ``rig export`` and
``rig import --out`` never write into a store or a run folder and write all or nothing, and
``rig import`` refuses wrong numbers in one line.

Files are written with pandas and npTDMS from the shipped example run
(rig/examples/runs/pair1-pos000), not by the code under test. Failed writes are real: the
``rig export`` process runs under a file size limit (``RLIMIT_FSIZE``, what a full disk does
to a write part-way) or into a read-only folder (as root, without the capability that lets
root ignore permissions).
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from nptdms import ChannelObject, TdmsWriter

import rig
from rig.core.errors import RigError, RunFormatError
from rig.core.ids import id_problem
from rig.io import read as io_read
from rig.io.exporter import export_run
from rig.io.importer import import_run, store_imported, write_imported
from rig.io.safe_write import WriteTargetError
from rig.runformat import read_run, runs_equal, write_run
from rig.store import InvalidIdError, Store
from tests.support.paths import REPO as ROOT
from tests.support.readonly import drop_dac_capabilities

EXAMPLE_RUN = ROOT / "rig/examples/runs/pair1-pos000"
UNIT = ROOT / "rig/examples/units/seed000-pair1.json"
CATMAN_MAP = ROOT / "examples/maps/catman.toml"
BAD_IDS = ["..", "a/b", "a\x00b", "a\nb", "../../../../outside/x"]
FORMATS = ("csv", "parquet", "mat", "xlsx")


def _rig(*args: str, cwd: Path, preexec=None) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONDONTWRITEBYTECODE": "1"}
    return subprocess.run([sys.executable, "-m", "rig", *args], capture_output=True,
                          text=True, cwd=cwd, timeout=300, env=env, preexec_fn=preexec)


def _one_line_error(res: subprocess.CompletedProcess) -> str:
    assert res.returncode == 2, (res.stdout, res.stderr)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rig: error:"), res.stderr
    assert "Traceback" not in res.stderr and "internal error" not in res.stderr
    return lines[0]


def _catman(tmp: Path, name: str = "data.csv") -> Path:
    run = read_run(EXAMPLE_RUN)
    path = tmp / name
    pd.DataFrame({"Time [s]": run.t_s, "Torque [N*m]": run.torque_Nm,
                  "Angle [arcsec]": run.output_angle_deg * 3600.0}
                 ).to_csv(path, sep=";", decimal=",", index=False)
    return path


def _store_with_run(tmp: Path) -> tuple[Store, str, Path]:
    """A store holding the example run (as `rig import --into` puts it)."""
    run = import_run(_catman(tmp), CATMAN_MAP, UNIT)
    run_id = store_imported(run, tmp / "rig-store")
    st = Store(tmp / "rig-store", create=False)
    return st, run_id, st.get_run(run_id).path


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


# ----------------------------------------------------------------------- item 2: run ids


def test_one_rule_one_message_for_every_entry(tmp_path: Path) -> None:
    """The store, the Python API, run.json on read and import give the same reason."""
    st, _run_id, _ = _store_with_run(tmp_path)
    for bad in BAD_IDS:
        reason = id_problem(bad)
        assert reason is not None and repr(bad)[:20] in reason and "ASCII letters" in reason
        with pytest.raises(InvalidIdError) as err:
            st.get_run(bad)
        assert str(err.value) == reason
        with pytest.raises(InvalidIdError) as err:
            rig.open(bad, store=st)
        assert str(err.value) == reason
        with pytest.raises(RigError) as err:
            import_run(_catman(tmp_path), CATMAN_MAP, UNIT, run_id=bad)
        assert str(err.value) == f"--run-id: {reason}"
        assert "\n" not in str(err.value)


@pytest.mark.parametrize("bad", BAD_IDS)
def test_run_json_with_a_path_as_run_id_is_refused_on_read(tmp_path: Path, bad: str) -> None:
    folder = tmp_path / "run"
    shutil.copytree(EXAMPLE_RUN, folder)
    doc = json.loads((folder / "run.json").read_text())
    doc["run_id"] = bad
    (folder / "run.json").write_text(json.dumps(doc, indent=2))
    with pytest.raises(RunFormatError) as err:
        read_run(folder)
    assert err.value.path == str(folder / "run.json")
    assert err.value.line == 3 and err.value.column is not None
    assert "invalid run id" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("bad", BAD_IDS)
def test_map_run_id_must_be_a_name(tmp_path: Path, bad: str) -> None:
    toml = json.dumps(bad)  # a JSON string is a TOML basic string (\u0000, \n escaped)
    mapping = tmp_path / "map.toml"
    mapping.write_text(f"run_id = {toml}\n" + CATMAN_MAP.read_text())
    with pytest.raises(RigError) as err:
        import_run(_catman(tmp_path), mapping, UNIT)
    message = str(err.value)
    assert message.startswith(f"{mapping}: run_id: invalid run id"), message
    assert "\n" not in message


def test_run_id_naming_a_stored_run_cannot_overwrite_it(tmp_path: Path) -> None:
    """The issue's attack: --run-id "rig-store/runs/<id>" then `rig export RUN --format csv`
    overwrote the stored run.json. Now the import is refused, and so is an export into the
    store, even with --force, and even through a run.json edited to carry that id."""
    st, run_id, stored = _store_with_run(tmp_path)
    before = _snapshot(stored)
    path_id = f"rig-store/runs/{run_id}"
    line = _one_line_error(_rig("import", "data.csv", "--map", str(CATMAN_MAP), "--unit",
                                str(UNIT), "--run-id", path_id, "--out", "x", cwd=tmp_path))
    assert "--run-id: invalid run id" in line and "slash" in line
    exported = export_run(st.load_run(run_id), "csv", tmp_path / "exported")
    doc = json.loads((exported / "run.json").read_text())
    doc["run_id"] = path_id
    (exported / "run.json").write_text(json.dumps(doc))
    line = _one_line_error(_rig("export", "exported", "--format", "csv", cwd=tmp_path))
    assert "invalid run id" in line and "run.json" in line
    run = st.load_run(run_id)
    for fmt, out in (("csv", stored), ("parquet", stored / "samples.parquet"),
                     ("xlsx", tmp_path / "rig-store/x.xlsx"), ("mat", stored.parent / "y.mat")):
        with pytest.raises(WriteTargetError) as err:
            export_run(run, fmt, out, force=True)
        assert "inside a measurement store" in str(err.value) or \
            "inside a run folder" in str(err.value), str(err.value)
    assert _snapshot(stored) == before
    assert runs_equal(st.load_run(run_id), read_run(stored))
    assert not (tmp_path / "rig-store/x.xlsx").exists()


def test_export_refuses_existing_targets_and_symlinks_without_force(tmp_path: Path,
                                                                   monkeypatch) -> None:
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    (tmp_path / "link.parquet").symlink_to(victim)
    (tmp_path / "old.mat").write_text("old")
    line = _one_line_error(_rig("export", str(EXAMPLE_RUN), "--format", "parquet", "--out",
                                "link.parquet", cwd=tmp_path))
    assert "link.parquet: is a symlink" in line and "--force" in line, line
    run = read_run(EXAMPLE_RUN)
    with pytest.raises(WriteTargetError, match="old.mat: exists; --force replaces it"):
        export_run(run, "mat", tmp_path / "old.mat")
    assert victim.read_text() == "keep me" and (tmp_path / "old.mat").read_text() == "old"
    export_run(run, "parquet", tmp_path / "link.parquet", force=True)
    assert victim.read_text() == "keep me"  # the link was replaced, not what it points to
    assert not (tmp_path / "link.parquet").is_symlink()
    # a run folder rig did not write is never replaced, even with --force
    other = tmp_path / "other-lab-run"
    shutil.copytree(EXAMPLE_RUN, other)
    with pytest.raises(WriteTargetError, match="did not write"):
        export_run(run, "csv", other, force=True)
    assert _snapshot(other) == _snapshot(EXAMPLE_RUN)
    # one rig wrote is (the default target: ./RUN_ID)
    monkeypatch.chdir(tmp_path)
    assert export_run(run, "csv") == Path("pair1-pos000")
    with pytest.raises(WriteTargetError, match="exists"):
        export_run(run, "csv")
    export_run(run, "csv", force=True)
    back = read_run(tmp_path / "pair1-pos000")
    # every original column bit for bit; the export adds the loop-centred twist_arcmin last
    assert back.meta == run.meta and back.columns == [*run.columns, "twist_arcmin"]
    assert all(back.data[c].tobytes() == run.data[c].tobytes() for c in run.columns)


# ----------------------------------------------------------- item 2: failed writes, for real

def _file_size_limit(limit: int):
    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


@pytest.mark.parametrize("fmt", FORMATS)
def test_a_failed_export_leaves_the_old_file_and_no_partial_file(tmp_path: Path,
                                                                 fmt: str) -> None:
    out = tmp_path / "out"
    out.mkdir()
    target = "run" if fmt == "csv" else f"run.{fmt}"
    res = _rig("export", str(EXAMPLE_RUN), "--format", fmt, "--out", target, cwd=out)
    assert res.returncode == 0, res.stderr
    written = out / target
    size = sum(p.stat().st_size for p in written.rglob("*")) if fmt == "csv" else \
        written.stat().st_size
    before = _snapshot(out)
    inode = written.stat().st_ino
    limit = max(size // 2, 4096)
    for preexec, why in ((_file_size_limit(limit), "File too large"),
                         (drop_dac_capabilities, "Permission denied")):
        if why == "Permission denied":
            out.chmod(0o555)
        try:
            res = _rig("export", str(EXAMPLE_RUN), "--format", fmt, "--out", target,
                       "--force", cwd=out, preexec=preexec)
        finally:
            out.chmod(0o755)
        line = _one_line_error(res)
        assert why in line and "left as it was" in line and target in line, line
        assert "Exception ignored" not in res.stderr
        assert _snapshot(out) == before  # the old file intact, no partial or temporary file
        assert written.stat().st_ino == inode


# ------------------------------------------------------------------ item 8: wrong numbers


def _rows(n: int = 40) -> list[list[str]]:
    return [[f"{i / 100:.2f}", f"{10 * np.sin(i / 5):.4f}", f"{3600 + i % 7}"]
            for i in range(n)]


def _write_csv(tmp: Path, rows: list[list[str]], header: list[str] | None = None,
               name: str = "d.csv") -> Path:
    header = header or ["Time [s]", "Torque [N*m]", "Angle [arcsec]"]
    path = tmp / name
    path.write_text(";".join(header) + "\n" + "".join(
        ";".join(c.replace(".", ",") for c in r) + "\n" for r in rows))
    return path


def _map(tmp: Path, edit=lambda s: s, name: str = "m.toml") -> Path:
    path = tmp / name
    path.write_text(edit(CATMAN_MAP.read_text()))
    return path


def _refused(source: Path, mapping: Path, *words: str) -> str:
    with pytest.raises(RigError) as err:
        import_run(source, mapping, UNIT)
    message = str(err.value)
    assert "\n" not in message
    for word in words:
        assert word in message, message
    return message


def test_tdms_unit_string_is_used_and_a_conflict_refused(tmp_path: Path) -> None:
    run = read_run(EXAMPLE_RUN)
    tdms = tmp_path / "bench.tdms"
    with TdmsWriter(tdms) as writer:
        writer.write_segment([
            ChannelObject("G", "Time", run.t_s, properties={"unit_string": "s"}),
            ChannelObject("G", "Torque", run.torque_Nm / 1000.0,
                          properties={"unit_string": "kN*m"}),
            ChannelObject("G", "Angle", run.output_angle_deg,
                          properties={"unit_string": "deg"}),
        ])
    mapping = tmp_path / "t.toml"
    mapping.write_text('[columns]\nt_s = "Time"\ntorque_Nm = "Torque"\n'
                       'output_angle_deg = "Angle"\n[test]\nrated_torque_Nm = 10.0\n')
    imported = import_run(tdms, mapping, UNIT)
    np.testing.assert_allclose(imported.torque_Nm, run.torque_Nm, rtol=1e-12, atol=1e-15)
    mapping.write_text(mapping.read_text().replace(
        'torque_Nm = "Torque"', 'torque_Nm = { column = "Torque", unit = "N*m" }'))
    _refused(tdms, mapping, "bench.tdms", "channel 'Torque'", "'N*m'", "'kN*m'")
    mapping.write_text(mapping.read_text().replace('unit = "N*m"', 'unit = "kNm"'))
    np.testing.assert_allclose(import_run(tdms, mapping, UNIT).torque_Nm, run.torque_Nm,
                               rtol=1e-12, atol=1e-15)


def test_catman_header_unit_is_used_and_a_conflict_refused(tmp_path: Path) -> None:
    header = ["Time [s]", "Torque [kN*m]", "Angle [arcsec]"]
    source = _write_csv(tmp_path, _rows(), header)
    mapping = _map(tmp_path, lambda s: s.replace("Torque [N*m]", "Torque [kN*m]"))
    run = import_run(source, mapping, UNIT)
    np.testing.assert_allclose(run.torque_Nm, [1000 * float(r[1]) for r in _rows()])
    conflict = _map(tmp_path, lambda s: s.replace(
        'torque_Nm = "Torque [N*m]"', 'torque_Nm = { column = "Torque [kN*m]", unit = "Nm" }'))
    _refused(source, conflict, "d.csv:1:2", "'Nm'", "'kN*m'")


def _set_column(rows: list[list[str]], k: int, index: int, value: str) -> list[list[str]]:
    rows = [list(r) for r in rows]
    rows[index][k] = value
    return rows


def _with_temperature_column(tmp_path: Path, index: int, value: str) -> tuple[Path, Path]:
    """The data with a temperature column 'T' (``value`` in row ``index``, 20 elsewhere) and
    the map that reads it as temperature_C."""
    rows = [r + [value if i == index else "20"] for i, r in enumerate(_rows())]
    return (_write_csv(tmp_path, rows, ["Time [s]", "Torque [N*m]", "Angle [arcsec]", "T"]),
            _map(tmp_path, lambda s: s.replace("[columns]", '[columns]\ntemperature_C = "T"')))


CASES = {
    "torque and angle on one column": (
        lambda t: (_write_csv(t, _rows()), _map(t, lambda s: s.replace(
            '{ column = "Angle [arcsec]", unit = "arcsec" }', '"Torque [N*m]"'))),
        ["m.toml", "columns", "torque_Nm and output_angle_deg", "'Torque [N*m]'"]),
    "temperature inf": (
        lambda t: _with_temperature_column(t, 5, "inf"),
        ["d.csv:7:4", "'T' (temperature_C)", "inf"]),
    "temperature -653 C": (
        lambda t: _with_temperature_column(t, 9, "-653"),
        ["d.csv:11:4", "-653.0 °C", "-273.15"]),
    "test temperature -653 C": (
        lambda t: (_write_csv(t, _rows()), _map(t, lambda s: s + "temperature_C = -653.0\n")),
        ["m.toml", "test.temperature_C", "-273.15"]),
    "time steps of 1e-300 s": (
        lambda t: (_write_csv(t, [[f"{i}e-300", r[1], r[2]] for i, r in enumerate(_rows())]),
                   _map(t)),
        ["d.csv:3:1", "column 'Time [s]'", "1e-300 s"]),
    "rated torque 1e308": (
        lambda t: (_write_csv(t, _rows()), _map(t, lambda s: s.replace(
            "rated_torque_Nm = 10.0", "rated_torque_Nm = 1e308"))),
        ["m.toml", "test.rated_torque_Nm", "1e+308"]),
    # issue 33 item 5: every reading in its physical range (rig/core/ranges.py)
    "torque 1e31 N*m (rated 10)": (
        lambda t: (_write_csv(t, _set_column(_rows(), 1, 5, "1e31")), _map(t)),
        ["d.csv:7:2", "column 'Torque [N*m]'", "torque_Nm 1e+31 is no reading", "from -10000 "
         "to 10000 N·m (at most 1000 x the rated 10 N·m in magnitude)"]),
    "angle 1e300 arcsec": (
        lambda t: (_write_csv(t, _set_column(_rows(), 2, 3, "1e300")), _map(t)),
        ["d.csv:5:3", "column 'Angle [arcsec]'", "output_angle_deg 2.77", "e+296 is no reading",
         "from -1e+09 to 1e+09 deg"]),
    "temperature -200 C": (
        lambda t: _with_temperature_column(t, 9, "-200"),
        ["d.csv:11:4", "temperature_C -200.0 is no reading", "from -100 to 300 °C"]),
    "test input angle 1e300": (
        lambda t: (_write_csv(t, _rows()), _map(t, lambda s: s + "input_angle_deg = 1e300\n")),
        ["m.toml", "test.input_angle_deg: expected from -3600 to 3600 deg (got 1e+300)"]),
    "test temperature 1e6 C": (
        lambda t: (_write_csv(t, _rows()), _map(t, lambda s: s + "temperature_C = 1e6\n")),
        ["m.toml", "test.temperature_C: expected from -100 to 300 °C (got 1000000.0)"]),
    "a single sample": (lambda t: (_write_csv(t, _rows(1)), _map(t)),
                        ["d.csv", "1 sample", "at least"]),
    "all-zero torque": (
        lambda t: (_write_csv(t, [[r[0], "0.0", r[2]] for r in _rows()]), _map(t)),
        ["d.csv", "column 'Torque [N*m]'", "0 N·m in all 40 samples"]),
    "header only": (lambda t: (_write_csv(t, []), _map(t)), ["d.csv", "no samples"]),
    "utf-16 map, utf-8 file": (
        lambda t: (_write_csv(t, _rows()), _map(t, lambda s: s.replace(
            'decimal = ","', 'decimal = ","\nencoding = "utf-16"'))),
        ["d.csv", "not utf-16 text", "encoding"]),
    "csv map without t_s": (
        lambda t: (_write_csv(t, _rows()), _map(t, lambda s: s.replace('t_s = "Time [s]"\n',
                                                                        ""))),
        ["m.toml", "columns.t_s"]),
}


@pytest.mark.parametrize("case", list(CASES))
def test_wrong_numbers_are_refused_in_one_line(tmp_path: Path, case: str) -> None:
    make, words = CASES[case]
    source, mapping = make(tmp_path)
    _refused(source, mapping, *words)


@pytest.mark.parametrize("case", ["header only", "utf-16 map, utf-8 file",
                                  "csv map without t_s"])
def test_former_internal_errors_are_one_line_from_the_cli(tmp_path: Path, case: str) -> None:
    source, mapping = CASES[case][0](tmp_path)
    line = _one_line_error(_rig("import", str(source), "--map", str(mapping), "--unit",
                                str(UNIT), "--out", "x", cwd=tmp_path))
    assert all(word in line for word in CASES[case][1]), line
    assert not (tmp_path / "x").exists()


def test_streamed_reading_keeps_values_and_lines_across_blocks(tmp_path: Path,
                                                               monkeypatch) -> None:
    """The file is parsed in blocks (pyarrow.csv.open_csv): with 1 kB blocks the values are
    those of one whole read, and a bad cell far down names its own line."""
    monkeypatch.setattr(io_read, "BLOCK_BYTES", 1024)
    source = _catman(tmp_path)
    whole = import_run(source, CATMAN_MAP, UNIT)
    run = read_run(EXAMPLE_RUN)
    assert whole.n_samples == run.n_samples > 1000
    np.testing.assert_allclose(whole.output_angle_deg, run.output_angle_deg, rtol=1e-15)
    lines = source.read_text().splitlines(keepends=True)
    lines[2001] = lines[2001].replace(";", ";x", 1)
    source.write_text("".join(lines))
    _refused(source, CATMAN_MAP, "data.csv:2002:2", "column 'Torque [N*m]'", "not a number")


def test_import_out_is_all_or_nothing_and_not_over_a_run(tmp_path: Path) -> None:
    source = _catman(tmp_path)
    args = ["import", str(source), "--map", str(CATMAN_MAP), "--unit", str(UNIT), "--out"]
    assert _rig(*args, "run", cwd=tmp_path).returncode == 0
    run = read_run(tmp_path / "run")
    write_run(run, tmp_path / "plain")  # the same run, written by write_run: same bytes
    assert (tmp_path / "plain/samples.csv").read_bytes() == \
        (tmp_path / "run/samples.csv").read_bytes()
    line = _one_line_error(_rig(*args, "run", cwd=tmp_path))
    assert "exists; --force" in line
    imported = import_run(source, CATMAN_MAP, UNIT)
    write_imported(imported, tmp_path / "run", force=True)
    with pytest.raises(WriteTargetError, match="did not write"):
        write_imported(imported, tmp_path / "plain", force=True)


def test_a_torque_of_1e31_is_not_stored_as_a_completed_run(tmp_path: Path) -> None:
    """Issue 33 item 5: ``rig import --into`` stored it as completed / NO LIMITS with no
    reason (and it got a certificate) while ``rig analyse`` refused the same run: now the
    import refuses it in one line naming file, line and column, and the store stays empty."""
    source, mapping = CASES["torque 1e31 N*m (rated 10)"][0](tmp_path)
    line = _one_line_error(_rig("import", str(source), "--map", str(mapping), "--unit",
                                str(UNIT), "--into", str(tmp_path / "st"), cwd=tmp_path))
    assert f"{source}:7:2: column 'Torque [N*m]' (torque_Nm): torque_Nm 1e+31 is no " \
        "reading" in line, line
    runs = tmp_path / "st" / "runs"
    assert not runs.exists() or not any(runs.iterdir())
