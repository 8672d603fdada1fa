"""Many rigs, one PostgreSQL store: concurrent writer processes, a SIGKILL, a server restart.

Four simulated rigs (``rig campaign run --simulated``, each with its own devices over their
real protocols) measure campaigns into one store at once, one of them killed mid-run.

The database-restart test records through the ordinary Store API
(:func:`rig.store.synthetic_runs.write_campaign`: runs of the reference dead-zone loop, samples
paced
like a rig's). The server is a real throw-away PostgreSQL cluster (tests/support/pg_server.py).
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
from pathlib import Path

import pytest

from rig.store import RECOVERED_REASON, Store
from tests.support.campaigns import campaign_toml, ok_or_out_of_step
from tests.support.paths import REPO

# loads the machine on purpose (tests/conftest.py)
pytestmark = [pytest.mark.realtime, pytest.mark.alone]

TINY = campaign_toml("tiny-line", "positions_deg = [90.0]", serial="SIM-1", drag=False)
# No [limits]: this test is about the store (no run lost or duplicated); on a loaded machine the
# sparse plan can leave a metric unavailable, which a limit would turn into exit code 1.

WRITER = """
import sys
from rig.store import Store
from rig.store.synthetic_runs import write_campaign

url, samples, serial, n_runs, seconds = sys.argv[1:6]
st = Store(url, samples=samples, reconnect_s=60)
positions = tuple(90.0 * k for k in range(int(n_runs)))
cid = write_campaign(st, serial, play_arcmin=2.0, positions_deg=positions,
                     run_seconds=float(seconds), on_run=lambda r: print("RUN", r, flush=True))
