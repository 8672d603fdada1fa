"""The control page's API without a rig (FastAPI TestClient): auth rules, settings, input
validation, history, run details and downloads from a real store."""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from rig.results.analyse import analyse_run
from rig.runformat import Run, read_campaign, read_run, runs_equal, samples_csv_bytes
from rig.store import Store
from rig.web import create_app
from rig.web.settings import TOKEN_ENV, WebSettingsError, resolve_settings
from tests.support.paths import REPO
from tests.support.simulated_page import identified

EXAMPLE_RUN = REPO / "rig" / "examples" / "runs" / "pair1-pos000"
EXAMPLE_CAMPAIGN = REPO / "rig" / "examples" / "runs" / "campaign-pair1-positions"
UNIT = json.loads((REPO / "rig" / "examples" / "units" / "seed000-pair1.json").read_text())
TOKEN = "operator-token-for-tests"


def store_run(store: Store, folder: Path, campaign_id: str | None = None) -> str:
    """Record an example run into the store through its public API; return its run id."""
    run = read_run(folder)
    meta = {k: v for k, v in run.meta.items()
            if k not in ("format", "run_id", "started_at", "status", "reason", "result",
                         "finished_at", "n_samples", "software_version", "campaign_id")}
    meta.setdefault("unit", {}).setdefault("serial", "pair1")
    with store.begin_run(meta, list(run.columns), campaign_id=campaign_id) as rec:
        for i in range(run.n_samples):
            rec.append([None if not np.isfinite(run.data[c][i]) else float(run.data[c][i])
                        for c in run.columns])
        return rec.run_id


@pytest.fixture
def store(tmp_path: Path) -> Store:
    return Store(tmp_path / "store")


