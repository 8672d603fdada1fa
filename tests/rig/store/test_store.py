"""The measurement store in one process: runs, campaigns, aborts, ids, calibration, WAL.

Every test taking ``make_store`` runs on both back-ends (SQLite, PostgreSQL: conftest.py).
"""

from __future__ import annotations

import json
import sqlite3
import threading
from datetime import UTC, datetime, timedelta

import numpy as np
import pytest

from rig.runformat import read_campaign, read_run
from rig.store import (
    InvalidIdError,
    Store,
    StoreError,
    UnknownIdError,
)
from rig.store.ids import ID_PATTERN

COLUMNS = ["t_s", "torque_Nm", "output_angle_deg", "temperature_C"]


def row(i: int) -> list[float]:
    """Sample i of a made-up run: 1 ms steps, ±10 N·m sine, a small twist, 20 °C."""
    return [i * 0.001, 10.0 * np.sin(i * 0.01), 1e-4 * i + 0.123456789012345, 20.0]


def fill(rec, n: int) -> None:
    for i in range(n):
        rec.append(row(i))


def test_completed_run_round_trips_through_folder_and_index(make_store, tmp_path):
    st = make_store(tmp_path / "store")
    meta = {
        "unit": {"serial": "RV-40E 1234", "kind": "internal_involute", "z_internal": 45},
        "test": {"rated_torque_Nm": 10.0, "input_angle_deg": 0.0},
        "operator": "Li Wei",
        "rig_id": "rig-2",
        "plan": {"name": "gbt-hysteresis", "version": "1.3"},
        "calibration": [{"sensor": "TS-77", "due": "2999-01-01", "certificate": "C-9"}],
        "lab_note": {"kept": True},
    }
    with st.begin_run(meta, COLUMNS) as rec:
        assert rec.meta["status"] == "running"
        assert json.loads((rec.path / "run.json").read_text())["status"] == "running"
        fill(rec, 250)
        rec.finish(result={"lost_motion_arcmin": 1.25, "backlash_arcmin": 0.75})
    info = st.get_run(rec.run_id)
    assert info.status == "completed" and info.reason is None
    assert info.n_samples == 250
    assert info.metrics == {"lost_motion_arcmin": 1.25, "backlash_arcmin": 0.75}
    assert (info.unit_serial, info.operator, info.rig_id) == ("RV-40E 1234", "Li Wei", "rig-2")
    assert (info.plan_name, info.plan_version) == ("gbt-hysteresis", "1.3")
    assert info.calibration == meta["calibration"] and info.calibration_warnings == []
    assert info.software_version == __import__("rig").__version__
    assert info.started_at <= info.finished_at
    assert info.path == st.run_path(rec.run_id) == tmp_path / "store" / "runs" / rec.run_id
    assert ID_PATTERN.fullmatch(rec.run_id) and rec.run_id.startswith("RV-40E_1234-")

    run = read_run(info.path)  # strict read: the finished folder is clean rig-run/1
    assert run.meta["status"] == "completed" and run.meta["reason"] is None
    assert run.meta["result"] == info.metrics and run.meta["n_samples"] == 250
    assert run.meta["lab_note"] == {"kept": True} and run.meta["unit"] == meta["unit"]
    expected = np.array([row(i) for i in range(250)])
    for j, name in enumerate(COLUMNS):
        assert np.array_equal(run.data[name], expected[:, j])  # bit-exact
    assert not (info.path / ".writer.lock").exists()
    assert st.load_run(rec.run_id).n_samples == 250
    # the samples appended as CSV during the run are kept in Parquet once it is finished
    assert sorted(p.name for p in info.path.iterdir()) == ["run.json", "samples.parquet"]
    assert read_run(info.path / "samples.parquet").columns == COLUMNS


def test_exception_in_the_block_aborts_the_run_and_keeps_its_samples(make_store, tmp_path):
    st = make_store(tmp_path)
    with pytest.raises(RuntimeError, match="torque limit"), st.begin_run({}, COLUMNS) as rec:
        fill(rec, 40)
        raise RuntimeError("torque limit 12 N·m exceeded: 12.5 N·m")
    info = st.get_run(rec.run_id)
    assert info.status == "aborted"
    assert info.reason == "RuntimeError: torque limit 12 N·m exceeded: 12.5 N·m"
    assert info.n_samples == 40
    run = read_run(info.path)
    assert run.n_samples == 40 and run.meta["status"] == "aborted"
    assert run.meta["reason"] == info.reason


def test_keyboard_interrupt_also_aborts(make_store, tmp_path):
    st = make_store(tmp_path)
    with pytest.raises(KeyboardInterrupt), st.begin_run({}, COLUMNS) as rec:
        fill(rec, 3)
        raise KeyboardInterrupt
    assert st.get_run(rec.run_id).reason == "KeyboardInterrupt"


