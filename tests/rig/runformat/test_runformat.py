"""The rig-run/1 reader/writer: round-trips, clear errors, campaigns, bare CSV, appender."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rig.core.errors import RunFormatError
from rig.runformat import (
    Campaign,
    Run,
    SamplesAppender,
    is_campaign,
    read_campaign,
    read_run,
    read_run_or_campaign,
    runs_equal,
    write_campaign,
    write_run,
)
from tests.support.paths import REPO

HEADER = "t_s,torque_Nm,output_angle_deg"


def bits(a: np.ndarray) -> np.ndarray:
    return np.asarray(a, dtype=np.float64).view(np.uint64)


def small_run(run_id: str = "pair1-pos000", n: int = 5, **kw) -> Run:
    t = np.arange(n) * 0.01
    return Run.from_arrays(run_id, t, np.sin(t) * 10.0, t * 1e-3, **kw)


def write_folder(folder: Path, csv_text: str | bytes, meta: dict | str | None = None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    if meta is None:
        meta = {"format": "rig-run/1", "run_id": folder.name}
    text = meta if isinstance(meta, str) else json.dumps(meta, indent=2)
    (folder / "run.json").write_text(text, encoding="utf-8")
    data = csv_text.encode() if isinstance(csv_text, str) else csv_text
    (folder / "samples.csv").write_bytes(data)
    return folder


def expect_error(path: Path, line: int | None, column: int | None) -> RunFormatError:
    """Read the run and check the error names the file, line and column."""
    with pytest.raises(RunFormatError) as info:
        read_run(path.parent if path.name in ("samples.csv", "run.json") else path)
    err = info.value
    assert err.path == str(path)
    assert (err.line, err.column) == (line, column), str(err)
    where = str(path) + (f":{line}" if line else "") + (f":{column}" if column else "")
    assert str(err).startswith(where + ": "), str(err)
    return err


# ----------------------------------------------------------------------------- round trip


SPECIAL = [
    0.1 + 0.2,
    1e-300,
    5e-324,
    -0.0,
    1.7976931348623157e308,
    -123456789.12345679,
    1 / 3,
    2.2250738585072014e-308,
    4.4e-5,
    6.02214076e23,
]


def _hard_floats(rng: np.random.Generator, n: int) -> np.ndarray:
    """:data:`SPECIAL`, then normal draws scaled by 10 to a power drawn in [-300, 300]."""
    return np.concatenate([SPECIAL, rng.standard_normal(n - len(SPECIAL)) * 10.0 ** rng.uniform(
        -300, 300, n - len(SPECIAL))])


def _hard_samples(rng: np.random.Generator, n: int, nan_rows: list[int]
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times, :func:`_hard_floats` and temperatures with NaN at ``nan_rows``, drawn in the
    order hard floats, temperatures, time steps."""
    hard = _hard_floats(rng, n)
    temperature = 20.0 + rng.standard_normal(n)
    temperature[nan_rows] = np.nan
    return np.cumsum(rng.uniform(1e-9, 1.0, n)), hard, temperature


