"""`import rig` as users' scripts and notebooks use it (docs/python-api.md): real example
files, the CLI's own JSON to compare with, and a measurement on the simulated rig."""

from __future__ import annotations

import importlib
import json
import subprocess
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pyarrow as pa  # noqa: E402
import pytest  # noqa: E402

import rig  # noqa: E402
from analysis.errors import AnalysisError  # noqa: E402
from rig.core.errors import RigError  # noqa: E402
from rig.runformat import Run as RawRun  # noqa: E402
from rig.runformat import write_run  # noqa: E402
from tests.support.paths import REPO as ROOT

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

EXAMPLES = ROOT / "rig/examples/runs"
CAMPAIGN = EXAMPLES / "campaign-pair1-positions"
UNIT = ROOT / "rig/examples/units/seed000-pair1.json"
RIG = [sys.executable, "-c", "from rig.cli import main; main()"]
TINY = {  # tests/rig/commands/test_measure_cli.py's fast plan, as a mapping
    "name": "tiny",
    "unit": {"file": str(UNIT), "serial": "SN-API-1"},
    "plan": {"rated_torque_Nm": 10.0, "steps_per_quarter": 2, "extra_levels_pct": [3.0],
             "dwell_s": 0.0, "pre_cycles": 0, "zero_band_Nm": 0.3, "zero_rate_Nm_per_s": 0.6},
    "axes": {"positions_deg": [90.0]},
    "limits": {"lost_motion_arcmin_max": 9.0},
}


def _empty_store(tmp_path: Path) -> rig.Store:
    return rig.Store(tmp_path / "empty-store")


CLI_CALLS = {  # the CLI's JSON of the example files, made once, in parallel
    "analyse-run": ("analyse", str(EXAMPLES / "pair3-pos000"), "--profile", "harmonic-drive"),
    "analyse-campaign": ("analyse", str(CAMPAIGN)),
    "diagnose": ("diagnose", str(CAMPAIGN)),
    "model": ("model", str(UNIT)),
}


@pytest.fixture(scope="module")
def cli_json(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict]:
    tmp = tmp_path_factory.mktemp("cli")
    procs = {name: subprocess.Popen([*RIG, *args, "--json", str(tmp / f"{name}.json")],
                                    stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                    text=True, cwd=tmp)
             for name, args in CLI_CALLS.items()}
    for name, proc in procs.items():
        _, err = proc.communicate(timeout=120)
        assert proc.returncode == 0, f"{name}: {err[-2000:]}"
    return {name: json.loads((tmp / f"{name}.json").read_text()) for name in CLI_CALLS}


def test_open_run_gives_samples_with_twist_as_arrow_and_pandas() -> None:
    run = rig.open(EXAMPLES / "pair1-pos000")
    assert isinstance(run, rig.Run) and run.run_id == "pair1-pos000"
    table = run.to_arrow()
    assert isinstance(table, pa.Table)
    assert table.column_names == [*run.columns, "twist_arcmin"]
    assert table.num_rows == run.n_samples == 2850
    # no test.ratio in this run: twist is the output angle alone (input locked), in arcmin,
    # centred on the loop as the loop analysis centres it (issue 21 item 20: not ~7405')
    raw = run.raw.output_angle_deg * 60.0
    low, high = np.percentile(raw, [0.5, 99.5])
    expected = raw - 0.5 * (low + high)
    twist = table.column("twist_arcmin").to_numpy()
    assert np.allclose(twist, expected, rtol=0, atol=1e-9)
    assert np.allclose(twist, run.twist_arcmin, rtol=0, atol=0)
    assert abs(np.percentile(twist, 0.5) + np.percentile(twist, 99.5)) < 1e-9
    assert np.ptp(twist) < 10.0 and abs(float(np.median(twist))) < 5.0
    frame = run.to_pandas()
    assert isinstance(frame, pd.DataFrame) and list(frame.columns) == table.column_names
    assert frame["torque_Nm"].to_numpy().tobytes() == run.raw.torque_Nm.tobytes()


def test_twist_uses_the_ratio_and_text_columns_survive(tmp_path: Path) -> None:
    t = np.arange(50) * 0.01
    raw = RawRun.from_arrays(
        "with-ratio", t, np.sin(t), 10.0 + 0.01 * t, input_angle_deg=300.0 * t,
        test={"rated_torque_Nm": 1.0, "ratio": 100.0},
        extra_columns={"phase": ["a"] * 50})
    folder = write_run(raw, tmp_path / "with-ratio")
    run = rig.open(folder)
    twist = run.to_arrow().column("twist_arcmin").to_numpy()
    raw_twist = (10.0 + 0.01 * t - 300.0 * t / 100.0) * 60.0
    low, high = np.percentile(raw_twist, [0.5, 99.5])
    assert np.allclose(twist, raw_twist - 0.5 * (low + high), atol=1e-9)
    assert run.to_pandas()["phase"].tolist() == ["a"] * 50
    # a bare CSV of samples (another lab's export) opens too, named by its file
    bare = tmp_path / "export.csv"
    bare.write_bytes((folder / "samples.csv").read_bytes())
    assert rig.open(bare).run_id == "export"


