"""The store across real processes: SIGKILL during a run, recovery, concurrent readers.

Every test runs on both back-ends (SQLite, PostgreSQL: ``make_store`` in conftest.py).
"""

from __future__ import annotations

import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pyarrow.parquet as pq
import pytest

from rig.runformat import read_run
from rig.store import RECOVERED_REASON
from tests.support.paths import REPO

# A writer that appends samples until it is killed; every 20 rows it reports the count.
WRITER = """
import math, sys, time
from rig.store import Store
st = Store(sys.argv[1])
rec = st.begin_run({"unit": {"serial": "SK-1"}, "operator": "test"},
                   ["t_s", "torque_Nm", "output_angle_deg", "note"])
print("RUN", rec.run_id, flush=True)
i = 0
while True:
    rec.append([i * 0.001, 10.0 * math.sin(i * 0.01), 0.123456789012 + 1e-5 * i, f"row {i}"])
    i += 1
    if i % 20 == 0:
        print("N", i, flush=True)
        time.sleep(0.002)
"""

# A writer killed (by itself) right after the half of a row reached the disk.
HALF_ROW = """
import os, signal, sys
from rig.store import Store
st = Store(sys.argv[1])
rec = st.begin_run({}, ["t_s", "torque_Nm", "output_angle_deg"])
for i in range(3):
    rec.append([i * 0.5, 1.0 + i, 2.0])
rec.samples.flush()
with open(rec.path / "samples.csv", "a") as f:
    f.write("1.5,4.0,2.0000")
print(rec.run_id, flush=True)
os.kill(os.getpid(), signal.SIGKILL)
"""

# A writer killed while it finalises: STAGE "tmp" dies with a half-written temporary Parquet
# file, STAGE "renamed" after samples.parquet is in place but before the CSV is removed.
MID_FINALISE = """
import os, signal, sys
from rig.runformat import read_run, write_samples_parquet
from rig.store import Store
st = Store(sys.argv[1])
rec = st.begin_run({}, ["t_s", "torque_Nm", "output_angle_deg", "step"])
for i in range(300):
    rec.append([i * 0.001, 0.1 * i - 7.0, 1e-7 * i + 0.3, float(i // 100)])
rec.samples.close()
if sys.argv[2] == "tmp":
    (rec.path / ".samples.parquet.tmp").write_bytes(b"PAR1 half")
else:
    run = read_run(rec.path)
    write_samples_parquet(rec.path / "samples.parquet", run.columns, run.data)
print(rec.run_id, flush=True)
os.kill(os.getpid(), signal.SIGKILL)
"""

# A writer that holds a run open until told (on stdin) to finish it.
HOLDER = """
import sys
from rig.store import Store
st = Store(sys.argv[1])
rec = st.begin_run({}, ["t_s", "torque_Nm", "output_angle_deg"])
rec.append([0.0, 0.0, 0.0])
rec.samples.flush()
print(rec.run_id, flush=True)
sys.stdin.readline()
rec.finish(result={"ok": 1})
print("done", flush=True)
"""

# Writes many short runs; the reader below lists them meanwhile.
MANY_RUNS = """
import sys
from rig.store import Store
st = Store(sys.argv[1])
for k in range(int(sys.argv[2])):
    with st.begin_run({"unit": {"serial": "W"}}, ["t_s", "torque_Nm", "output_angle_deg"]) as rec:
        for i in range(40):
            rec.append([i * 0.01, float(k), float(i)])
print("writer done", flush=True)
"""

READER = """
import sqlite3, sys, time
from rig.store import Store
st = Store(sys.argv[1], recover=False)
stop = sys.argv[2]
lists = loads = 0
seen = set()
import os
while not os.path.exists(stop):
    runs = st.list_runs()
    lists += 1
    seen.update(r.status for r in runs)
    if runs:
        st.load_run(runs[0].run_id)  # the newest: often still being written
        loads += 1
print("reader", lists, loads, ",".join(sorted(seen)), flush=True)
"""


def spawn(script: str, *args: str, stdin: int | None = None,
          env: dict[str, str] | None = None) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-c", script, *args], env={**os.environ, **(env or {})},
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=stdin, text=True,
    )


def line_reader(proc: subprocess.Popen) -> queue.Queue:
    """Lines of the child's stdout, read by a thread so that the test never blocks on them."""
    lines: queue.Queue = queue.Queue()

    def pump() -> None:
        for line in proc.stdout:
            lines.put(line.rstrip("\n"))
        lines.put(None)

    threading.Thread(target=pump, daemon=True).start()
    return lines


def next_line(lines: queue.Queue, proc: subprocess.Popen, timeout: float = 60.0) -> str:
    try:
        line = lines.get(timeout=timeout)
    except queue.Empty:
        proc.kill()
        pytest.fail(f"child printed nothing for {timeout} s; stderr: {proc.stderr.read()}")
    if line is None:
        proc.wait(10)
        pytest.fail(f"child ended (rc {proc.returncode}); stderr: {proc.stderr.read()}")
    return line


