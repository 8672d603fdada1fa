"""What a campaign certificate's figures and words say (issue 33 items 8 and 19).

Made without simulated devices: campaigns of the reference dead-zone loop
(:mod:`rig.store.synthetic_runs`, seed 000 pair 1 as the unit, so the nominal model is drawn),
labelled as a measured campaign labels its runs, and an aborted campaign written through the
store as the rig writes one. Read back through ``pdftotext`` (poppler-utils) and the HTML,
whose figures carry their words as SVG text.
"""

from __future__ import annotations

import base64
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from rig.reports.certificate import resolve_subject, write_certificate
from rig.store import Store
from rig.store.synthetic_runs import loop_samples, write_campaign
from tests.support.paths import REPO

UNIT = json.loads((REPO / "rig/examples/units/seed000-pair1.json").read_text())
POSITIONS = (0.0, 120.0, 240.0)
PLAYS = [2.0, 6.0, 3.0]
"""Lost motion 2.020, 6.020 and 3.020 arcmin against a limit of 4: NOT OK at 120 deg only."""
RIG = [sys.executable, "-c", "from rig.cli import main; main()"]


def _pdf_text(path: Path) -> str:
    if shutil.which("pdftotext") is None:
        pytest.fail("pdftotext not found: install poppler-utils (.ci/install)")
    text = subprocess.run(["pdftotext", str(path), "-"], capture_output=True, text=True,
                          check=True).stdout
    return " ".join(text.split())


def _figure(page: str, alt: str) -> str:
    """The SVG document of the page's figure whose alt text is ``alt``."""
    found = re.search(rf'alt="{re.escape(alt)}" src="data:image/svg\+xml;base64,([^"]+)"', page)
    assert found, f"no figure {alt!r} on the page"
    return base64.b64decode(found.group(1)).decode("utf-8")


def _texts(svg: str) -> list[str]:
    return [re.sub(r"<[^>]+>", "", t).strip() for t in
            re.findall(r"<text\b[^>]*>(.*?)</text>", svg, re.S)]


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """A NOT OK campaign (runs labelled pos000, pos120, pos240 as ``rig campaign`` labels
    them) and an aborted one (its only run stopped by the E-stop after a whole loop,
    never analysed), in one folder store."""
    root = tmp_path_factory.mktemp("certfig") / "store"
    st = Store(root)
    try:
        cid = write_campaign(st, "SN-8", play_arcmin=PLAYS, positions_deg=POSITIONS,
                             unit_data=UNIT, limits={"lost_motion_arcmin_max": 4.0},
                             n_quarter=200)
        aborted = st.create_campaign("stopped", {"unit": {**UNIT, "serial": "SN-9"},
                                                 "limits": {"lost_motion_arcmin_max": 4.0}})
        rec = st.begin_run({"unit": {**UNIT, "serial": "SN-9"}, "label": "pos000",
                            "test": {"rated_torque_Nm": 10.0, "input_angle_deg": 0.0},
                            "profile": "nabtesco"},
                           ["t_s", "torque_Nm", "output_angle_deg"], campaign_id=aborted)
        for row in loop_samples(5.0, 30.0, 10.0, 200).tolist():
            rec.append(row)
        rec.finish("aborted", reason="E-stop pressed", extra={"outcome": "incomplete"})
        st.finish_campaign(aborted, "aborted", {"reason": "E-stop pressed"},
                           extra={"outcome": "incomplete"})
        folder = st.get_campaign(cid).path
    finally:
        st.close()
    for path in folder.glob("*/run.json"):  # labelled as a measured campaign's runs are
        meta = json.loads(path.read_text())
        meta["label"] = f"pos{meta['test']['input_angle_deg']:03.0f}"
        path.write_text(json.dumps(meta))
    return {"root": root, "campaign": cid, "folder": folder, "aborted": aborted}