def test_campaign_results_one_tidy_row_per_run_equal_to_rig_analyse(cli_json: dict) -> None:
    campaign = rig.open(CAMPAIGN)
    assert isinstance(campaign, rig.Campaign) and len(campaign) == 4
    table = campaign.results()
    cli = cli_json["analyse-campaign"]
    assert list(table["run_id"]) == [r["run_id"] for r in cli["runs"]]
    assert list(table["input_angle_deg"]) == [0.0, 90.0, 180.0, 270.0]
    assert list(table["temperature_C"]) == [21.0] * 4
    for row, doc in zip(table.to_dict("records"), cli["runs"], strict=True):
        for key in ("lost_motion_arcmin", "backlash_arcmin", "stiffness_Nm_per_arcmin",
                    "loop_area_J", "torque_offset_Nm", "stiffness_pos_Nm_per_arcmin"):
            assert row[key] == doc[key], key
            assert row[f"{key}_u"] == doc["uncertainty"][key], key
        assert row["model_lost_motion_arcmin"] == doc["model"]["lost_motion_arcmin"]
        assert row["model_play_arcmin"] == doc["model"]["play_arcmin"]
    for col in ("label", "amplitude_pct", "repeat", "lost_motion_arcmin_max",
                "backlash_arcmin_max", "stiffness_Nm_per_arcmin_min", "outcome"):
        assert col in table.columns, col
    # the generator's truth lies within a few uncertainties of each measured lost motion
    truth = [r.meta["generator"]["true_lost_motion_arcmin"] for r in campaign]
    assert np.all(np.abs(table["lost_motion_arcmin"] - truth) < 0.05)
    # a campaign's samples in one table, run_id first
    samples = campaign.to_pandas()
    assert samples.columns[0] == "run_id" and samples.columns[-1] == "twist_arcmin"
    assert samples.groupby("run_id").size().to_dict() == {r.run_id: r.n_samples for r in campaign}
    assert campaign["pair1-pos090"].results()["lost_motion_arcmin"][0] == table[
        "lost_motion_arcmin"][1]


def test_reports_to_dict_equal_the_cli_json(cli_json: dict) -> None:
    single = EXAMPLES / "pair3-pos000"
    assert rig.analyse(single, profile="harmonic-drive").to_dict() == cli_json["analyse-run"]
    assert rig.open(single).analyse(profile="harmonic-drive").to_dict() == cli_json[
        "analyse-run"]
    campaign = rig.open(CAMPAIGN)
    assert rig.analyse(campaign).to_dict() == cli_json["analyse-campaign"]
    assert rig.analyse(CAMPAIGN).to_dict() == cli_json["analyse-campaign"]
    diagnosis = rig.diagnose(campaign)
    assert diagnosis.to_dict() == cli_json["diagnose"]
    assert diagnosis.verdict == "runout"
    model = rig.model(UNIT)
    assert model.to_dict() == cli_json["model"]
    assert rig.model(json.loads(UNIT.read_text())).to_dict() == model.to_dict()
    assert campaign[0].model().to_dict()["unit"] == rig.model(campaign[0].unit).to_dict()["unit"]


def test_plots_draw_into_the_axes_given_or_a_new_one() -> None:
    campaign = rig.open(CAMPAIGN)
    fig, (left, right) = plt.subplots(1, 2)
    assert campaign[0].plot(ax=left) is left
    assert len(left.lines) >= 2  # measured loop and model loop
    assert campaign.plot_positions(ax=right) is right
    _, ys = right.containers[0].lines[0].get_data()  # the errorbar points: one per run
    assert list(ys) == list(campaign.results()["lost_motion_arcmin"])
    new = campaign.plot()
    assert new is not left and new is not right
    labels = [line.get_label() for line in new.lines]  # the runs by position, the model once
    assert {"0°", "90°", "180°", "270°"} <= set(labels) and labels.count("model") == 1, labels
    plt.close("all")


def test_namespace_exports_and_submodules_stay_reachable() -> None:
    assert {"open", "analyse", "diagnose", "model", "connect", "Store", "Run",
            "Campaign"} <= set(rig.__all__)
    assert rig.Store is importlib.import_module("rig.store").Store
    # rig.analyse / rig.diagnose are the API functions; the services are rig.results' modules
    from rig.results.analyse import analyse_run
    from rig.results.diagnose import diagnose_path

    assert callable(rig.analyse) and rig.analyse.__module__ == "rig.api.reports"
    assert callable(rig.diagnose) and rig.diagnose.__module__ == "rig.api.reports"
    assert importlib.import_module("rig.results.analyse").analyse_run is analyse_run
    assert importlib.import_module("rig.results.diagnose").diagnose_path is diagnose_path
    for name in ("rig", "rig.api", "rig.api.data", "rig.api.reports", "rig.results.table",
                 "rig.store.frame", "rig.api.connect", "rig.api.plots"):
        module = importlib.import_module(name)
        exported = set(module.__all__)
        assert not exported & {"np", "pd", "pa", "dataclass", "Path", "Any"}, name
        for public in exported:
            assert hasattr(module, public), f"{name}.{public}"