def test_sigkill_keeps_the_samples_and_the_next_start_marks_the_run_aborted(make_store, tmp_path):
    target, env = make_store.target(tmp_path), make_store.env(tmp_path)
    proc = spawn(WRITER, target, env=env)
    lines = line_reader(proc)
    try:
        first = next_line(lines, proc)
        assert first.startswith("RUN ")
        run_id = first.split()[1]
        count = 0
        while count < 400:
            count = int(next_line(lines, proc).split()[1])
        # a second process opening the store while the writer lives must not abort the run
        live = make_store(tmp_path)
        assert live.recovered == []
        assert live.get_run(run_id).status == "running"
        assert live.load_run(run_id).n_samples > 0
        # drain to the newest count, then let > 1 s pass (flush interval 0.5 s) and kill
        while True:
            try:
                item = lines.get_nowait()
            except queue.Empty:
                break
            if item is not None:
                count = int(item.split()[1])
        appended_before = count
        time.sleep(2.0)
        proc.send_signal(signal.SIGKILL)
        assert proc.wait(30) == -signal.SIGKILL
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)

    store = make_store(tmp_path)
    assert store.recovered == [run_id]
    info = store.get_run(run_id)
    assert info.status == "aborted" and info.reason == RECOVERED_REASON
    assert info.n_samples >= appended_before
    run = store.load_run(run_id)
    assert run.n_samples == info.n_samples
    i = np.arange(run.n_samples)
    assert np.array_equal(run.t_s, i * 0.001)
    assert np.array_equal(run.torque_Nm, np.array([10.0 * np.sin(k * 0.01) for k in i]))
    assert np.array_equal(run.output_angle_deg, 0.123456789012 + 1e-5 * i)
    assert run.data["note"][-1] == f"row {run.n_samples - 1}"
    meta = json.loads((info.path / "run.json").read_text())
    assert meta["status"] == "aborted" and meta["reason"] == RECOVERED_REASON
    assert meta["recovery"]["by_pid"] == os.getpid()
    read_run(info.path)  # strict reader: the folder is clean rig-run/1 after recovery
    # recovery finalised the CSV stream to Parquet, bit for bit
    assert sorted(p.name for p in info.path.iterdir()) == ["run.json", "samples.parquet"]
    table = pq.read_table(info.path / "samples.parquet")
    assert table.column_names == ["t_s", "torque_Nm", "output_angle_deg", "note"]
    assert np.array_equal(table.column("t_s").to_numpy().view(np.uint64),
                          (i * 0.001).view(np.uint64))
    assert make_store(tmp_path).recovered == []


def test_a_row_cut_off_by_the_kill_is_dropped_and_recorded(make_store, tmp_path):
    target, env = make_store.target(tmp_path), make_store.env(tmp_path)
    proc = spawn(HALF_ROW, target, env=env)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL, err
    run_id = out.strip()
    raw = (tmp_path / "runs" / run_id / "samples.csv").read_bytes()
    assert raw.endswith(b"1.5,4.0,2.0000")
    store = make_store(tmp_path)
    assert store.recovered == [run_id]
    run = read_run(store.run_path(run_id))
    assert run.n_samples == 3 and list(run.t_s) == [0.0, 0.5, 1.0]
    assert run.meta["recovery"]["dropped_incomplete_line"] == "1.5,4.0,2.0000"
    assert store.get_run(run_id).n_samples == 3


@pytest.mark.parametrize("stage", ["tmp", "renamed"])
def test_a_kill_during_the_parquet_finalisation_is_recovered(make_store, tmp_path, stage):
    target, env = make_store.target(tmp_path), make_store.env(tmp_path)
    proc = spawn(MID_FINALISE, target, stage, env=env)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL, err
    run_id = out.strip()
    folder = tmp_path / "runs" / run_id
    assert (folder / "samples.csv").is_file()
    store = make_store(tmp_path)
    assert store.recovered == [run_id]
    info = store.get_run(run_id)
    assert (info.status, info.reason, info.n_samples) == ("aborted", RECOVERED_REASON, 300)
    assert sorted(p.name for p in folder.iterdir()) == ["run.json", "samples.parquet"]
    run = read_run(folder)
    i = np.arange(300)
    assert np.array_equal(run.t_s, i * 0.001) and np.array_equal(run.data["step"], i // 100)
    assert np.array_equal(run.torque_Nm, 0.1 * i - 7.0)


def test_a_live_writer_in_another_process_is_left_alone_and_finishes(make_store, tmp_path):
    target, env = make_store.target(tmp_path), make_store.env(tmp_path)
    proc = spawn(HOLDER, target, stdin=subprocess.PIPE, env=env)
    lines = line_reader(proc)
    try:
        run_id = next_line(lines, proc)
        for _ in range(3):
            assert make_store(tmp_path).recovered == []
        assert make_store(tmp_path).get_run(run_id).status == "running"
        proc.stdin.write("finish\n")
        proc.stdin.flush()
        assert next_line(lines, proc) == "done"
        assert proc.wait(30) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    info = make_store(tmp_path).get_run(run_id)
    assert (info.status, info.metrics, info.n_samples) == ("completed", {"ok": 1}, 1)


def test_concurrent_reader_process_never_blocks_or_fails_while_a_writer_works(make_store,
                                                                             tmp_path):
    target, env = make_store.target(tmp_path), make_store.env(tmp_path)
    make_store(tmp_path)
    stop = tmp_path / "stop-reader"
    n_runs = 25
    reader = spawn(READER, target, str(stop), env=env)
    writer = spawn(MANY_RUNS, target, str(n_runs), env=env)
    try:
        w_out, w_err = writer.communicate(timeout=100)
        stop.touch()
        r_out, r_err = reader.communicate(timeout=60)
    finally:
        for p in (reader, writer):
            if p.poll() is None:
                p.kill()
                p.wait(10)
    assert writer.returncode == 0, w_err
    assert reader.returncode == 0, r_err
    assert "database is locked" not in w_err + r_err
    _, lists, loads, _ = r_out.split()
    assert int(lists) > 0
    runs = make_store(tmp_path).list_runs()
    assert len(runs) == n_runs and {r.status for r in runs} == {"completed"}
    assert all(r.n_samples == 40 for r in runs)