def test_round_trip_is_bit_exact_for_hard_floats(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    n = 400
    t_s, hard, temperature = _hard_samples(rng, n, [3, 50, n - 1])
    run = Run.from_arrays(
        "hard",
        t_s,
        hard,
        hard[::-1].copy(),
        input_angle_deg=rng.standard_normal(n) * 1e6,
        temperature_C=temperature,
        unit={"kind": "internal_involute", "m_value_internal_mm": [42.485, 42.481]},
    )
    back = read_run(write_run(run, tmp_path / "r"))
    assert runs_equal(run, back)
    assert np.array_equal(bits(back.torque_Nm), bits(hard))
    assert np.signbit(back.torque_Nm[3])  # -0.0 survives
    assert np.isnan(back.temperature_C[[3, 50, n - 1]]).all()
    assert back.notes == []
    first = (tmp_path / "r" / "samples.csv").read_bytes()
    write_run(back, tmp_path / "again")
    assert (tmp_path / "again" / "samples.csv").read_bytes() == first


def test_numbers_are_written_shortest_exact_and_missing_is_empty(tmp_path: Path) -> None:
    run = Run.from_arrays(
        "fmt", [0.0, 1.0], [0.1 + 0.2, 1 / 3], [1e-300, 123.456789012345],
        temperature_C=[np.nan, 20],
    )
    text = (write_run(run, tmp_path / "r") / "samples.csv").read_text()
    assert text == (
        "t_s,torque_Nm,output_angle_deg,temperature_C\n"
        "0.0,0.30000000000000004,1e-300,\n"
        "1.0,0.3333333333333333,123.456789012345,20.0\n"
    )
    # 1/3 needs every digit: at least the 10 significant digits the spec asks for
    assert len("3333333333333333") >= 10


def test_unknown_columns_text_columns_and_keys_are_kept(tmp_path: Path) -> None:
    meta = {
        "format": "rig-run/1",
        "run_id": "lab-B-17",
        "started_at": "2026-11-21T10:00:00Z",
        "operator": {"name": "Wang", "shift": ["early", {"badge": 17}]},
        "unit": {"kind": "cycloid", "lobes": 39, "vendor": {"lot": "A-3", "ppm": 1.25}},
        "test": {"rated_torque_Nm": 10.0, "cycles": 2, "future_key": None},
        "sensors": {"encoder_counts_per_rev": 8388608, "calibrated": True},
    }
    csv_text = (
        "t_s,strain_ue,torque_Nm,label,output_angle_deg,input_angle_deg\n"
        '0.0,1.50,-1.0,"start, preload",0.25,\n'
        '0.5,,0.0,"he said ""ok""",0.2500001,12.0\n'
        "1.0,3e2,1.0,温度 stable,0.26,12.0\n"
        '1.5,-4,2.0,"two\nlines",0.27,12.5\n'
        "2.0,5,3.0,,0.28,13\n"
    )
    folder = write_folder(tmp_path / "lab", csv_text, meta)
    run = read_run(folder)
    assert run.meta == meta
    assert list(run.meta) == list(meta)
    assert run.columns == [
        "t_s", "strain_ue", "torque_Nm", "label", "output_angle_deg", "input_angle_deg"
    ]
    assert run.data["label"] == ["start, preload", 'he said "ok"', "温度 stable", "two\nlines", ""]
    assert np.array_equal(run.data["strain_ue"], [1.5, np.nan, 300.0, -4.0, 5.0], equal_nan=True)
    assert run.unit["vendor"]["lot"] == "A-3"
    assert run.test["future_key"] is None
    assert run.sensors["calibrated"] is True
    assert run.temperature_C is None
    assert np.isnan(run.input_angle_deg[0])
    back = read_run(write_run(run, tmp_path / "copy"))
    assert runs_equal(run, back)
    assert json.loads((tmp_path / "copy" / "run.json").read_text()) == meta


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    st.lists(
        st.tuples(
            st.floats(allow_nan=False, allow_infinity=False),
            st.floats(allow_nan=False, allow_infinity=False),
            st.floats(allow_infinity=False),
            st.text(alphabet=st.characters(codec="utf-8", exclude_categories=["Cs"]), max_size=8),
        ),
        min_size=1,
        max_size=30,
    )
)
def test_round_trip_property(rows: list[tuple[float, float, float, str]]) -> None:
    n = len(rows)
    torque, angle, temp, label = (list(c) for c in zip(*rows, strict=True))
    label[-1] = "not a number"  # one text that is no number keeps the column a text column
    run = Run.from_arrays(
        "prop", np.arange(n) * 0.5, torque, angle, temperature_C=temp,
        extra_columns={"label": label},
    )
    with tempfile.TemporaryDirectory() as d:
        back = read_run(write_run(run, Path(d) / "r"))
    assert runs_equal(run, back)


# ----------------------------------------------------------------------------- samples errors


