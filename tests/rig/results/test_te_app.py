"""Transmission error runs in the application (issue 22 item 5, all but the page): rig analyse,
the Python API, the verdict with its limits, campaign files, the certificate, SPC, export, and
the encoder eccentricity calibration. TE runs come from tests/support/te_runs.py (numerics only)."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import rig
from rig.plans.campaign_file import CampaignError, campaign_from_mapping
from rig.results.outcome import run_outcome
from rig.results.te import analyse_te_run, reversal_calibration
from rig.runformat import read_run, write_run
from tests.support.te_runs import SEED000_UNIT, store_te_unit, te_run, truth_pp_arcsec, write_te_run

RIG = [sys.executable, "-c", "from rig.cli import main; main()"]
TE_METRICS = ("te_pp_arcsec", "te_pp_forward_arcsec", "te_pp_reverse_arcsec",
              "te_total_Fi_arcsec", "te_tooth_fi_arcsec", "te_hysteresis_arcmin")


def _rig(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "COLUMNS": "80"}  # an 80-column terminal (piped: 120 without it)
    return subprocess.run([*RIG, *args], capture_output=True, text=True, timeout=300, cwd=cwd,
                          env=env)


@pytest.fixture(scope="module")
def te_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_te_run(tmp_path_factory.mktemp("te") / "te-1", run_id="te-1")


def test_rig_analyse_json_of_a_te_run(te_folder: Path, tmp_path: Path) -> None:
    out = tmp_path / "te.json"
    res = _rig("analyse", str(te_folder), "--json", str(out), "--plot", str(tmp_path / "te.png"))
    assert res.returncode == 0, res.stderr
    assert "Transmission error" in res.stdout and "F'i (ISO 1328)" in res.stdout
    assert "…" not in res.stdout and max(map(len, res.stdout.splitlines())) <= 80
    d = json.loads(out.read_text())
    assert d["test_kind"] == "transmission_error"
    m = d["metrics"]
    for key in TE_METRICS:
        assert isinstance(m[key], float) and isinstance(m[f"{key}_u"], float), key
        assert key in d["model"], key
    assert m["te_pp_arcsec"] == max(m["te_pp_forward_arcsec"], m["te_pp_reverse_arcsec"])
    for entry in m["te_orders"]:
        assert {"order", "per", "amplitude_arcsec", "phase_deg", "direction"} <= set(entry)
        assert entry["per"] in ("output_rev", "input_rev", "crank", "mesh")
    assert len(m["te_orders_u"]) == len(m["te_orders"])
    assert {"order", "per", "amplitude_arcsec"} <= set(d["model"]["te_orders"][0])
    # the generator's truth: peak-to-peak within 5 %, the ring's eccentricity order found
    assert m["te_pp_arcsec"] == pytest.approx(truth_pp_arcsec(), rel=0.05)
    ring = next(o for o in m["te_orders"] if o["per"] == "input_rev" and o["order"] == 1
                and o["direction"] == "forward")
    model_ring = next(o for o in d["model"]["te_orders"] if o["per"] == "input_rev"
                      and o["order"] == 1 and o["direction"] == "forward")
    assert ring["amplitude_arcsec"] == pytest.approx(model_ring["amplitude_arcsec"], rel=0.1)
    assert d["comparison"]["flagged"] == []
    assert d["encoder_eccentricity"]["removed"] is False
    assert (tmp_path / "te.png").stat().st_size > 10_000


def test_run_te_is_a_dataframe_and_rig_analyse_the_cli_json(te_folder: Path) -> None:
    run = rig.open(te_folder)
    frame = run.te()
    assert list(frame.columns) == ["output_angle_deg", "te_forward_arcsec",
                                   "te_reverse_arcsec"]
    assert frame["output_angle_deg"].is_monotonic_increasing
    assert frame["output_angle_deg"].iloc[-1] < 360.0
    d = rig.analyse(run).to_dict()
    # one revolution each way: F_is is that revolution's max - min, less the noise's bias on
    # an extreme (issue 32: te_evaluation says how much was taken away)
    removed = d["te_evaluation"]["noise_bias_removed_arcsec"]
    assert d["metrics"]["te_total_Fi_arcsec"] == pytest.approx(max(
        np.ptp(frame[f"te_{name}_arcsec"]) - removed[f"te_total_Fi_{name}_arcsec"]
        for name in ("forward", "reverse")))
    assert rig.analyse(te_folder).to_dict()["metrics"] == d["metrics"]
    row = run.results().iloc[0]
    assert row["test_kind"] == "transmission_error"
    assert row["te_pp_arcsec"] == pytest.approx(d["metrics"]["te_pp_arcsec"])
    assert row["verdict"] == "NO LIMITS"


@pytest.mark.parametrize(("value", "limits", "expected"), [
    (250.0, {"te_pp_max_arcsec": 300.0}, "ok"),
    (350.0, {"te_pp_max_arcsec": 300.0}, "not_ok"),
    (math.nan, {"te_pp_max_arcsec": 300.0}, "incomplete"),
    (None, {"te_pp_max_arcsec": 300.0}, "incomplete"),
    (250.0, {"te_hysteresis_max_arcmin": 4.0}, "not_ok"),
    (250.0, {"lost_motion_arcmin_max": 3.0}, "no_limits"),  # the loop's limit: not a TE's
    (250.0, {"lost_motion_arcmin_max": 3.0, "te_pp_max_arcsec": 300.0}, "ok"),
])
def test_outcome_of_a_te_run_against_its_limits(value, limits, expected) -> None:
    record = {"status": "completed", "test": {"kind": "transmission_error"},
              "result": {"te_pp_arcsec": value, "te_hysteresis_arcmin": 4.5}}
    assert run_outcome(record, limits)[0] == expected


def test_te_limits_do_not_apply_to_a_hysteresis_run() -> None:
    loop = {"status": "completed", "test": {"rated_torque_Nm": 10.0},
            "result": {"lost_motion_arcmin": 2.0}}
    assert run_outcome(loop, {"te_pp_max_arcsec": 60.0})[0] == "no_limits"
    assert run_outcome(loop, {"te_pp_max_arcsec": 60.0, "lost_motion_arcmin_max": 1.0}
                       )[0] == "not_ok"


def test_campaign_file_limit_keys() -> None:
    base = {"name": "te", "unit": {**SEED000_UNIT, "serial": "X"},
            "plan": {"rated_torque_Nm": 10.0}}
    camp = campaign_from_mapping({**base, "limits": {"te_pp_max_arcsec": 60.0,
                                                     "te_hysteresis_max_arcmin": 1.0}})
    assert camp.limits.te_pp_max_arcsec == 60.0
    assert camp.limits.te_hysteresis_max_arcmin == 1.0
    assert camp.limits.outcome({"status": "completed", "test": {"kind": "transmission_error"},
                                "result": {"te_pp_arcsec": 61.0, "te_hysteresis_arcmin": 0.5}}
                               ) == "not_ok"
    with pytest.raises(CampaignError, match="te_pp_max_arcsec"):
        campaign_from_mapping({**base, "limits": {"te_pp_max_arcsec": -1.0}})


def test_certificate_of_a_te_run_has_its_section_on_one_page(tmp_path: Path) -> None:
    folder = write_te_run(tmp_path / "te-cert", run_id="te-cert",
                          limits={"te_pp_max_arcsec": 200.0, "te_hysteresis_max_arcmin": 6.0})
    res = _rig("certificate", str(folder), "--pdf", str(tmp_path / "c.pdf"), "--html",
               str(tmp_path / "c.html"))
    assert res.returncode == 0, res.stderr
    assert "NOT OK" in res.stdout  # its ~286 arcsec is above the 200 arcsec limit
    page = (tmp_path / "c.html").read_text()
    assert "transmission error of a gear reducer" in page
    assert "Transmission error against the output angle" in page
    assert "≤ 200 arcsec" in page and "F&#39;i, total single-flank composite" in page
    assert page.count("data:image/svg+xml") == 1
    info = subprocess.run(["pdfinfo", str(tmp_path / "c.pdf")], capture_output=True, text=True)
    assert "Pages:           1" in info.stdout


def test_certificate_of_a_te_campaign(tmp_path: Path) -> None:
    from rig.runformat import Campaign, write_campaign

    runs = [te_run("te-a", samples_per_output_rev=4000),
            te_run("te-b", scale=1.6, samples_per_output_rev=4000, seed=1)]
    folder = write_campaign(Campaign(meta={"name": "te-camp", "status": "completed",
                                           "unit": runs[0].unit,
                                           "limits": {"te_pp_max_arcsec": 350.0}},
                                     runs=runs), tmp_path / "te-camp")
    res = _rig("certificate", str(folder), "--pdf", str(tmp_path / "c.pdf"), "--html",
               str(tmp_path / "c.html"))
    assert res.returncode == 0, res.stderr
    assert "NOT OK" in res.stdout  # te-b's eccentricities 1.6 times pair 1's: above 350
    page = (tmp_path / "c.html").read_text()
    assert "transmission error of a gear reducer, campaign of 2 runs" in page
    assert "Transmission error against the output angle" in page
    assert "Lost motion against input position" not in page
    assert "te-a" in page and "te-b" in page and "limit ≤ 350 arcsec" in page
    assert "not applicable" not in page
    info = subprocess.run(["pdfinfo", str(tmp_path / "c.pdf")], capture_output=True, text=True)
    assert "Pages:           1" in info.stdout


def test_spc_charts_te_peak_to_peak(tmp_path: Path) -> None:
    from rig.reports.spc import spc_report
    from rig.store import Store

    st = Store(tmp_path / "store")
    scales = [1.0, 1.1, 0.9, 1.3, 1.05]
    for k, scale in enumerate(scales):
        store_te_unit(st, f"T-{k}", scale=scale, limits={"te_pp_max_arcsec": 320.0}, seed=k)
    (d,) = spc_report(st)["designs"]
    te = d["metrics"]["te_pp_arcsec"]
    values = [p["value"] for p in te["points"]]
    assert len(values) == 5 and values[3] == max(values)
    assert te["usl"] == 320.0
    assert [p["verdict"] for p in te["points"]][3] == "NOT OK"
    assert te["chart"]["individuals"]["centre"] == pytest.approx(np.mean(values))
    assert d["metrics"]["lost_motion_arcmin"]["points"] == []
    from rig.reports.spc.html import render_html

    page = render_html(spc_report(st))
    assert 'data-metric="te_pp_arcsec"' in page and page.count("data:image/png;base64,") == 1


def test_export_of_a_te_run_round_trips(te_folder: Path, tmp_path: Path) -> None:
    res = _rig("export", str(te_folder), "--format", "csv", "--out", str(tmp_path / "exp"))
    assert res.returncode == 0, res.stderr
    orig, back = read_run(te_folder), read_run(tmp_path / "exp")
    assert back.columns == [*orig.columns, "te_arcsec", "twist_arcmin"]
    for c in orig.columns:
        assert np.array_equal(orig.data[c], back.data[c], equal_nan=True), c
    assert back.meta["test"] == orig.meta["test"]
    te = back.data["te_arcsec"]
    moving = back.data["direction"] != 0
    assert np.isnan(te[~moving]).all() and np.isfinite(te[moving]).all()
    a, b = analyse_te_run(orig, with_model=False), analyse_te_run(back, with_model=False)
    assert a.metrics_dict() == b.metrics_dict()
    res = _rig("export", str(te_folder), "--format", "parquet", "--out",
               str(tmp_path / "te.parquet"))
    assert res.returncode == 0, res.stderr
    import pyarrow.parquet as pq

    table = pq.read_table(tmp_path / "te.parquet")
    assert json.loads(table.schema.metadata[b"run.json"])["test"]["kind"] == \
        "transmission_error"
    assert np.array_equal(table["te_arcsec"].to_numpy(), te, equal_nan=True)


def test_te_calibrate_refuses_one_run_given_twice(tmp_path: Path) -> None:
    """Issue 33 item 11: ``rig te-calibrate RUN RUN`` exited 0 and printed an eccentricity
    "to add" from one run given twice (or a copy of it): the second run has to be the
    coupling indexed by 180 deg, another measurement. One line, exit 2, nothing printed."""
    write_run(te_run("a", index_deg=0.0, ecc_arcsec=20.0, ecc_phase_deg=50.0), tmp_path / "a")
    copy = tmp_path / "copy"
    shutil.copytree(tmp_path / "a", copy)
    for second in (tmp_path / "a", tmp_path / "." / "a", copy):
        res = _rig("te-calibrate", str(tmp_path / "a"), str(second), "--json", "-")
        assert res.returncode == 2, res.stdout + res.stderr
        (line,) = res.stderr.strip().splitlines()
        assert line.startswith("rig: error: ") and "the same run" in line, line
        assert "indexed by 180" in line and "[calibration.encoder]" not in res.stderr
        assert res.stdout == ""


def test_te_calibrate_checks_the_second_run_is_indexed_by_180_deg(tmp_path: Path) -> None:
    """Issue 33 item 11: the second run has to be indexed by 180 deg, and te-calibrate checks
    it: runs record where the coupling was (test.coupling_index_deg, ``rig measure
    --coupling-index-deg``); 90 deg apart is refused, and so are runs that record nothing
    unless the operator states the index (``--indexed-by 180``)."""
    ecc = {"ecc_arcsec": 20.0, "ecc_phase_deg": 50.0}
    write_run(te_run("a", index_deg=0.0, **ecc), tmp_path / "a")
    write_run(te_run("b90", index_deg=90.0, seed=1, **ecc), tmp_path / "b90")
    res = _rig("te-calibrate", str(tmp_path / "a"), str(tmp_path / "b90"), "--json", "-")
    assert res.returncode == 2 and res.stdout == "", res.stdout + res.stderr
    (line,) = res.stderr.strip().splitlines()
    assert "indexed by 90 deg; the reversal needs 180 +- 5 deg" in line, line
    for name, index in (("a0", 0.0), ("b0", 180.0)):  # older runs: no index recorded
        run = te_run(name, index_deg=index, seed=int(index), **ecc)
        del run.meta["test"]["coupling_index_deg"]
        write_run(run, tmp_path / name)
    res = _rig("te-calibrate", str(tmp_path / "a0"), str(tmp_path / "b0"), "--json", "-")
    assert res.returncode == 2, res.stdout + res.stderr
    (line,) = res.stderr.strip().splitlines()
    assert "records no coupling index" in line and "--indexed-by 180" in line, line
    res = _rig("te-calibrate", str(tmp_path / "a0"), str(tmp_path / "b0"), "--indexed-by",
               "180", "--json", "-")
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["eccentricity_arcsec"] == pytest.approx(20.0, abs=0.3)


def test_encoder_eccentricity_calibrated_by_reversal_is_removed(tmp_path: Path) -> None:
    """A 20 arcsec encoder-mounting eccentricity: in one run it is the output's order 1; the
    reversal (coupling indexed by 180 deg) finds it, the rig configuration's calibration
    carries it, and a later run's TE no longer shows it."""
    from rig.hardware.calibration import CalibrationEntry

    ecc = {"ecc_arcsec": 20.0, "ecc_phase_deg": 50.0}
    write_run(te_run("a", index_deg=0.0, **ecc), tmp_path / "a")
    write_run(te_run("b", index_deg=180.0, seed=1, **ecc), tmp_path / "b")
    res = _rig("te-calibrate", str(tmp_path / "a"), str(tmp_path / "b"), "--json", "-")
    assert res.returncode == 0, res.stderr
    cal = json.loads(res.stdout)
    assert "[calibration.encoder]" in res.stderr and "eccentricity_arcsec = 20.0" in res.stderr
    assert cal == reversal_calibration(read_run(tmp_path / "a"), read_run(tmp_path / "b"))
    assert cal["eccentricity_arcsec"] == pytest.approx(20.0, abs=0.3)
    assert cal["eccentricity_phase_deg"] == pytest.approx(-40.0, abs=1.0)  # cos(x - 40)
    entry = CalibrationEntry(id="ENC-1", certificate="reversal 2026-11-26", date="2026-11-26",
                             due="2027-11-26", uncertainty="0.2 arcsec",
                             **{k: cal[k] for k in ("eccentricity_arcsec",
                                                    "eccentricity_phase_deg",
                                                    "eccentricity_u_arcsec")})
    record = entry.record("encoder")
    assert record["eccentricity_arcsec"] == cal["eccentricity_arcsec"]

    def order1(item):
        return next(o for o in item.result.orders_list() if o["per"] == "output_rev"
                    and o["order"] == 1 and o["direction"] == "forward")["amplitude_arcsec"]

    raw = analyse_te_run(te_run("c", seed=2, **ecc), with_model=False)
    assert order1(raw) == pytest.approx(20.0, abs=0.5)  # the unit has no order 1 of its own
    folder = write_run(te_run("d", seed=2, calibration=[record], **ecc), tmp_path / "d")
    fixed = analyse_te_run(read_run(folder), with_model=False)
    assert order1(fixed) < 0.5
    assert fixed.result.encoder_eccentricity["removed"] is True
    assert fixed.result.metrics["te_pp_arcsec"] == pytest.approx(truth_pp_arcsec(), rel=0.02)
    removed = raw.te_frame()["te_forward_arcsec"] - fixed.te_frame()["te_forward_arcsec"]
    assert np.ptp(removed) == pytest.approx(40.0, abs=1.0)  # the 20 arcsec sinusoid