def test_bad_input_names_what_is_wrong(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("RIG_STORE", raising=False)
    with pytest.raises(RigError, match="nowhere: no such file or folder, and no store at"):
        rig.open("nowhere")
    with pytest.raises(RigError, match="no run or campaign 'nowhere' in the store"):
        rig.open("nowhere", store=_empty_store(tmp_path))
    with pytest.raises(RigError, match="unknown profile 'bogus'"):
        rig.open(CAMPAIGN).results(profile="bogus")
    with pytest.raises(RigError, match="not both or neither"):
        rig.connect(simulated=True, rig=tmp_path / "rig.toml", store=tmp_path / "s")
    with pytest.raises((RigError, AnalysisError), match="unit: unit key 'z_internal'"):
        rig.model({"kind": "internal_involute", "z_internal": "many"})
    with rig.connect(simulated=True, store=tmp_path / "s") as r, pytest.raises(
            RigError, match="limits.lost_motion_arcmin_max: Input should be greater than 0"):
        r.campaign({**TINY, "limits": {"lost_motion_arcmin_max": -3.0}})


def test_connect_simulated_campaign_measure_and_store_query(tmp_path: Path) -> None:
    events = []
    store = tmp_path / "store"
    with rig.connect(simulated=True, store=store) as r:
        campaign = r.campaign(TINY, progress=events.append)
        single = r.measure(rated_torque_Nm=10.0, steps_per_quarter=2, pre_cycles=0,
                           dwell_s=0.0, zero_rate_Nm_per_s=0.6,
                           limits={"lost_motion_arcmin_max": 1.0})
    kinds = [e.kind for e in events]
    assert kinds[0] == "start" and kinds[-1] == "finished" and "run_finished" in kinds
    # issue 21 item 20: the run_finished event names the run that finished
    (finished,) = [e for e in events if e.kind == "run_finished"]
    assert finished.run_label == "pos090-a100-r0"
    assert finished.run_id == campaign[0].run_id == finished.data["run_id"]
    assert campaign.result["outcome"] == "ok" and campaign.result["failures"] == []
    (row,) = campaign.results().to_dict("records")
    assert row["label"] == "pos090-a100-r0" and row["input_angle_deg"] == 90.0
    assert row["amplitude_pct"] == 100.0 and row["repeat"] == 0
    assert row["lost_motion_arcmin_max"] == 9.0 and row["outcome"] == "ok"
    # no runout in this plant: the measured lost motion is the model's
    assert abs(row["lost_motion_arcmin"] - row["model_lost_motion_arcmin"]) < 0.05
    assert row["lost_motion_arcmin"] == pytest.approx(
        campaign.result["runs"][0]["lost_motion_arcmin"], abs=1e-9)
    # the single run failed its 1' limit: NOT OK, recorded and in the table
    assert single.result["outcome"] == "not_ok" and single.results()["outcome"][0] == "not_ok"
    assert "twist_arcmin" in single.to_pandas().columns
    # the store's history as a DataFrame, filtered like `rig runs`
    st = rig.Store(store)
    every = st.runs()
    assert set(every["run_id"]) == {campaign[0].run_id, single.run_id}
    assert str(every["started_at"].dtype).startswith("datetime64")
    assert list(st.runs(serial="SN-API-1")["run_id"]) == [campaign[0].run_id]
    assert list(st.runs(outcome="not_ok")["run_id"]) == [single.run_id]
    # the displayed words as well as the codes; anything else names the valid values
    assert list(st.runs(outcome="NOT OK")["run_id"]) == [single.run_id]
    assert list(st.runs(outcome="ok")["run_id"]) == [campaign[0].run_id]
    with pytest.raises(ValueError, match="no_limits"):
        st.runs(outcome="FAIL")
    assert st.runs(since="2100-01-01").empty and list(st.runs(since="2000-01-01")["run_id"]) \
        == list(every["run_id"])
    listed = subprocess.run([*RIG, "runs", "--store", str(store), "--json", "-"],
                            capture_output=True, text=True, timeout=60)
    assert [r["run_id"] for r in json.loads(listed.stdout)["runs"]] == list(every["run_id"])
    # open by store id
    assert rig.open(single.run_id, store=store).to_arrow().equals(single.to_arrow())
    assert rig.open(campaign.result["campaign_id"], store=st)[0].run_id == campaign[0].run_id