CSV_ERRORS = [
    # (name, csv text, line, column, words the message must hold)
    ("too few fields", f"{HEADER}\n0,1,2\n1,2\n", 3, 3, ["output_angle_deg", "field 3 missing"]),
    ("too many fields", f"{HEADER}\n0,1,2\n1,2,3,4\n", 3, 4, ["4 fields", "unexpected"]),
    ("bad number", f"{HEADER}\n0,1,2\n1,1.2.3,2\n2,0,0\n", 3, 2, ["torque_Nm", "'1.2.3'"]),
    ("bad number late column", f"{HEADER},input_angle_deg\n0,1,2,x9\n", 2, 4,
     ["input_angle_deg", "'x9'"]),
    ("empty torque", f"{HEADER}\n0,1,2\n1,,2\n", 3, 2, ["torque_Nm", "empty value"]),
    ("nan torque", f"{HEADER}\n0,1,2\n1,NaN,2\n2,1,2\n", 3, 2, ["torque_Nm", "NaN"]),
    ("empty angle", f"{HEADER}\n0,1,2\n1,1,\n", 3, 3, ["output_angle_deg", "empty value"]),
    ("empty time", f"{HEADER}\n0,1,2\n,1,2\n", 3, 1, ["t_s", "empty value"]),
    ("infinite torque", f"{HEADER}\n0,inf,2\n", 2, 2, ["torque_Nm", "non-finite"]),
    ("time repeats", f"{HEADER}\n0,1,2\n0.5,1,2\n0.5,1,2\n", 4, 1,
     ["t_s", "strictly ascending", "on line 3"]),
    ("time goes back", f"{HEADER}\n0,1,2\n0.5,1,2\n0.75,1,2\n0.25,1,2\n", 5, 1,
     ["0.25 after 0.75", "on line 4"]),
    ("blank line inside", f"{HEADER}\n0,1,2\n\n1,1,2\n", 3, None, ["blank line"]),
    ("duplicate column", f"{HEADER},torque_Nm\n0,1,2,3\n", 1, 4, ["'torque_Nm'", "twice"]),
    ("empty column name", f"{HEADER},\n0,1,2,3\n", 1, 4, ["empty name"]),
    ("case of a required name", "t_s,Torque_Nm,output_angle_deg\n0,1,2\n", 1, 2,
     ["'torque_Nm' is missing", "did you mean column 2 'Torque_Nm'"]),
    ("required column absent", "t_s,output_angle_deg\n0,1\n", 1, None,
     ["'torque_Nm' is missing", "['t_s', 'output_angle_deg']"]),
    ("empty file", "", 1, None, ["no header"]),
    ("semicolons", "t_s;torque_Nm;output_angle_deg\n0;1,5;2\n", 1, 1, ["semicolon-separated"]),
    # quoted fields take the csv-module path: line numbers still count physical lines
    ("quoted, bad number", f'{HEADER},note\n0,1,2,"two\nlines"\n1,x,3,a\n', 4, 2,
     ["torque_Nm", "'x'"]),
    ("quoted, nan torque", f'{HEADER},note\n0,1,2,"a"\n1,nan,3,"b"\n', 3, 2,
     ["torque_Nm", "'nan' (NaN)"]),
    ("quoted, time back", f'{HEADER},note\n0,1,2,"a\n\nb"\n-1,1,3,c\n', 5, 1,
     ["-1.0 after 0.0", "on line 2"]),
    ("quoted, too few fields", f'{HEADER},note\n0,1,2,"a,b"\n1,2,"c"\n', 3, 4,
     ["note", "field 4 missing"]),
    # a text extra column takes the column-by-column path
    ("text column, empty torque", f"{HEADER},note\n0,1,2,a\n1,,3,b\n", 3, 2, ["empty value"]),
    ("crlf, bad number", f"{HEADER}\r\n0,1,2\r\n1,2,?\r\n", 3, 3, ["output_angle_deg", "'?'"]),
]


@pytest.mark.parametrize(
    ("text", "line", "column", "words"),
    [c[1:] for c in CSV_ERRORS],
    ids=[c[0] for c in CSV_ERRORS],
)
def test_samples_errors_name_file_line_and_column(
    tmp_path: Path, text: str, line: int, column: int | None, words: list[str]
) -> None:
    folder = write_folder(tmp_path / "run", text)
    err = expect_error(folder / "samples.csv", line, column)
    for word in words:
        assert word in str(err)


def test_non_utf8_byte_names_line_and_field(tmp_path: Path) -> None:
    folder = write_folder(tmp_path / "run", f"{HEADER},note\n0,1,2,a\n1,2,3,caf\xe9\n".encode(
        "latin-1"))
    err = expect_error(folder / "samples.csv", 3, 4)
    assert "0xe9" in str(err)


def test_bad_row_in_a_large_file_is_found(tmp_path: Path) -> None:
    n = 20000
    lines = [f"{i * 0.001!r},{float(np.sin(i))!r},{i * 1e-6!r}" for i in range(n)]
    lines[15321] = lines[15321].replace(",", ",1e", 1)  # "…,1e-0.7…" cannot be parsed
    folder = write_folder(tmp_path / "big", HEADER + "\n" + "\n".join(lines) + "\n")
    err = expect_error(folder / "samples.csv", 15323, 2)
    assert "torque_Nm" in str(err)


# ----------------------------------------------------------------------------- run.json errors


def test_invalid_json_names_line_and_character_column(tmp_path: Path) -> None:
    text = '{\n  "format": "rig-run/1",\n  "run_id": "x"\n  "unit": {}\n}\n'
    folder = write_folder(tmp_path / "run", f"{HEADER}\n0,1,2\n", text)
    err = expect_error(folder / "run.json", 4, 3)
    assert "invalid JSON" in str(err) and "delimiter" in str(err)