def test_append_by_column_name_and_bad_rows(make_store, tmp_path):
    st = make_store(tmp_path)
    with st.begin_run({}, COLUMNS) as rec:
        rec.append({"t_s": 0.0, "torque_Nm": 1.0, "output_angle_deg": 2.0})
        with pytest.raises(ValueError, match="unknown column"):
            rec.append({"t_s": 1.0, "torque_Nm": 1.0, "output_angle_deg": 2.0, "Torque": 3})
        with pytest.raises(ValueError, match="strictly ascending"):
            rec.append([0.0, 1.0, 2.0, 20.0])
    run = st.load_run(rec.run_id)
    assert run.n_samples == 1 and np.isnan(run.temperature_C[0])
    assert st.get_run(rec.run_id).n_samples == 1


def test_finish_arguments_are_checked_and_a_bad_call_leaves_the_run_open(make_store, tmp_path):
    st = make_store(tmp_path)
    rec = st.begin_run({}, COLUMNS)
    fill(rec, 5)
    with pytest.raises(ValueError, match="needs a reason"):
        rec.finish("aborted")
    with pytest.raises(ValueError, match="status must be one of"):
        rec.finish("done")
    with pytest.raises(ValueError, match="JSON"):
        rec.finish(result={"lost_motion_arcmin": float("nan")})
    assert st.get_run(rec.run_id).status == "running"
    fill_more = [0.005, 1.0, 2.0, None]
    rec.append(fill_more)  # still open
    info = rec.finish("aborted", reason="operator pressed stop")
    assert (info.status, info.reason, info.n_samples) == ("aborted", "operator pressed stop", 6)
    with pytest.raises(StoreError, match="already finished"):
        rec.finish()


def test_bad_start_meta_is_refused_before_any_folder_is_made(make_store, tmp_path):
    st = make_store(tmp_path)
    bad = [
        ({"status": "completed"}, "may not set \\['status'\\]"),
        ({"run_id": "mine"}, "may not set"),
        ({"calibration": {"TS-1": "2027-01-01"}}, "must be a list"),
        ({"calibration": [{"sensor": "TS-1", "due": "31.01.2027"}]}, r"\[0\].*'TS-1'.*ISO"),
        ({"calibration": [{"due": "2027-01-01"}]}, "'sensor'"),
        ({"unit": {"serial": ["x"]}}, r"meta\['unit'\]\['serial'\]"),
        ({"plan": "gbt"}, r"meta\['plan'\] must be a dict"),
        ({"x": float("inf")}, "JSON"),
    ]
    for meta, pattern in bad:
        with pytest.raises(ValueError, match=pattern):
            st.begin_run(meta, COLUMNS)
    with pytest.raises(ValueError, match="lack the required \\['torque_Nm'\\]"):
        st.begin_run({}, ["t_s", "Torque_Nm", "output_angle_deg"])
    assert list((tmp_path / "runs").iterdir()) == []
    assert st.list_runs() == []


def test_calibration_past_due_is_warned(make_store, tmp_path, caplog):
    st = make_store(tmp_path)
    today = datetime.now(UTC).date()
    cal = [
        {"sensor": "encoder-out", "due": (today - timedelta(days=1)).isoformat()},
        {"sensor": "TS-77", "due": today.isoformat()},
        {"sensor": "encoder-in", "due": (today + timedelta(days=30)).isoformat()},
    ]
    with caplog.at_level("WARNING", logger="rig.store"), st.begin_run(
        {"calibration": cal}, COLUMNS
    ) as rec:
        fill(rec, 2)
    assert len(rec.warnings) == 1 and "'encoder-out'" in rec.warnings[0]
    assert "past due" in caplog.text and "encoder-out" in caplog.text
    assert st.get_run(rec.run_id).calibration_warnings == rec.warnings