@pytest.fixture
def client(store: Store, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.delenv(TOKEN_ENV, raising=False)
    settings = resolve_settings(store_root=store.root, token=TOKEN)
    with TestClient(create_app(settings, store=store)) as c:
        yield c


AUTH = {"Authorization": f"Bearer {TOKEN}"}


def run_request(**plan: object) -> dict:
    return identified({"unit": UNIT, "plan": {"rated_torque_Nm": 10.0, **plan}})


# --------------------------------------------------------------------------- auth rules


@pytest.mark.parametrize("path,body", [
    ("/api/control/start", run_request()),
    ("/api/control/pause", None),
    ("/api/control/resume", None),
    ("/api/control/abort", None),
    ("/api/devices/tare", None),
    ("/api/devices/input-lock", {"confirm": True}),
])
def test_commands_need_the_operator_token(client: TestClient, path: str, body: dict | None):
    none = client.post(path, json=body)
    assert none.status_code == 401
    assert "operator token" in none.json()["detail"]
    assert none.headers["www-authenticate"] == "Bearer"
    wrong = client.post(path, json=body, headers={"Authorization": "Bearer not-the-token"})
    assert wrong.status_code == 403
    assert "wrong operator token" in wrong.json()["detail"]
    right = client.post(path, json=body, headers=AUTH)
    assert right.status_code == 409  # authorised, but there is no rig to command
    assert "no rig is connected" in right.json()["detail"] or "no measurement" in \
        right.json()["detail"]


def test_estop_needs_no_token_and_viewers_can_watch(client: TestClient):
    r = client.post("/api/control/estop")
    assert r.status_code == 200
    assert r.json()["message"] == "E-stop: no rig connected"
    viewer = client.get("/api/status").json()
    assert viewer["operator"] is False and viewer["state"] == "no_rig"
    assert client.get("/api/status", headers=AUTH).json()["operator"] is True
    for path in ("/api/runs", "/api/campaigns", "/api/units", "/", "/openapi.json"):
        assert client.get(path).status_code == 200, path


def test_preview_is_open_to_viewers_and_names_the_model(client: TestClient):
    r = client.post("/api/plan/preview", json=run_request(mode="constant_rate", pre_cycles=0))
    assert r.status_code == 200
    p = r.json()
    assert p["n_runs"] == 1 and p["name"] == "hysteresis"
    # constant rate, no pre-cycle: zero, -T, settle, checkpoint, 4 quarters with a slow band
    assert p["n_steps"] == len(p["steps"]) and not p["truncated"]
    # duration: ramps 10/25 s, 4 quarters of 10 N*m with |T| < 0.3 at 0.3 N*m/s ...
    assert p["estimated_s"] > 4 * 0.3 / 0.3
    assert p["fits"] is False and "no rig connected" in p["problems"][0]
    # the reference nominal model of run-format.md for pair 1 (play = backlash)
    assert p["model"]["play_arcmin"] == pytest.approx(p["model"]["backlash_arcmin"])
    k = p["model"]["stiffness_Nm_per_arcmin"]
    assert p["model"]["lost_motion_arcmin"] == pytest.approx(
        p["model"]["play_arcmin"] + 2 * 0.3 / k, rel=1e-9)


# --------------------------------------------------------------------------- settings


def test_binding_elsewhere_than_loopback_needs_a_chosen_token(tmp_path: Path,
                                                              monkeypatch: pytest.MonkeyPatch):
    monkeypatch.delenv(TOKEN_ENV, raising=False)
    with pytest.raises(WebSettingsError, match="refusing to bind to 0.0.0.0.*--token"):
        resolve_settings("0.0.0.0", 8765, store_root=tmp_path)
    assert not (tmp_path / "web" / "operator-token").exists()
    ok = resolve_settings("0.0.0.0", 8765, store_root=tmp_path, token="chosen-token-1")
    assert ok.token == "chosen-token-1" and ok.token_source == "option"
    monkeypatch.setenv(TOKEN_ENV, "from-the-environment")
    env = resolve_settings("0.0.0.0", 8765, store_root=tmp_path)
    assert env.token_source == "environment" and env.token == "from-the-environment"
    with pytest.raises(WebSettingsError, match="at least 8 characters"):
        resolve_settings(store_root=tmp_path, token="short")


def test_token_is_generated_once_and_kept(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.delenv(TOKEN_ENV, raising=False)
    first = resolve_settings(store_root=tmp_path)
    assert first.token_source == "generated" and len(first.token) >= 20
    path = tmp_path / "web" / "operator-token"
    assert path.stat().st_mode & 0o777 == 0o600
    again = resolve_settings(store_root=tmp_path)
    assert again.token == first.token and again.token_source == "file"
    assert first.url == "http://127.0.0.1:8765/"


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize("change,field", [
    ({"plan": {"rated_torque_Nm": -1}}, "rated_torque_Nm"),
    ({"plan": {"rated_torque_Nm": 10, "amplitude_pct": 150}}, "amplitude_pct"),
    ({"plan": {"rated_torque_Nm": 10, "mode": "sideways"}}, "mode"),
    ({"plan": {"rated_torque_Nm": 10, "cycles": 0}}, "cycles"),
    ({"plan": {"rated_torque_Nm": 10, "unknown_key": 1}}, "unknown_key"),
    ({"unit": {**UNIT, "z_internal": 30}}, "z_internal"),
    ({"unit": {**UNIT, "module_mm": "one"}}, "module_mm"),
    ({"position_deg": 1e9}, "position_deg"),
])
def test_bad_values_get_422_naming_the_field(client: TestClient, change: dict, field: str):
    body = {**run_request(), **change}
    r = client.post("/api/plan/preview", json=body)
    assert r.status_code == 422
    text = json.dumps(r.json()["detail"])
    assert field in text


def test_a_plan_too_long_to_preview_is_refused(client: TestClient):
    body = {**run_request(steps_per_quarter=200, cycles=20), "kind": "campaign",
            "axes": {"positions_deg": list(range(0, 360, 10)), "repeats": 50}}
    r = client.post("/api/plan/preview", json=body)
    assert r.status_code == 422
    assert "steps" in r.json()["detail"][0]["msg"]


# --------------------------------------------------------------------------- history


def test_history_details_loop_and_downloads(client: TestClient, store: Store, tmp_path: Path):
    run_id = store_run(store, EXAMPLE_RUN)
    runs = client.get("/api/runs").json()
    assert [r["run_id"] for r in runs] == [run_id]
    assert runs[0]["status"] == "completed" and runs[0]["unit_serial"] == "pair1"

    detail = client.get(f"/api/runs/{run_id}").json()
    assert detail["meta"]["format"] == "rig-run/1"
    assert detail["columns"][:3] == ["t_s", "torque_Nm", "output_angle_deg"]

    expected = analyse_run(read_run(EXAMPLE_RUN)).to_dict()
    loop = client.get(f"/api/runs/{run_id}/loop", params={"max_points": 500}).json()
    assert loop["analysis_error"] is None and loop["n_samples"] == read_run(EXAMPLE_RUN).n_samples
    assert len(loop["torque_Nm"]) == 500 == len(loop["model_twist_arcmin"])
    assert loop["metrics"]["lost_motion_arcmin"] == pytest.approx(
        expected["lost_motion_arcmin"], rel=1e-12)
    assert loop["band_Nm"] == pytest.approx(0.03 * read_run(EXAMPLE_RUN).test["rated_torque_Nm"])
    # the drawn loop is centred: its twist range is symmetric about zero
    twist = np.array(loop["twist_arcmin"])
    assert abs(twist.max() + twist.min()) < 0.05 * (twist.max() - twist.min())

    csv = client.get(f"/api/runs/{run_id}/samples.csv")
    assert csv.headers["content-type"].startswith("text/csv")
    # a stored run keeps Parquet; the download is its samples in rig-run/1 CSV, bit for bit
    assert not (store.run_path(run_id) / "samples.csv").exists()
    assert csv.content == samples_csv_bytes(store.load_run(run_id))
    (tmp_path / "download.csv").write_bytes(csv.content)
    downloaded = read_run(tmp_path / "download.csv")
    assert runs_equal(Run(store.load_run(run_id).meta, downloaded.columns, downloaded.data),
                      store.load_run(run_id))

    z = client.get(f"/api/runs/{run_id}/run.zip")
    assert z.headers["content-type"] == "application/zip"
    with zipfile.ZipFile(io.BytesIO(z.content)) as zf:
        assert sorted(zf.namelist()) == [f"{run_id}/run.json", f"{run_id}/samples.csv"]
        zf.extractall(tmp_path / "unzipped")
    assert runs_equal(read_run(tmp_path / "unzipped" / run_id), store.load_run(run_id))

    png = client.get(f"/api/runs/{run_id}/loop.png")
    assert png.status_code == 200 and png.content[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("bad,code", [
    ("..", 404), ("a.b", 422), ("%2e%2e%2fetc", 404), ("-leading", 422), ("x" * 101, 422),
    ("unknown-run-1", 404),
])
def test_run_ids_cannot_escape_the_store(client: TestClient, bad: str, code: int):
    for suffix in ("", "/samples.csv", "/run.zip", "/loop"):
        r = client.get(f"/api/runs/{bad}{suffix}")
        assert r.status_code == code, (bad, suffix, r.status_code)


def test_campaign_results_and_diagnosis(client: TestClient, store: Store):
    campaign = read_campaign(EXAMPLE_CAMPAIGN)
    cid = store.create_campaign("pair1-positions", meta={"unit": UNIT})
    for run in campaign.runs:
        store_run(store, run.path, campaign_id=cid)
    running = client.get(f"/api/campaigns/{cid}/diagnosis.json")
    assert running.status_code == 409 and "still running" in running.json()["detail"]
    store.finish_campaign(cid, "completed", summary={"passed": True, "failures": []})
    c = client.get(f"/api/campaigns/{cid}").json()
    assert c["status"] == "completed" and len(c["runs"]) == len(campaign.runs)
    assert [x["campaign_id"] for x in client.get("/api/campaigns").json()] == [cid]
    report = client.get(f"/api/campaigns/{cid}/diagnosis.json").json()
    assert report["format"] == "rig-diagnosis/1" and "verdict" in report
    page = client.get(f"/api/campaigns/{cid}/diagnosis.html")
    assert page.status_code == 200 and "<html" in page.text.lower()
    assert report["verdict"] in page.text
    assert "data:image/png;base64," in page.text and "http" not in page.text  # works offline
    assert client.get("/api/campaigns/no-such-campaign").status_code == 404


# --------------------------------------------------------------------------- faults


def test_faults_in_plain_words_keep_the_device_message():
    from drivers.errors import DeviceDisconnected, DeviceFault, DeviceTimeout
    from rig.engine.safety import TorqueLimitExceeded, check_command, check_measured
    from rig.web.faults import explain

    watchdog = DeviceFault("loading drive (Modbus unit 2 on tcp 127.0.0.1:5020)",
                           "a normal reply", "drive fault code 2 WATCHDOG_TIMEOUT")
    heartbeat = DeviceDisconnected("encoder node 1 on slcan socket://127.0.0.1:9",
                                   "a heartbeat within 0.6 s", "none for 1.2 s (heartbeat lost)")
    trip = check_measured(25.0, 20.0, "torque transducer")
    with pytest.raises(TorqueLimitExceeded) as refused:
        check_command(30.0, 20.0)
    silent = DeviceTimeout("torque transducer on /dev/pts/3", "a sample within 0.5 s", "none")
    cases = [
        ("E-stop: E-stop pressed on the control page", "E-stop pressed"),
        ("aborted by the operator", "Stopped by the operator"),
        (str(watchdog), "communication watchdog"),
        (str(heartbeat), "heartbeat lost"),
        (trip, "Torque beyond the limit"),
        (str(refused.value), "was refused"),
        (str(silent), "torque transducer did not answer"),
        ("something nobody foresaw", "The measurement stopped"),
    ]
    for reason, title in cases:
        fault = explain(reason)
        assert title in fault.title, (reason, fault)
        assert fault.detail == reason and fault.action  # the device's own words are kept
    assert explain(None) is None


def test_campaign_files_by_name_or_upload_never_a_path(client: TestClient):
    """Issue 21 item 17: the rig's example campaigns by name; an upload parsed from its text
    (its unit file never opened, unless it names an example unit); names that try a path,
    unknown names and broken files refused in one line."""
    names = [c["name"] for c in client.get("/api/campaign-files").json()]
    assert "seed000-pair1" in names
    setup = client.get("/api/campaign-files/seed000-pair1").json()
    assert setup["request"]["axes"]["positions_deg"] == [0.0, 90.0, 180.0, 270.0]
    assert setup["request"]["limits"]["lost_motion_arcmin_max"] == 3.0
    assert setup["request"]["unit"]["z_internal"] == UNIT["z_internal"]
    for bad in ("..%2F..%2Fpyproject", "%2Fetc%2Fpasswd", "seed000-pair1.toml", "nope"):
        assert client.get(f"/api/campaign-files/{bad}").status_code in (404, 422), bad
    text = (REPO / "examples" / "campaigns" / "seed000-pair3.toml").read_text()
    up = client.post("/api/campaign-upload", json={"file_name": "../x/p3.toml",
                                                        "text": text}).json()
    assert up["source"] == "p3.toml" and up["request"]["unit"]["center_distance_mm"] > 2.5
    secret = text.replace("../../rig/examples/units/seed000-pair3.json", "/etc/passwd")
    up = client.post("/api/campaign-upload", json={"file_name": "s.toml", "text": secret})
    assert up.status_code == 200 and up.json()["request"]["unit"] is None
    assert "not read from an uploaded file" in " ".join(up.json()["notes"])
    bad = client.post("/api/campaign-upload", json={"file_name": "b.toml",
                                                         "text": "name = 'b'\n[plan\n"})
    assert bad.status_code == 400 and bad.json()["detail"].startswith("b.toml:2:")
    bad = client.post("/api/campaign-upload", json={
        "file_name": "c.toml", "text": text.replace("rated_torque_Nm = 10.0",
                                                    "rated_torque_Nm = -1")})
    assert bad.status_code == 400
    assert bad.json()["detail"] == "c.toml: plan.rated_torque_Nm: expected greater than 0 " \
                                   "and at most 1e+07 N·m (got -1)"  # rig/core/ranges.py


@pytest.mark.parametrize("change,field,echo", [
    ({"operator": None}, "operator", "got none"),
    ({"operator": "   "}, "operator", 'got "   "'),
    ({"operator": "Ann\n<b>x</b>\u0007"}, "operator", r'got "Ann\n<b>x</b>\u0007"'),
    ({"unit": {k: v for k, v in UNIT.items() if k != "serial"}}, "unit.serial", "got none"),
])
def test_start_needs_the_operator_and_the_units_serial(client: TestClient, change: dict,
                                                       field: str, echo: str):
    """Issue 33 item 9: no part result without who measured which part; the API (not only
    the page) refuses a start without either, in one line naming the field, what it echoes
    escaped (a newline or a bell never breaks the line)."""
    r = client.post("/api/control/start", json={**run_request(), **change}, headers=AUTH)
    assert r.status_code == 400, r.text
    detail = r.json()["detail"]
    assert isinstance(detail, str) and "\n" not in detail and "\u0007" not in detail, detail
    assert detail.startswith(field + ": expected "), detail
    assert detail.endswith(echo), detail
    # with both given, the start gets past them (refused only because no rig is connected)
    r = client.post("/api/control/start", json=run_request(), headers=AUTH)
    assert r.status_code == 409 and "no rig" in r.json()["detail"], r.text