@pytest.mark.parametrize(
    ("text", "line", "column", "words"),
    [
        ('{\n  "run_id": "x",\n  "format": "rig-run/2"\n}', 3, 13, ["'rig-run/2'", "rig-run/1"]),
        ('{"unit": {"format": "rig-run/1"},\n "run_id": "x"}', 1, 1, ["no 'format'"]),
        ('{\n  "format": "rig-run/1",\n  "unit": {"run_id": "nested"}\n}', 1, 1, ["no 'run_id'"]),
        ('{"format": "rig-run/1",\n  "run_id": 17}', 2, 13, ["non-empty string", "17"]),
        ('{"format": "rig-run/1", "run_id": "x",\n "test": [1, 2]}', 2, 10, ["'test'", "list"]),
        ('[\n  "format"\n]', 1, 1, ["JSON object", "list"]),
        ('{"format": "rig-run/1", "run_id": "a",\n "run_id": "b"}', 2, 2, ["'run_id'", "twice"]),
    ],
    ids=["wrong format", "no format", "no run_id", "run_id not str", "test not object",
         "not an object", "duplicate key"],
)
def test_run_json_errors(
    tmp_path: Path, text: str, line: int, column: int, words: list[str]
) -> None:
    folder = write_folder(tmp_path / "run", f"{HEADER}\n0,1,2\n", text)
    err = expect_error(folder / "run.json", line, column)
    for word in words:
        assert word in str(err)


def test_unreadable_paths(tmp_path: Path) -> None:
    expect_error(tmp_path / "nowhere", None, None)
    (tmp_path / "empty").mkdir()
    err = expect_error(tmp_path / "empty", None, None)
    assert "no run.json" in str(err)
    only_json = write_folder(tmp_path / "only_json", "")
    (only_json / "samples.csv").unlink()
    err = expect_error(only_json / "samples.csv", None, None)
    assert "no such file" in str(err)
    folder_csv = write_folder(tmp_path / "dir_csv", "")
    (folder_csv / "samples.csv").unlink()
    (folder_csv / "samples.csv").mkdir()
    err = expect_error(folder_csv / "samples.csv", None, None)
    assert "is a folder" in str(err)


# ----------------------------------------------------------------------------- bare CSV


def test_bare_csv_from_another_lab(tmp_path: Path) -> None:
    path = tmp_path / "lab_B_export_07.csv"
    path.write_bytes(
        b"\xef\xbb\xbft_s, torque_Nm, output_angle_deg, temperature_C\r\n"
        b"0,0.0,12.5,21.5\r\n0.01,0.5,12.50001,\r\n0.02,1.0,12.50002,21.6"
    )
    run = read_run(path)
    assert run.meta == {"format": "rig-run/1", "run_id": "lab_B_export_07"}
    assert run.path == path
    assert any("bare CSV" in n for n in run.notes)
    assert any("stripped spaces" in n for n in run.notes)
    assert any("no newline" in n for n in run.notes)
    assert np.array_equal(run.output_angle_deg, [12.5, 12.50001, 12.50002])
    assert np.array_equal(run.temperature_C, [21.5, np.nan, 21.6], equal_nan=True)
    back = read_run(write_run(run, tmp_path / "imported"))
    assert runs_equal(run, back)
    campaign = read_run_or_campaign(path)
    assert [r.run_id for r in campaign.runs] == ["lab_B_export_07"]


def test_samples_csv_beside_run_json_reads_the_run(tmp_path: Path) -> None:
    folder = write_run(small_run(), tmp_path / "r")
    assert read_run(folder / "samples.csv").meta["run_id"] == "pair1-pos000"
    assert read_run(folder / "run.json").path == folder


# ----------------------------------------------------------------------------- truncated tail


def test_truncated_last_line(tmp_path: Path) -> None:
    run = small_run(n=50, temperature_C=np.full(50, 20.25))
    folder = write_run(run, tmp_path / "r")
    csv_path = folder / "samples.csv"
    raw = csv_path.read_bytes()
    last_start = raw.rstrip(b"\n").rfind(b"\n") + 1
    csv_path.write_bytes(raw[: last_start + 9])  # cut inside the last row's 2nd field
    with pytest.raises(RunFormatError) as info:
        read_run(folder)
    assert (info.value.line, info.value.column) == (51, 3)
    assert "allow_truncated_tail=True" in str(info.value)
    cut = read_run(folder, allow_truncated_tail=True)
    assert cut.n_samples == 49
    assert np.array_equal(bits(cut.torque_Nm), bits(run.torque_Nm[:49]))
    assert len(cut.notes) == 1 and "line 51" in cut.notes[0]