print("CAMPAIGN", cid, flush=True)
"""


def spawn(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", WRITER, *args], cwd=REPO, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def lines_of(proc: subprocess.Popen) -> queue.Queue:
    q: queue.Queue = queue.Queue()

    def pump() -> None:
        for line in proc.stdout:
            q.put(line.split())
        q.put(None)

    threading.Thread(target=pump, daemon=True).start()
    return q


def collect(procs: list[subprocess.Popen], timeout: float = 60.0) -> list[str]:
    errors = []
    for p in procs:
        try:
            p.wait(timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(10)
        errors.append(p.stderr.read())
        assert p.returncode == 0, errors[-1][-2000:]
    return errors


def sim_rig(pg_url: str, samples: Path, folder: Path, serial: str, positions: str,
            env: dict[str, str]) -> subprocess.Popen:
    """``rig campaign run --simulated``: its own simulated rig (CAN, Modbus and serial devices
    on their real protocols), measuring a short campaign into the shared store."""
    toml = folder / f"{serial}.toml"
    toml.write_text(TINY.replace('name = "tiny-line"', f'name = "line-{serial.lower()}"')
                    .replace('serial = "SIM-1"', f'serial = "{serial}"')
                    .replace("positions_deg = [90.0]", f"positions_deg = {positions}"))
    return subprocess.Popen(
        [sys.executable, "-c", "from rig.cli import main; main()", "campaign", "run",
         str(toml), "--simulated", "--store", pg_url, "--samples", str(samples), "--json",
         str(folder / f"{serial}.json")],
        cwd=folder, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_four_simulated_rigs_one_killed_lose_nothing(pg_url, tmp_path):
    """Four processes, each a simulated rig running a campaign, write into one PostgreSQL
    store at once; one is SIGKILLed mid-run. The others finish unaffected, no run is lost or
    duplicated, ids are unique, and the killed rig's run is recovered as aborted."""
    samples = tmp_path / "shared-samples"
    Store(pg_url, samples=samples)  # created once; the rigs open it concurrently
    env = {k: v for k, v in os.environ.items() if k not in ("RIG_STORE", "RIG_SAMPLES_DIR")}
    # each rig's simulated devices and engine at real-time priority where permitted, as a
    # rig PC that shares its CPU runs them (docs/reliability.md): four rigs at once on the
    # normal scheduler of this 2-core machine starved an engine's heartbeat reading and its
    # keepalive for 1.5-2 s (3 of 4 tries, 2026-11-28); at FIFO 20, 3 of 3 passed
    env["RIG_SIM_REALTIME_PRIORITY"] = "20"
    serials = ["SIM-1", "SIM-2", "SIM-3"]
    rigs = [sim_rig(pg_url, samples, tmp_path, s, "[0.0, 180.0]", env) for s in serials]
    victim = sim_rig(pg_url, samples, tmp_path, "KILLED", "[0.0, 90.0, 180.0]", env)
    watcher = Store(pg_url, samples=samples)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not watcher.list_runs(serial="KILLED"):
            time.sleep(0.2)
        assert watcher.list_runs(serial="KILLED"), victim.communicate(timeout=5)[1][-2000:]
        time.sleep(1.0)  # into its first run
        victim.send_signal(signal.SIGKILL)
        assert victim.wait(30) == -signal.SIGKILL
        errors = [r.communicate(timeout=240)[1] for r in rigs]
        for r, err, serial in zip(rigs, errors, serials, strict=True):
            # exit 2 (INCOMPLETE) only for runs whose channels came out of step: four rigs
            # measuring at once on two cores starve a channel (the torque 35-39 ms late in
            # two CI runs of 2026-11-28); what this test is about is checked below
            assert r.returncode == 0 or (r.returncode == 2 and all(
                ok_or_out_of_step(run) for run in json.loads(
                    (tmp_path / f"{serial}.json").read_text())["runs"])), err[-2000:]
    finally:
        for p in (*rigs, victim):
            if p.poll() is None:
                p.kill()
                p.wait(10)

    st = Store(pg_url, samples=samples)  # opening recovers the killed rig's run
    assert len(st.recovered) == 1
    (killed_run,) = st.recovered
    info = st.get_run(killed_run)
    assert info.status == "aborted" and info.reason == RECOVERED_REASON
    assert info.unit_serial == "KILLED" and st.load_run(killed_run).n_samples == info.n_samples
    runs = st.list_runs()
    ids = [r.run_id for r in runs]
    assert len(ids) == len(set(ids)) == 2 * len(serials) + 1
    assert len({r.path for r in runs}) == len(runs)  # every run has its own folder
    for serial in serials:
        doc = json.loads((tmp_path / f"{serial}.json").read_text())
        mine = st.list_runs(serial=serial)
        assert sorted(r.run_id for r in mine) == sorted(r["run_id"] for r in doc["runs"])
        assert {r.status for r in mine} == {"completed"}
        assert st.get_campaign(doc["campaign_id"]).status == "completed"
        for r in mine:
            assert st.load_run(r.run_id).n_samples == r.n_samples > 100


def test_a_database_restart_mid_campaign_is_survived(tmp_path):
    """Own cluster: stopping it must not disturb the other tests' server."""
    from tests.support.pg_server import PgServer, required_bin_dir

    server = PgServer(required_bin_dir())
    try:
        server.start()
        url = server.url()
        samples = tmp_path / "samples"
        Store(url, samples=samples)
        writer = spawn(url, str(samples), "RESTART", "4", "0.6")
        lines = lines_of(writer)
        first = lines.get(timeout=60)
        assert first is not None and first[0] == "RUN", writer.stderr.read()
        server.stop("fast")  # kills every connection; the writer is inside run 2
        time.sleep(1.5)
        server.start()
        (err,) = collect([writer])
        assert "reconnecting" in err  # it saw the outage and waited it out
        st = Store(url, samples=samples)
        runs = st.list_runs(serial="RESTART")
        assert len(runs) == 4 and {r.status for r in runs} == {"completed"}, runs
        assert all(r.n_samples == 4001 for r in runs)  # no sample lost during the outage
        (camp,) = st.list_campaigns()
        assert camp.status == "completed"
    finally:
        server.destroy()