@pytest.fixture(scope="module")
def not_ok(store: dict) -> dict:
    """The NOT OK campaign's certificate by ``rig certificate`` (PDF text and HTML)."""
    out = store["root"].parent
    res = subprocess.run([*RIG, "certificate", store["campaign"], "--store", str(store["root"]),
                          "--pdf", str(out / "camp.pdf"), "--html", str(out / "camp.html")],
                         capture_output=True, text=True, timeout=180,
                         env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"})
    assert res.returncode == 0, res.stderr
    assert "NOT OK" in res.stdout, res.stdout
    return {"text": _pdf_text(out / "camp.pdf"),
            "page": (out / "camp.html").read_text(encoding="utf-8")}


def test_the_loop_box_shows_the_worst_run_the_verdict_rests_on(not_ok: dict):
    """Issue 33 item 8: the box in the loop picture showed the first run's figures (lost
    motion 2.020) on a NOT OK certificate whose failing run has 6.020: it shows the worst run's,
    named so, in the PDF and the HTML."""
    box = _texts(_figure(not_ok["page"], "torque against twist"))
    assert "worst run: pos120 (120°)" in box, box
    assert "lost motion 6.020 arcmin" in box and "backlash 6.000 arcmin" in box, box
    assert "lost motion 2.020 arcmin" not in box, box
    text = not_ok["text"]
    assert "worst run: pos120 (120°) lost motion 6.020 arcmin backlash 6.000 arcmin" in text, text
    assert "lost motion 2.020 arcmin" not in text


def test_the_loop_legend_names_runs_by_position(not_ok: dict, store: dict):
    """Issue 33 item 8: the legend named the lines by run id; it names them by label and
    input angle."""
    legend = _texts(_figure(not_ok["page"], "torque against twist"))
    for name in ("pos000 (0°)", "pos120 (120°)", "pos240 (240°)"):
        assert name in legend, legend
    run_ids = [p.parent.name for p in store["folder"].glob("*/run.json")]
    assert len(run_ids) == 3
    assert not [t for t in legend if any(r in t for r in run_ids)], legend
    assert "pos240 (240°)" in not_ok["text"]


def _paths(svg: str) -> list[tuple[str, list[float]]]:
    """(style, x coordinates) of every path drawn in the axes (the legend's left out)."""
    plot = re.sub(r'<g id="legend_\d+">.*', "", svg, flags=re.S)
    return [(style, [float(x) for x in re.findall(r"[ML] ([-\d.]+) [-\d.]+", d)])
            for d, style in re.findall(r'<path d="([^"]*)"[^>]*style="([^"]*)"', plot)]


def test_the_model_line_is_drawn_dashed_as_its_legend_shows_it(not_ok: dict):
    """Issue 33 item 19: the model line was drawn along the measured torque, there and back,
    so that its dashes fell on each other's gaps: solid in the picture, dashed in the
    legend. Each dashed line of the axes now goes one way (no stretch drawn twice), in the
    legend's colour (black)."""
    svg = _figure(not_ok["page"], "torque against twist")
    dashed = [(style, xs) for style, xs in _paths(svg) if "stroke-dasharray" in style]
    assert dashed, "no dashed line in the loop picture"
    for style, xs in dashed:
        steps = [b - a for a, b in zip(xs, xs[1:], strict=False) if abs(b - a) > 1e-6]
        assert all(s > 0 for s in steps) or all(s < 0 for s in steps), \
            f"a dashed line goes back over itself: {xs[:12]} ..."
        assert "stroke: #000000" in style, style
    legend = re.search(r'<g id="legend_\d+">.*', svg, re.S).group(0)
    handle = re.findall(r'style="([^"]*stroke-dasharray[^"]*)"', legend)
    assert handle and all("stroke: #000000" in h for h in handle), handle


def test_an_aborted_campaign_names_its_runs_and_the_model_it_draws(store: dict, tmp_path):
    """Issue 33 item 19: an aborted campaign's certificate said "campaign of 1 runs" and
    called the model "not available" beside a loop picture that draws it."""
    write_certificate(resolve_subject(store["aborted"], store["root"]),
                      pdf=tmp_path / "aborted.pdf", html=tmp_path / "aborted.html")
    text = _pdf_text(tmp_path / "aborted.pdf")
    assert "campaign of 1 run, aborted" in text, text
    assert "1 runs" not in text
    assert "INCOMPLETE" in text and "E-stop pressed" in text
    box = _texts(_figure((tmp_path / "aborted.html").read_text(), "torque against twist"))
    drawn = next(t for t in box if t.startswith("model lost motion"))
    model = drawn.removeprefix("model lost motion ").removesuffix(" arcmin")
    assert f"nominal model, no runout): {model} arcmin" in text, text
    assert "not available" not in text


def test_the_loop_area_is_in_millijoule(store: dict, tmp_path):
    """Issue 33 item 19: the loop area read "8.68e-05 ± 5.13e-06 J" on the certificate and
    0.087 mJ on the page and in ``rig analyse``: mJ, 3 decimals, on the certificate too."""
    folder = tmp_path / "run"
    shutil.copytree(sorted(store["folder"].glob("*/run.json"))[0].parent, folder)
    meta = json.loads((folder / "run.json").read_text())
    meta["result"]["loop_area_J"] = 8.68e-05
    meta["result"].setdefault("uncertainty", {})["loop_area_J"] = 5.13e-06
    (folder / "run.json").write_text(json.dumps(meta))
    write_certificate(resolve_subject(str(folder), store["root"]), pdf=tmp_path / "run.pdf")
    text = _pdf_text(tmp_path / "run.pdf")
    assert "0.087 ± 0.005 mJ" in text, text
    assert "e-05" not in text and "e-06" not in text