def test_cut_inside_the_last_field_is_noted_or_dropped(tmp_path: Path) -> None:
    t = np.arange(10) * 0.01
    run = Run.from_arrays("cut", t, np.cos(t), np.full(10, 0.123456789))
    folder = write_run(run, tmp_path / "r")
    csv_path = folder / "samples.csv"
    csv_path.write_bytes(csv_path.read_bytes()[:-3])  # last value 0.1234567: still a number
    lenient = read_run(folder)
    assert lenient.n_samples == 10
    assert any("line 11" in n and "no newline" in n for n in lenient.notes)
    strict = read_run(folder, allow_truncated_tail=True)
    assert strict.n_samples == 9
    assert runs_equal(
        strict, Run(run.meta, run.columns, {k: v[:9] for k, v in run.data.items()})
    )


# ----------------------------------------------------------------------------- campaigns


def test_campaign_round_trip_keeps_order_and_keys(tmp_path: Path) -> None:
    names = ["pos090", "pos000", "pos045"]
    runs = [
        small_run(f"pair1-{n}", test={"input_angle_deg": float(n[3:]), "cycles": 1})
        for n in names
    ]
    campaign = Campaign(
        meta={"format": "rig-campaign/1", "name": "pair1", "runs": names, "note": {"by": "QA"}},
        runs=runs,
    )
    folder = write_campaign(campaign, tmp_path / "pair1")
    assert is_campaign(folder) and is_campaign(folder / "campaign.json")
    back = read_campaign(folder)
    assert back.meta == campaign.meta
    assert back.name == "pair1"
    assert [r.run_id for r in back.runs] == ["pair1-pos090", "pair1-pos000", "pair1-pos045"]
    assert all(runs_equal(a, b) for a, b in zip(runs, back.runs, strict=True))
    assert back.notes == []
    again = write_campaign(back, tmp_path / "copy")
    assert json.loads((again / "campaign.json").read_text()) == campaign.meta


def test_campaign_without_json_is_sorted_and_named_after_folder(tmp_path: Path) -> None:
    for name in ["b_pos2", "a_pos1", "c_pos3"]:
        write_run(small_run(name), tmp_path / "unitX" / name)
    (tmp_path / "unitX" / "plots").mkdir()
    assert is_campaign(tmp_path / "unitX")
    assert not is_campaign(tmp_path / "unitX" / "a_pos1")
    assert not is_campaign(tmp_path / "unitX" / "plots")
    camp = read_campaign(tmp_path / "unitX")
    assert camp.meta == {
        "format": "rig-campaign/1", "name": "unitX", "runs": ["a_pos1", "b_pos2", "c_pos3"]
    }
    assert [r.run_id for r in camp.runs] == ["a_pos1", "b_pos2", "c_pos3"]
    assert camp.notes  # says where the run list came from
    single = read_run_or_campaign(tmp_path / "unitX" / "b_pos2")
    assert len(single.runs) == 1 and single.runs[0].run_id == "b_pos2"
    whole = read_run_or_campaign(tmp_path / "unitX")
    assert len(whole.runs) == 3


def test_campaign_json_errors_and_unlisted_runs(tmp_path: Path) -> None:
    folder = tmp_path / "c"
    for name in ["p0", "p1", "p2"]:
        write_run(small_run(name), folder / name)
    cj = folder / "campaign.json"
    cj.write_text('{"format": "rig-campaign/1", "name": "c",\n "runs": ["p0", "p9"]}\n')
    with pytest.raises(RunFormatError) as info:
        read_campaign(folder)
    assert (info.value.path, info.value.line, info.value.column) == (str(cj), 2, 17)
    assert "'p9'" in str(info.value)
    cj.write_text('{"format": "rig-campaign/1", "runs": ["p2", "p0"]}')
    camp = read_campaign(folder)
    assert [r.run_id for r in camp.runs] == ["p2", "p0"]
    assert any("['p1']" in n for n in camp.notes)
    cj.write_text('{"format": "rig-run/1", "runs": []}')
    with pytest.raises(RunFormatError) as info:
        read_campaign(folder)
    assert (info.value.line, info.value.column) == (1, 12)
    cj.write_text('{"format": "rig-campaign/1",\n "runs": "p0"}')
    with pytest.raises(RunFormatError) as info:
        read_campaign(folder)
    assert (info.value.line, info.value.column) == (2, 10)
    cj.write_text('{"format": "rig-campaign/1", "runs": ["../p0"]}')
    with pytest.raises(RunFormatError, match="sub-folder name"):
        read_campaign(folder)
    cj.unlink()
    write_run(small_run("p0"), folder / "p0_copy")
    with pytest.raises(RunFormatError, match="run_id 'p0' is also the run_id of 'p0'"):
        read_campaign(folder)


# ----------------------------------------------------------------------------- building runs