def test_reanalyse_of_a_stored_te_run(tmp_path: Path) -> None:
    from rig.store import Store
    from rig.store.reanalyse import plan, run_job

    st = Store(tmp_path / "store")
    store_te_unit(st, "R-1", limits={"te_pp_max_arcsec": 400.0})
    jobs, _ = plan(st)
    (job,) = [j for j in jobs if j.kind == "run"]
    out = run_job(job)
    assert out["status"] == "ok", out["error"]
    recorded = st.list_runs()[0]
    assert out["metrics"]["te_pp_arcsec"] == pytest.approx(
        recorded.metrics["te_pp_arcsec"])
    assert out["metrics"]["encoder_eccentricity"]["removed"] is False


@pytest.mark.parametrize(("change", "message"), [
    (lambda run: run.meta["test"].pop("ratio"), "test.ratio missing"),
    (lambda run: run.meta["test"].update(output_revolutions=0.5), None),
])
def test_bad_te_runs_are_one_line_errors(tmp_path: Path, change, message) -> None:
    run = te_run("bad", samples_per_output_rev=3000)
    change(run)
    if message is None:  # scaled to 0.44 output revolutions each way: too short a TE run
        run.data["input_angle_deg"] = run.data["input_angle_deg"] * 0.4
        run.data["output_angle_deg"] = run.data["output_angle_deg"] * 0.4
        message = "full output revolution"
    folder = write_run(run, tmp_path / "bad")
    res = _rig("analyse", str(folder))
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0] and "bad" in lines[0], res.stderr
