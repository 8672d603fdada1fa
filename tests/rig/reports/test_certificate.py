"""The test certificate (issue 11): measured on the simulated rig, certified, read back.

A single run (``rig measure``) and a two-position campaign (``rig campaign run``) are measured
at the same time on two simulated rigs (their own processes, real protocols), then
``rig certificate`` writes PDF and HTML and ``pdftotext`` (poppler-utils, .ci/install) reads
the PDF: serial, operator, outcome word, limits and the measured lost motion must be in it.
"""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from rig.reports.certificate import CertificateError, resolve_subject, write_certificate
from rig.reports.certificate.header import software_version
from tests.support.campaigns import TINY
from tests.support.hostile import page_text
from tests.support.paths import REPO as ROOT

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

RIG = [sys.executable, "-c", "from rig.cli import main; main()"]
UNIT = ROOT / "rig/examples/units/seed000-pair1.json"
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
CAMPAIGN = (TINY.replace("LIMIT", "1.0")
            .replace('name = "tiny"', 'name = "cert"\noperator = "Q. Inspector"')
            .replace("[unit]\n", '[unit]\nserial = "SN-CERT-2"\n')
            .replace("positions_deg = [90.0]", "positions_deg = [0.0, 180.0]"))


def _rig(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([*RIG, *args], capture_output=True, text=True, cwd=cwd, env=ENV,
                          timeout=180)


def _pdf_text(path: Path) -> str:
    if shutil.which("pdftotext") is None:
        pytest.fail("pdftotext not found: install poppler-utils (.ci/install)")
    text = subprocess.run(["pdftotext", str(path), "-"], capture_output=True, text=True,
                          check=True).stdout
    return " ".join(text.split())  # lines wrap where the page's columns end


def _pages(path: Path) -> int:
    info = subprocess.run(["pdfinfo", str(path)], capture_output=True, text=True,
                          check=True).stdout
    return int(re.search(r"^Pages:\s+(\d+)", info, re.M).group(1))


@pytest.fixture(scope="module")
def measured(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """One run (limits 9' lost motion, 8' backlash: OK) and a campaign at 0 and 180 deg
    (limit 1': NOT OK), measured one after the other."""
    tmp = tmp_path_factory.mktemp("cert")
    (tmp / "camp.toml").write_text(CAMPAIGN)
    run_cmd = ["measure", "--simulated", "--unit", str(UNIT), "--serial", "SN-CERT-1",
               "--rated-torque", "10", "--steps", "2", "--pre-cycles", "0",
               "--max-lost-motion", "9", "--max-backlash", "8", "--store", str(tmp / "s1"),
               "--json", str(tmp / "run.json")]
    camp_cmd = ["campaign", "run", str(tmp / "camp.toml"), "--simulated", "--store",
                str(tmp / "s2"), "--json", str(tmp / "camp.json")]
    procs, outs = [], []
    for cmd in (run_cmd, camp_cmd):  # one simulated rig at a time: a loaded CI box
        procs.append(subprocess.Popen([*RIG, *cmd], cwd=tmp, env=ENV, stdout=subprocess.PIPE,
                                      stderr=subprocess.STDOUT, text=True))
        outs.append(procs[-1].communicate(timeout=180)[0])
    assert procs[0].returncode == 0, outs[0][-2000:]
    assert procs[1].returncode == 1, outs[1][-2000:]  # NOT OK against 1 arcmin
    return {"tmp": tmp, "run": json.loads((tmp / "run.json").read_text()),
            "campaign": json.loads((tmp / "camp.json").read_text())}


def test_run_certificate_by_store_id(measured: dict):
    tmp, run = measured["tmp"], measured["run"]
    assert run["outcome"] == "ok"
    res = _rig("certificate", run["run_id"], "--store", str(tmp / "s1"), "--pdf",
               str(tmp / "run.pdf"), "--html", str(tmp / "run.html"), cwd=tmp)
    assert res.returncode == 0, res.stderr
    assert "(unit SN-CERT-1): OK" in res.stdout
    text = _pdf_text(tmp / "run.pdf")
    assert _pages(tmp / "run.pdf") == 1
    assert "SN-CERT-1" in text and run["run_id"] in text
    assert re.search(r"\bOK\b", text) and "NOT OK" not in text and "INCOMPLETE" not in text
    lm, u = run["lost_motion_arcmin"], run["uncertainty"]["lost_motion_arcmin"]
    assert f"{lm:.3f} ± {u:.3f} arcmin" in text
    assert f"{run['backlash_arcmin']:.3f} ± {run['uncertainty']['backlash_arcmin']:.3f}" in text
    assert "≤ 9 arcmin" in text and "≤ 8 arcmin" in text
    assert "Operator" in text and "not recorded" in text  # no --operator given
    assert f"backlash-rig {software_version()}" in text and "simulated" in text  # the rig
    assert "encoder_counts_per_rev" in text and "8388608" in text  # the sensors
    page = (tmp / "run.html").read_text()
    assert "data:image/svg+xml;base64," in page  # the loop, inline
    assert not re.search(r"(src|href)=\"?https?:", page)  # self-contained


def test_campaign_certificate_with_position_band_and_diagnosis(measured: dict):
    tmp, camp = measured["tmp"], measured["campaign"]
    folder = Path(camp["path"])
    res = _rig("certificate", str(folder), "--pdf", str(tmp / "camp.pdf"), cwd=tmp)
    assert res.returncode == 0, res.stderr
    text = _pdf_text(tmp / "camp.pdf")
    assert _pages(tmp / "camp.pdf") == 1
    assert "SN-CERT-2" in text and "Q. Inspector" in text and "NOT OK" in text
    assert "≤ 1 arcmin" in text
    assert len(camp["runs"]) == 2
    for r in camp["runs"]:
        assert f"{r['lost_motion_arcmin']:.3f} ± {r['uncertainty']['lost_motion_arcmin']:.3f}" \
            in text
    assert "Lost motion against input position" in text
    low, high = camp["batch"]["band_95_arcmin"]
    assert f"{low:.3f} .. {high:.3f} arcmin" in text
    assert f"{camp['model']['lost_motion_arcmin']:.3f}" in text  # the nominal model
    assert "Diagnosis:" not in text  # none was made yet

    res = _rig("diagnose", str(folder), "--json", str(folder / "diagnosis.json"), "--html",
               str(tmp / "diag.html"), cwd=tmp)
    assert res.returncode == 0, res.stderr
    report = json.loads((folder / "diagnosis.json").read_text())
    page = (tmp / "diag.html").read_text()  # the diagnosis page has the same header
    assert 'class="cert-head"' in page
    assert "SN-CERT-2" in page_text(page) and "Q. Inspector" in page_text(page)
    # by its id in the store (in this process: the command line was run above)
    write_certificate(resolve_subject(camp["campaign_id"], tmp / "s2"), pdf=tmp / "camp2.pdf")
    text = _pdf_text(tmp / "camp2.pdf")
    assert f"Diagnosis: {report['verdict']}" in text


def test_certificate_from_the_page(measured: dict):
    from fastapi.testclient import TestClient

    from rig.store import Store
    from rig.web import create_app
    from rig.web.settings import resolve_settings

    tmp, run = measured["tmp"], measured["run"]
    store = Store(tmp / "s1")
    app = create_app(resolve_settings(store_root=store.root, token="cert-operator"),
                     store=store)
    with TestClient(app) as client:
        pdf = client.get(f"/api/runs/{run['run_id']}/certificate.pdf")
        assert pdf.status_code == 200, pdf.text
        assert pdf.headers["content-type"] == "application/pdf"
        (tmp / "web.pdf").write_bytes(pdf.content)
        assert "SN-CERT-1" in _pdf_text(tmp / "web.pdf")
        page = client.get(f"/api/runs/{run['run_id']}/certificate.html")
        assert page.status_code == 200 and "SN-CERT-1" in page.text
        assert client.get("/api/runs/no-such-run/certificate.pdf").status_code == 404
        assert client.get("/api/campaigns/no-such/certificate.html").status_code == 404
        js = client.get("/static/app.js")
        assert js.status_code == 200 and "/certificate.pdf" in js.text
        # History links the HTML certificate too (issue 21 item 13), for runs and campaigns
        assert "/api/runs/${id}/certificate.html" in js.text
        assert "/api/campaigns/${id}/certificate.html" in js.text


@pytest.mark.parametrize(("args", "message"), [
    (["no-such-run", "--pdf", "x.pdf"], "no run or campaign with that id"),
    (["RUN"], "give --pdf FILE and/or --html FILE"),
])
def test_bad_argument_is_one_line_exit_2(measured: dict, args: list[str], message: str):
    tmp = measured["tmp"]
    args = [measured["run"]["run_id"] if a == "RUN" else a for a in args]
    res = _rig("certificate", *args, "--store", str(tmp / "s1"), cwd=tmp)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], res.stderr


@pytest.mark.parametrize(("target", "message"), [
    ("../outside", "no such run or campaign folder (and not a run or campaign id)"),
    ("s1", "not a run folder (no run.json) or a campaign folder (no campaign.json)"),
])
def test_a_target_that_is_neither_folder_nor_id_is_named(measured: dict, target: str,
                                                         message: str, monkeypatch):
    monkeypatch.chdir(measured["tmp"])
    with pytest.raises(CertificateError, match=re.escape(f"{target}: {message}")):
        resolve_subject(target, measured["tmp"] / "s1")


def test_calibration_operator_and_an_aborted_run(measured: dict):
    """What the record adds is shown: calibration references (list or per-sensor mapping, past
    due flagged), the operator; an aborted run is INCOMPLETE with its reason."""
    tmp, run = measured["tmp"], measured["run"]
    folder = tmp / "edited"
    shutil.copytree(run["path"], folder)
    meta = json.loads((folder / "run.json").read_text())
    meta["operator"] = "B. Tester"
    meta["calibration"] = [{"sensor": "torque_transducer", "id": "TT-12",
                            "certificate": "DAkkS D-K-1234 2026-17", "date": "2025-06-01",
                            "due": "2026-06-01", "uncertainty": "0.05 % of full scale"}]
    (folder / "run.json").write_text(json.dumps(meta))
    context = write_certificate(resolve_subject(str(folder), tmp / "s1"),
                                html=tmp / "edited.html")
    page = page_text((tmp / "edited.html").read_text())
    assert context["outcome_word"] == "OK" and "B. Tester" in page
    for text in ("TT-12", "DAkkS D-K-1234 2026-17", "2026-06-01", "0.05 % of full scale",
                 "calibration of sensor 'torque_transducer' was past due"):
        assert text in page, text
    meta["calibration"] = {"output_encoder": {"certificate": "ENC-7", "due": "2099-01-01"}}
    meta.update(status="aborted", reason="E-stop pressed", outcome="incomplete")
    del meta["result"]
    (folder / "run.json").write_text(json.dumps(meta))
    context = write_certificate(resolve_subject(str(folder), tmp / "s1"),
                                html=tmp / "aborted.html")
    page = page_text((tmp / "aborted.html").read_text())
    assert context["outcome_word"] == "INCOMPLETE"
    assert "E-stop pressed" in page and "not measured" in page and "ENC-7" in page
    assert "past due" not in page


def test_a_nan_metric_is_never_certified_ok_and_no_limits_is_no_verdict(measured: dict):
    """Issue 21 items 3 and 13: a stored result with lost_motion_arcmin NaN against a 3'
    limit (recorded "ok" by the writer) is INCOMPLETE, never OK; a run without limits (as an
    older version recorded it, "ok") says NO LIMITS / "no limits set" and no OK anywhere."""
    import rig

    tmp, run = measured["tmp"], measured["run"]
    nan_folder, free_folder = tmp / "nan-run", tmp / "no-limits-run"
    for folder in (nan_folder, free_folder):
        shutil.copytree(run["path"], folder)
    meta = json.loads((nan_folder / "run.json").read_text())
    meta["unit"]["serial"] = "Q1"
    meta["result"]["lost_motion_arcmin"] = float("nan")
    meta["limits"] = {"lost_motion_arcmin_max": 3.0, "backlash_arcmin_max": None,
                      "stiffness_Nm_per_arcmin_min": None}
    meta["outcome"] = "ok"
    (nan_folder / "run.json").write_text(json.dumps(meta))  # NaN, as the file held it
    res = _rig("certificate", str(nan_folder), "--pdf", str(tmp / "nan.pdf"), cwd=tmp)
    assert res.returncode == 0, res.stderr
    assert "(unit Q1): INCOMPLETE" in res.stdout, res.stdout
    text = _pdf_text(tmp / "nan.pdf")
    assert "INCOMPLETE" in text and "not a number" in text
    assert "lost_motion_arcmin = nan is not a finite number" in text
    assert not re.search(r"\bOK\b", text.replace("NOT OK", "")), text
    assert rig.open(nan_folder).results()["verdict"][0] == "INCOMPLETE"

    meta = json.loads((free_folder / "run.json").read_text())
    meta["limits"] = {key: None for key in meta["limits"]}
    meta["outcome"] = "ok"  # as the page recorded a run without limits before "no_limits"
    (free_folder / "run.json").write_text(json.dumps(meta))
    res = _rig("certificate", str(free_folder), "--pdf", str(tmp / "free.pdf"), cwd=tmp)
    assert res.returncode == 0, res.stderr
    assert "): NO LIMITS\n" in res.stdout, res.stdout
    text = _pdf_text(tmp / "free.pdf")
    assert _pages(tmp / "free.pdf") == 1
    assert "NO LIMITS" in text and "no limits set" in text
    assert not re.search(r"\bOK\b", text), text  # neither OK nor NOT OK
    results = rig.open(free_folder).results()
    assert (results["outcome"][0], results["verdict"][0]) == ("no_limits", "NO LIMITS")


# --------------------------------------------------------------------------- issue 21 item 13

A4_WIDTH_PT, MARGIN_PT = 595.28, 11 / 25.4 * 72  # @page margin 10mm 11mm (certificate.html)
CALIBRATION = [
    {"sensor": "transducer", "id": "T40B-123456-ABCDEFGH", "certificate":
     "DAkkS D-K-15070-01-00 2026-0881", "date": "2025-01-15", "due": "2026-01-15",
     "uncertainty": "0.05 % of full scale (k = 2)"},
    {"sensor": "output_encoder", "id": "RESOLUTE-RA26BTA-SN0123456789",
     "certificate": "PTB 5.22-2025-4411", "date": "2025-06-01", "due": "2027-06-01",
     "uncertainty": "±0.5 arcsec"},
    {"sensor": "input_encoder", "id": "ECN-1313-SN98765", "certificate":
     "DAkkS D-K-15070 2026-990", "date": "2026-02-01", "due": "2027-02-01",
     "uncertainty": 0.0003},
    {"sensor": "torque_sensor", "id": "TS-70-000042", "certificate": "ISO 17025 LAB-77 2026/12",
     "date": "2026-03-10", "due": "2027-03-10", "uncertainty": "0.1 % FS"},
]
OVERRIDE_REASON = ("transducer is back from the lab on 2026-12-03; checked against the "
                   "reference transducer T40B-999 this morning, within 0.02 % at 10 N·m")


def _words(pdf: Path) -> list[tuple[str, float, float, float]]:
    """(word, xMin, xMax, yMin) of every word pdftotext finds on the page(s)."""
    out = subprocess.run(["pdftotext", "-bbox", str(pdf), "-"], capture_output=True,
                         text=True, check=True).stdout
    return [(html.unescape(w), float(x0), float(x1), float(y0)) for x0, y0, x1, w in
            re.findall(r'<word xMin="([\d.]+)" yMin="([\d.]+)" xMax="([\d.]+)" '
                       r'yMax="[\d.]+">(.*?)</word>', out)]


def _assert_laid_out(pdf: Path) -> str:
    """One A4 page, nothing beyond its margins, no word broken at a hyphen (a word ending in
    "-" at a line's end: pdftotext would then drop the hyphen); returns the page's text."""
    assert _pages(pdf) == 1
    words = _words(pdf)
    assert words
    off = [w for w in words if w[2] > A4_WIDTH_PT - MARGIN_PT + 0.5 or w[1] < MARGIN_PT - 0.5]
    assert not off, f"beyond the page's margins: {off}"
    broken = [w[0] for w in words if w[0].endswith("-") and w[0] != "-"]
    assert not broken, f"words broken at a hyphen: {broken}"
    return _pdf_text(pdf)


def _probe(measured: dict, name: str, **changes) -> tuple[Path, dict]:
    """The measured run's folder copied and its run.json changed; its certificate as PDF."""
    tmp, run = measured["tmp"], measured["run"]
    folder = tmp / name
    shutil.rmtree(folder, ignore_errors=True)  # a rerun of the test finds its first try's copy
    shutil.copytree(run["path"], folder)
    meta = json.loads((folder / "run.json").read_text())
    for key, value in changes.items():
        if value is None:
            meta.pop(key, None)
        elif isinstance(value, dict) and isinstance(meta.get(key), dict):
            meta[key] = {**meta[key], **value}
        else:
            meta[key] = value
    (folder / "run.json").write_text(json.dumps(meta))
    write_certificate(resolve_subject(str(folder), tmp / "s1"), pdf=tmp / f"{name}.pdf")
    return tmp / f"{name}.pdf", meta


def test_calibration_fields_and_override_reason_complete_on_one_page(measured: dict):
    """Four calibrated sensors, one expired and used with an override reason, a long serial,
    design and operator: one A4 page, and every calibration field (sensor, id, certificate,
    calibrated, due, uncertainty), the past-due line and the override reason complete on it."""
    pdf, meta = _probe(
        measured, "calibrated", calibration=CALIBRATION, operator="Bartholomew Fitzgerald-Smith",
        unit={"serial": "SN-2026-LINE-B-0000001234", "design":
              "RV-320E-171.5 CRB long-life variant for welding robots"},
        calibration_override={"reason": OVERRIDE_REASON, "operator": "B. Tester",
                              "time": "2026-11-26T08:00:00Z",
                              "expired": ["calibration of transducer expired on 2026-01-15"]})
    text = _assert_laid_out(pdf)
    for entry in CALIBRATION:
        for key in ("sensor", "id", "certificate", "date", "due", "uncertainty"):
            shown = f"{entry[key]:g}" if isinstance(entry[key], float) else entry[key]
            assert shown in text, (key, shown)
    assert (f"calibration of sensor 'transducer' was past due at the start of the run (due "
            f"2026-01-15, run started {meta['started_at'][:10]})") in text
    assert f"reason: {OVERRIDE_REASON}" in text
    assert "Calibration override by B. Tester, 2026-11-26 08:00:00 UTC" in text
    for whole in ("SN-2026-LINE-B-0000001234", "RV-320E-171.5 CRB long-life variant for "
                  "welding robots", "Bartholomew Fitzgerald-Smith", meta["run_id"]):
        assert whole in text, whole


def test_header_box_holds_simulated_and_not_recorded(measured: dict):
    """A simulated run with no operator, design or software version recorded: "simulated"
    and each "not recorded" stand whole on one line inside the header box (the page's
    margins), the page is one A4 page."""
    pdf, _ = _probe(measured, "unrecorded", operator=None, software_version=None,
                    rig_id="simulated")
    _assert_laid_out(pdf)
    words = _words(pdf)
    nots = [(i, w) for i, w in enumerate(words) if w[0] == "not" and i + 1 < len(words)
            and words[i + 1][0] == "recorded"]
    assert len(nots) >= 3  # design, operator, measured with
    for i, w in nots:
        assert abs(words[i + 1][3] - w[3]) < 1.0, "'not recorded' broken over two lines"
    assert any(w[0] == "simulated" for w in words)


def test_a_metric_below_zero_is_never_printed_as_a_measurement(measured: dict):
    """Issue 21 item 15: a loop area of -4.58e-06 ± 1.36e-05 J reads "below resolution
    (< 0.027 mJ)" (U = 2u, in mJ as issue 33 item 19 shows it); one far below zero "below
    zero: no measurement"."""
    run = measured["run"]
    pdf, _ = _probe(measured, "below-zero", result={
        "loop_area_J": -4.58e-06,
        "uncertainty": {**run["uncertainty"], "loop_area_J": 1.36e-05}})
    text = _assert_laid_out(pdf)
    assert "below resolution (< 0.027 mJ)" in text
    assert "-4.58e-06" not in text and "4.58e-06" not in text and "-0.005" not in text
    assert "a value below zero is no measurement" in text
    from rig.reports.certificate import below_zero_text

    assert below_zero_text("lost_motion_arcmin", -0.5, 0.01, ".3f", " arcmin") == \
        "below zero: no measurement"
    assert below_zero_text("lost_motion_arcmin", -0.01, 0.01, ".3f", " arcmin") == \
        "below resolution (< 0.020 arcmin)"
    assert below_zero_text("torque_offset_Nm", -0.5, 0.01, ".4f", " N·m") is None
    assert below_zero_text("loop_area_J", 0.0, 0.01, ".3g", " J") is None


def test_an_imported_run_without_limits_reads_no_limits(measured: dict, tmp_path: Path):
    """A run exported and imported into a store (no outcome and no limits recorded by the
    import): its certificate says NO LIMITS / "no limits set", never OK, on one page."""
    tmp, run = measured["tmp"], measured["run"]
    work = tmp_path  # not under tmp: it holds run.json (rig measure --json), a run folder
    res = _rig("export", run["run_id"], "--store", str(tmp / "s1"), "--format", "csv",
               "--out", str(work / "exported"), cwd=work)
    assert res.returncode == 0, res.stderr
    (work / "map.toml").write_text('[columns]\nt_s = "t_s"\ntorque_Nm = "torque_Nm"\n'
                                  'output_angle_deg = "output_angle_deg"\n\n[test]\n'
                                  'rated_torque_Nm = 10.0\n')
    res = _rig("import", str(work / "exported" / "samples.csv"), "--map",
               str(work / "map.toml"), "--unit", str(UNIT), "--into", str(work / "imported"),
               cwd=work)
    assert res.returncode == 0, res.stderr
    from rig.store import Store

    st = Store(work / "imported", create=False)
    try:
        (info,) = st.list_runs()
    finally:
        st.close()
    res = _rig("certificate", info.run_id, "--store", str(work / "imported"), "--pdf",
               str(work / "imported.pdf"), cwd=work)
    assert res.returncode == 0, res.stderr
    assert "): NO LIMITS" in res.stdout, res.stdout
    text = _assert_laid_out(work / "imported.pdf")
    assert "NO LIMITS" in text and "no limits set" in text
    assert not re.search(r"\bOK\b", text), text