def test_from_arrays_builds_meta_and_checks_input(tmp_path: Path) -> None:
    run = small_run(
        unit={"kind": "internal_involute"},
        sensors={"torque_full_scale_Nm": 20.0},
        extra_meta={"started_at": "2026-11-21T10:00:00Z", "site": "lab A"},
        extra_columns={"phase": ["up", "up", "down", "down", "up"], "current_A": np.ones(5)},
    )
    assert list(run.meta) == ["format", "run_id", "started_at", "unit", "sensors", "site"]
    assert run.meta["started_at"] == "2026-11-21T10:00:00Z"
    assert run.columns == ["t_s", "torque_Nm", "output_angle_deg", "phase", "current_A"]
    assert run.test == {} and run.input_angle_deg is None and run.n_samples == 5
    assert Run.from_arrays("x", [0], [1], [2]).meta["started_at"].endswith("Z")
    with pytest.raises(ValueError, match="has 2 values, expected 3"):
        Run.from_arrays("x", [0, 1, 2], [1, 2, 3], [1, 2])
    with pytest.raises(ValueError, match=r"torque_Nm\[1\] is nan"):
        Run.from_arrays("x", [0, 1], [1, np.nan], [1, 2])
    with pytest.raises(ValueError, match="strictly ascending"):
        Run.from_arrays("x", [0, 1, 1], [1, 2, 3], [1, 2, 3])
    broken = small_run()
    broken.data["torque_Nm"] = broken.data["torque_Nm"][:2]
    with pytest.raises(ValueError, match="has 2 values"):
        write_run(broken, tmp_path / "never")
    assert not (tmp_path / "never").exists()


# ----------------------------------------------------------------------------- appender


COLUMNS = ["t_s", "torque_Nm", "output_angle_deg", "temperature_C", "phase"]


def rows_for(n: int, start: int = 0) -> list[list]:
    return [
        [i * 0.001, np.sin(i) * 5.0, 0.1 + 0.2 * i, None if i % 3 else 20.0 + i / 7, f"p,{i}"]
        for i in range(start, start + n)
    ]


def test_appender_writes_what_write_run_writes(tmp_path: Path) -> None:
    path = tmp_path / "live" / "samples.csv"
    path.parent.mkdir()
    rows = rows_for(40)
    with SamplesAppender(path, COLUMNS) as app:
        for row in rows[:25]:
            app.append(row)
    with SamplesAppender(path, COLUMNS) as app:  # reopen: header checked, rows appended
        for row in rows[25:]:
            app.append(row)
        with pytest.raises(ValueError, match="strictly ascending"):
            app.append(rows[0])
        with pytest.raises(ValueError, match="finite number"):
            app.append([1.0, float("nan"), 0.0, None, ""])
        with pytest.raises(ValueError, match="has 2 values"):
            app.append([1.0, 2.0])
    cols = list(zip(*rows, strict=True))
    run = Run.from_arrays(
        "live", cols[0], cols[1], cols[2],
        temperature_C=[np.nan if v is None else v for v in cols[3]],
        extra_columns={"phase": list(cols[4])},
    )
    reference = write_run(run, tmp_path / "ref") / "samples.csv"
    assert path.read_bytes() == reference.read_bytes()
    with pytest.raises(ValueError, match="closed"):
        app.append(rows[0])
    with pytest.raises(RunFormatError) as info:
        SamplesAppender(path, ["t_s", "torque_Nm", "output_angle_deg", "phase"])
    assert (info.value.line, info.value.column) == (1, 4)
    assert "does not match" in str(info.value)
    with pytest.raises(ValueError, match="'output_angle_deg' is missing"):
        SamplesAppender(tmp_path / "other.csv", ["t_s", "torque_Nm", "angle_deg"])


def test_appender_flushes_by_itself(tmp_path: Path) -> None:
    path = tmp_path / "samples.csv"
    app = SamplesAppender(path, COLUMNS, flush_interval_s=0.2)
    try:
        app.append(rows_for(1)[0])
        deadline = time.monotonic() + 20.0  # generous: only checks that it happens at all
        while path.read_text().count("\n") < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert path.read_text().count("\n") == 2
    finally:
        app.close()


CHILD = """
import sys
from rig.runformat import SamplesAppender
app = SamplesAppender(sys.argv[1], ["t_s", "torque_Nm", "output_angle_deg"], flush_interval_s=0.2)
i = 0
while True:
    app.append([i * 0.001, (i % 200) * 0.05 - 5.0, i * 1e-7])
    i += 1
    if i % 500 == 0:
        app.flush()
        print(i, flush=True)
"""