def test_ids_are_unique_within_one_second_and_across_threads(make_store, tmp_path):
    st = make_store(tmp_path)
    ids: list[str] = []
    errors: list[BaseException] = []

    def worker() -> None:
        try:
            for _ in range(5):
                with st.begin_run({"unit": {"serial": "S1"}}, COLUMNS) as rec:
                    rec.append(row(0))
                ids.append(rec.run_id)
        except BaseException as e:  # reported below
            errors.append(e)

    threads = [threading.Thread(target=worker) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert errors == []
    assert len(ids) == 20 and len(set(ids)) == 20
    assert all(ID_PATTERN.fullmatch(i) for i in ids)
    assert {i.run_id for i in st.list_runs()} == set(ids)
    assert [i.run_id for i in st.list_runs(limit=3)] == [i.run_id for i in st.list_runs()][:3]


@pytest.mark.parametrize(
    "bad",
    ["..", "../x", "a/b", "a\\b", ".hidden", "", "x" * 101, "a b", "a\x00", "é", 7, None],
)
def test_ids_from_callers_are_validated(make_store, tmp_path, bad):
    st = make_store(tmp_path)
    for call in (st.get_run, st.run_path, st.load_run, st.get_campaign):
        with pytest.raises(InvalidIdError, match="invalid"):
            call(bad)
    if bad is None:  # None means "no campaign" to the two calls below
        return
    with pytest.raises(InvalidIdError):
        st.list_runs(campaign_id=bad)
    with pytest.raises(InvalidIdError):
        st.begin_run({}, COLUMNS, campaign_id=bad)


def test_unknown_ids_and_hostile_serials(make_store, tmp_path):
    st = make_store(tmp_path / "s")
    with pytest.raises(UnknownIdError, match="no run 'unit-20260101T000000Z-1'"):
        st.get_run("unit-20260101T000000Z-1")
    with st.begin_run({"unit": {"serial": "../../etc/passwd"}}, COLUMNS) as rec:
        rec.append(row(0))
    assert rec.path.parent == tmp_path / "s" / "runs"
    assert rec.run_id.startswith("etc_passwd-")
    with st.begin_run({"unit": {"serial": "..."}}, COLUMNS) as rec:
        rec.append(row(0))
    assert rec.run_id.startswith("unit-")


def test_campaign_folder_is_a_readable_campaign_of_its_completed_runs(make_store, tmp_path):
    st = make_store(tmp_path)
    cid = st.create_campaign("pair 1 positions", {"unit": {"serial": "P1"}, "positions": 3})
    done = []
    for k in range(3):
        with st.begin_run({"test": {"input_angle_deg": 120.0 * k}}, COLUMNS,
                          campaign_id=cid) as rec:
            fill(rec, 20)
        done.append(rec.run_id)
    with pytest.raises(ZeroDivisionError), st.begin_run({}, COLUMNS, campaign_id=cid) as bad:
        fill(bad, 5)
        _ = 1 / 0
    other = st.begin_run({}, COLUMNS)
    other.finish()
    assert {i.run_id for i in st.list_runs(campaign_id=cid)} == {*done, bad.run_id}
    assert [i.run_id for i in st.list_runs(campaign_id=cid, status="aborted")] == [bad.run_id]
    camp = read_campaign(st.get_campaign(cid).path)
    assert [r.run_id for r in camp.runs] == done  # completed ones, in order
    assert any(bad.run_id in n for n in camp.notes)  # the aborted folder is kept, named
    assert camp.meta["positions"] == 3 and camp.meta["status"] == "running"
    st.finish_campaign(cid, "completed", {"verdict": "runout"})
    info = st.get_campaign(cid)
    assert (info.status, info.summary) == ("completed", {"verdict": "runout"})
    assert json.loads((info.path / "campaign.json").read_text())["summary"] == info.summary
    with pytest.raises(StoreError, match="already completed"):
        st.finish_campaign(cid, "aborted")
    with pytest.raises(StoreError, match="is completed"):
        st.begin_run({}, COLUMNS, campaign_id=cid)
    with pytest.raises(ValueError, match="may not set"):
        st.create_campaign("x", {"runs": []})
    assert [c.campaign_id for c in st.list_campaigns()] == [cid]


def test_a_live_run_of_this_process_is_not_aborted_by_a_second_store(make_store, tmp_path):
    st = make_store(tmp_path)
    rec = st.begin_run({}, COLUMNS)
    fill(rec, 10)
    rec.samples.flush()
    second = make_store(tmp_path)
    assert second.recovered == [] and second.recover() == []
    assert second.get_run(rec.run_id).status == "running"
    assert second.load_run(rec.run_id).n_samples == 10  # readable while running
    rec.finish()
    assert second.get_run(rec.run_id).status == "completed"


def test_an_abandoned_recorder_is_recovered_once_its_lock_is_gone(make_store, tmp_path):
    st = make_store(tmp_path)
    rec = st.begin_run({}, COLUMNS)
    fill(rec, 7)
    rec.samples.close()
    rec._lock.release(remove=False)  # what the kernel does when the writer process dies
    assert make_store(tmp_path).recovered == [rec.run_id]
    info = st.get_run(rec.run_id)
    assert info.status == "aborted" and info.n_samples == 7
    assert make_store(tmp_path).recovered == []  # once only


def test_index_is_in_wal_mode_and_an_open_reader_does_not_block_the_writer(tmp_path):
    st = Store(tmp_path, busy_timeout_s=2.0)
    with st.begin_run({}, COLUMNS) as rec:
        rec.append(row(0))
    reader = sqlite3.connect(tmp_path / "index.sqlite", isolation_level=None)
    try:
        assert reader.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        reader.execute("BEGIN")
        assert reader.execute("SELECT count(*) FROM runs").fetchone()[0] == 1
        # the reader holds its snapshot open while the writer starts and finishes runs
        for _ in range(3):
            with st.begin_run({}, COLUMNS) as rec:
                rec.append(row(0))
        assert reader.execute("SELECT count(*) FROM runs").fetchone()[0] == 1  # snapshot
        reader.execute("COMMIT")
        assert reader.execute("SELECT count(*) FROM runs").fetchone()[0] == 4
    finally:
        reader.close()


def test_missing_store_and_newer_schema_are_clear_errors(tmp_path):
    with pytest.raises(StoreError, match="no store at .*index.sqlite"):
        Store(tmp_path / "nowhere", create=False)
    assert not (tmp_path / "nowhere").exists()
    Store(tmp_path / "s")
    conn = sqlite3.connect(tmp_path / "s" / "index.sqlite")
    conn.execute("PRAGMA user_version = 99")
    conn.commit()
    conn.close()
    with pytest.raises(StoreError, match="schema version 99 is newer"):
        Store(tmp_path / "s")