def test_appender_survives_sigkill(tmp_path: Path) -> None:
    path = tmp_path / "killed.csv"
    env = dict(os.environ, PYTHONPATH=str(REPO))
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(path)], stdout=subprocess.PIPE, text=True, env=env
    )
    try:
        flushed = 0
        while flushed < 3000:
            line = child.stdout.readline()
            assert line, "child appender died"
            flushed = int(line)
        child.send_signal(signal.SIGKILL)
        child.wait(timeout=30)
    finally:
        if child.poll() is None:
            child.kill()
        child.stdout.close()
    run = read_run(path, allow_truncated_tail=True)
    n = run.n_samples
    assert n >= flushed
    i = np.arange(n)
    assert np.array_equal(bits(run.t_s), bits(i * 0.001))
    assert np.array_equal(bits(run.torque_Nm), bits((i % 200) * 0.05 - 5.0))
    if not path.read_bytes().endswith(b"\n"):
        assert "dropped the incomplete last line" in run.notes[-1]


def test_appender_repairs_a_cut_tail_only_when_asked(tmp_path: Path) -> None:
    path = tmp_path / "samples.csv"
    with SamplesAppender(path, COLUMNS) as app:
        for row in rows_for(10):
            app.append(row)
    path.write_bytes(path.read_bytes()[:-7])
    with pytest.raises(RunFormatError) as info:
        SamplesAppender(path, COLUMNS)
    assert info.value.line == 11 and "repair_truncated_tail" in str(info.value)
    with SamplesAppender(path, COLUMNS, repair_truncated_tail=True) as app:
        for row in rows_for(5, start=9):
            app.append(row)
    run = read_run(path)
    assert run.n_samples == 14
    assert np.array_equal(run.t_s, np.arange(14) * 0.001)


# ----------------------------------------------------------------------------- pyarrow data path


def test_whole_numbers_of_extra_columns_are_written_as_integers(tmp_path: Path) -> None:
    n = 6
    run = small_run(n=n, extra_columns={
        "step": [0.0, 0.0, 1.0, 1.0, 2.0, 17.0],
        "sample_window": np.full(n, 8.0),
        "torque_command_Nm": [0.0, -0.0, 2.5, -10.0, 2.0**53, np.nan],
    })
    folder = write_run(run, tmp_path / "r")
    lines = (folder / "samples.csv").read_text().splitlines()
    assert lines[0].endswith(",step,sample_window,torque_command_Nm")
    tails = [line.split(",")[-3:] for line in lines[1:]]
    assert [t[0] for t in tails] == ["0", "0", "1", "1", "2", "17"]
    assert {t[1] for t in tails} == {"8"}
    # -0.0 keeps its sign, 2**53 is past the exact integers, NaN is empty
    assert [t[2] for t in tails] == ["0", "-0.0", "2.5", "-10", "9007199254740992.0", ""]
    assert lines[1].startswith("0.0,0.0,0.0,")  # the standard columns keep their point
    back = read_run(folder)
    assert runs_equal(run, back)
    assert np.signbit(back.data["torque_command_Nm"][1])
    # the appender writes the same bytes as write_run
    live = tmp_path / "live.csv"
    with SamplesAppender(live, run.columns) as app:
        for i in range(n):
            app.append([None if np.isnan(run.data[c][i]) else run.data[c][i]
                        for c in run.columns])
    assert live.read_bytes() == (folder / "samples.csv").read_bytes()


def test_floats_are_written_as_python_repr_at_every_magnitude(tmp_path: Path) -> None:
    rng = np.random.default_rng(11)
    bits_ = rng.integers(0, 2**64 - 1, 20000, dtype=np.uint64, endpoint=True)
    values = bits_.view(np.float64)
    values = values[np.isfinite(values)]
    mags = rng.standard_normal(20000) * 10.0 ** rng.integers(-20, 20, 20000)
    hard = np.concatenate([values, mags, SPECIAL, [1e-4, 9.999999999999999e-05, 1e16,
                                                   9999999999999998.0, np.inf, -np.inf]])
    n = hard.size
    run = Run.from_arrays("mag", np.arange(n, dtype=float), np.zeros(n), np.zeros(n),
                          temperature_C=hard)
    folder = write_run(run, tmp_path / "r")
    lines = (folder / "samples.csv").read_text().splitlines()[1:]
    assert [line.split(",")[3] for line in lines] == [repr(float(x)) for x in hard]
    assert runs_equal(read_run(folder), run)


@pytest.mark.parametrize(("cell", "column"), [("1_000", 2), ("١٢", 3), ("0x10", 1)])
def test_numbers_python_takes_but_the_format_does_not_are_refused(
    tmp_path: Path, cell: str, column: int
) -> None:
    rows = [["0", "1", "2"], ["1", "2", "3"], ["2", "3", "4"]]
    rows[1][column - 1] = cell
    text = HEADER + "\n" + "\n".join(",".join(r) for r in rows) + "\n"
    folder = write_folder(tmp_path / "run", text)
    err = expect_error(folder / "samples.csv", 3, column)
    assert f"cannot read {cell!r} as a number" in str(err)
    # in a column the format does not define, such cells make a text column
    folder = write_folder(tmp_path / "extra", f"{HEADER},count\n0,1,2,1_000\n1,2,3,7\n")
    assert read_run(folder).data["count"] == ["1_000", "7"]


def test_a_comment_line_is_not_skipped_but_refused(tmp_path: Path) -> None:
    # rig-run/1 has no comment lines (docs/run-format.md): such a line is a bad row
    folder = write_folder(tmp_path / "run", f"{HEADER}\n0,1,2\n# a comment\n1,2,3\n")
    err = expect_error(folder / "samples.csv", 3, 2)
    assert "field 2 missing" in str(err)
    folder = write_folder(tmp_path / "run2", f"{HEADER}\n0,1,2\n# t,T,angle\n1,2,3\n")
    err = expect_error(folder / "samples.csv", 3, 1)
    assert "cannot read '# t' as a number" in str(err)


def test_blank_fields_and_spaces_read_as_the_slow_pass_reads_them(tmp_path: Path) -> None:
    from rig.runformat.csvread import read_located, read_samples_csv

    text = (
        "t_s,torque_Nm,output_angle_deg,temperature_C,note,gap,flag\n"
        '0.0, 1.5 ,2,  ,"a, b",1,true\n'
        '0.5,-inf ,2,NaN,,  ,false\n'
        "1.0,2e-3,2.5,Infinity,x,3,true\n"
    ).replace("-inf ", "-1.25")
    path = tmp_path / "s.csv"
    path.write_text(text)
    fast = read_samples_csv(path, False)
    slow = read_located(path, False)
    assert fast[0] == slow[0]
    for name in fast[0]:
        a, b = fast[1][name], slow[1][name]
        if isinstance(b, np.ndarray):
            assert np.array_equal(bits(a), bits(b)), name
        else:
            assert a == b, name
    assert np.isnan(fast[1]["temperature_C"][:2]).all() and fast[1]["temperature_C"][2] == np.inf
    assert np.isnan(fast[1]["gap"][1]) and fast[1]["flag"] == ["true", "false", "true"]


def test_parquet_run_folder_round_trips_bit_exact(tmp_path: Path) -> None:
    from rig.runformat import SAMPLES_PARQUET, write_samples_parquet

    rng = np.random.default_rng(3)
    n = 500
    t_s, hard, temperature = _hard_samples(rng, n, [0, 7, n - 1])
    run = Run.from_arrays(
        "stored", t_s, hard, hard[::-1].copy(),
        temperature_C=temperature,
        extra_columns={"step": np.floor(np.arange(n) / 50.0),
                       "note": [f"row {i}, ok" if i % 7 else "" for i in range(n)]},
        extra_meta={"status": "completed", "future": {"kept": [1, 2]}},
    )
    folder = write_run(run, tmp_path / "r")
    write_samples_parquet(folder / SAMPLES_PARQUET, run.columns, run.data)
    (folder / "samples.csv").write_text(HEADER + "\n")  # a leftover CSV: Parquet wins
    back = read_run(folder)
    assert runs_equal(run, back) and back.notes == []
    assert np.signbit(back.torque_Nm[3])
    back.data["torque_Nm"][0] = 1.0  # writable like arrays read from CSV
    assert runs_equal(read_run(folder / SAMPLES_PARQUET), run)
    bare = read_run(tmp_path / "r" / SAMPLES_PARQUET)
    assert bare.run_id == "stored" and bare.path == folder


def test_parquet_problems_name_the_file_and_column(tmp_path: Path) -> None:
    from rig.runformat import SAMPLES_PARQUET, write_samples_parquet

    folder = write_run(small_run(), tmp_path / "r")
    path = folder / SAMPLES_PARQUET
    path.write_bytes(b"PAR1 not really")
    with pytest.raises(RunFormatError, match="not a readable Parquet file") as info:
        read_run(folder)
    assert info.value.path == str(path)
    write_samples_parquet(path, ["t_s", "torque_Nm", "output_angle_deg"],
                          {"t_s": np.array([0.0, 1.0, 1.0]), "torque_Nm": np.zeros(3),
                           "output_angle_deg": np.zeros(3)})
    with pytest.raises(RunFormatError, match="row 3: time must be strictly ascending") as info:
        read_run(folder)
    assert info.value.column == 1
