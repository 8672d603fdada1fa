"""``rig spc``: every figure against a hand computation (charts, rules, capability, batch band).

Hand computations (values x = 2.0, 2.2, 2.1, 2.6, 2.3):
mean = 11.2 / 5 = 2.24; moving ranges 0.2, 0.1, 0.5, 0.3, MR-bar = 1.1 / 4 = 0.275;
sigma_within = 0.275 / 1.128 = 0.2437943; individuals limits 2.24 ± 0.825 / 1.128 =
2.24 ± 0.7313830 -> 2.9713830 / 1.5086170; MR upper limit 3.267 * 0.275 = 0.898425.
Against LSL 1.5, USL 3.0: Cp = 1.5 * 1.128 / (6 * 0.275) = 1.692 / 1.65 = 1.0254545;
Cpk = min(0.76, 0.74) * 1.128 / (3 * 0.275) = 0.83472 / 0.825 = 1.0117818; overall
s = sqrt((0.24² + 0.04² + 0.14² + 0.36² + 0.06²) / 4) = sqrt(0.053) = 0.2302173,
Pp = 1.5 / (6 s) = 1.0859306, Ppk = 0.74 / (3 s) = 1.0714515.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from analysis.spc import capability, imr_chart, run_rules
from tests.support.paths import REPO

UNIT = json.loads((REPO / "rig/examples/units/seed000-pair1.json").read_text())
X = [2.0, 2.2, 2.1, 2.6, 2.3]


def test_individuals_and_moving_range_chart_by_hand():
    c = imr_chart(X)
    assert c.centre == pytest.approx(2.24, abs=1e-12)
    assert c.moving_ranges.tolist() == pytest.approx([0.2, 0.1, 0.5, 0.3], abs=1e-12)
    assert c.mr_centre == pytest.approx(0.275, abs=1e-12)
    assert c.sigma_within == pytest.approx(0.2437943, abs=1e-7)
    assert (c.ucl, c.lcl) == (pytest.approx(2.9713830, abs=1e-7),
                              pytest.approx(1.5086170, abs=1e-7))
    assert c.mr_ucl == pytest.approx(0.898425, abs=1e-12)
    assert c.violations == []


def test_capability_by_hand():
    cap = capability(X, 0.275 / 1.128, lsl=1.5, usl=3.0)
    assert cap["cp"] == pytest.approx(1.0254545, abs=1e-7)
    assert cap["cpk"] == pytest.approx(1.0117818, abs=1e-7)
    assert cap["sigma_overall"] == pytest.approx(0.2302173, abs=1e-7)
    assert cap["pp"] == pytest.approx(1.0859306, abs=1e-7)
    assert cap["ppk"] == pytest.approx(1.0714515, abs=1e-7)
    upper_only = capability(X, 0.275 / 1.128, usl=3.0)  # 0.76 * 1.128 / 0.825 = 1.0391273
    assert upper_only["cp"] is None and upper_only["cpk"] == pytest.approx(1.0391273, abs=1e-7)
    lower_only = capability(X, 0.275 / 1.128, lsl=1.5)  # (2.24 - 1.5) / (3 sigma) = 1.0117818
    assert lower_only["cpk"] == pytest.approx(1.0117818, abs=1e-7)
    assert capability(X, 0.0, usl=3.0)["cpk"] is None  # no spread: undefined


@pytest.mark.parametrize(("values", "expected"), [
    ([0.0, 3.2, 0.0], [("WE1", 1, (1,))]),
    ([0.0, 2.5, -0.5, 2.1, 0.0], [("WE2", 3, (1, 3))]),
    ([1.5, 1.2, -0.5, 1.1, 1.3, 0.0], [("WE3", 4, (0, 1, 3, 4))]),
    ([0.5, 0.6] * 4 + [-0.5], [("WE4", 7, tuple(range(8)))]),
    ([-0.3, -0.2, -0.1, 0.1, 0.2, 0.3], [("N3", 5, tuple(range(6)))]),
    ([-2.5, -0.2, -2.2, 0.3], [("WE2", 2, (0, 2))]),  # below the centre too
])
def test_each_rule_on_a_sequence_built_to_break_it(values, expected):
    got = [(v.rule, v.index, v.points) for v in run_rules(values, 0.0, 1.0)]
    assert got == expected


def test_a_jump_signals_on_both_charts():
    # MR-bar = (8 * 0.1 + 2.0) / 9 = 0.31111; D4 MR-bar = 1.01640 < 2.0 (MR at point 9).
    # mean = 2.4 / 10 = 0.24, UCL = 0.24 + 3 * 0.31111 / 1.128 = 1.06745 < 2.0 (WE1 at 9);
    # points 0..8 (<= 0.1) lie below 0.24: WE4 at 7 and 8.
    c = imr_chart([0.0, 0.1] * 4 + [0.0, 2.0])
    assert c.mr_ucl == pytest.approx(3.267 * 2.8 / 9, abs=1e-12)
    assert c.ucl == pytest.approx(0.24 + 3 * 2.8 / 9 / 1.128, abs=1e-12)
    got = sorted((v.chart, v.rule, v.index) for v in c.violations)
    assert got == [("I", "WE1", 9), ("I", "WE4", 7), ("I", "WE4", 8), ("MR", "WE1", 9)]


def small_line(st) -> None:
    """Five units, two positions each; worst lost motion = max play + 0.02 (closed form:
    2 * 3 % * 10 N·m / 30 N·m/arcmin) = 2.02, 2.22, 2.12, 2.62, 2.32 arcmin; worst backlash
    = X; one run of another design that must stay out of the SYN-1 charts."""
    from rig.store.synthetic_runs import write_campaign

    plays = [[2.0, 1.9], [2.1, 2.2], [2.1, 1.8], [2.6, 2.5], [2.3, 2.2]]
    for k, p in enumerate(plays):
        write_campaign(st, f"P-{k}", play_arcmin=p, design="SYN-1", unit_data=UNIT,
                       limits={"lost_motion_arcmin_max": 3.0,
                               "stiffness_Nm_per_arcmin_min": 20.0}, n_quarter=100)
    write_campaign(st, "OTHER", play_arcmin=9.0, positions_deg=(0.0,), design="SYN-2",
                   n_quarter=100)


def test_rig_spc_json_and_html_on_a_small_store(make_store, tmp_path):
    root = tmp_path / "store"
    small_line(make_store(root))
    env = {k: v for k, v in os.environ.items() if k not in ("RIG_STORE", "RIG_SAMPLES_DIR")}
    env.update(make_store.env(root))
    out = subprocess.run(
        [sys.executable, "-c", "from rig.cli import main; main()", "spc", "--store",
         make_store.target(root), "--design", "SYN-1", "--since", "2000-01-01",
         "--json", str(tmp_path / "spc.json"), "--html", str(tmp_path / "spc.html")],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    # issue 33 item 18: the page's file said, as every command that writes one says it
    assert f"charts written to {tmp_path / 'spc.html'}" in out.stdout.splitlines()
    doc = json.loads((tmp_path / "spc.json").read_text())
    (d,) = doc["designs"]
    assert (d["design"], d["n_tests"], d["n_runs"]) == ("SYN-1", 5, 10)
    assert [t["unit_serial"] for t in d["tests"]] == [f"P-{k}" for k in range(5)]
    lm = d["metrics"]["lost_motion_arcmin"]
    assert [p["value"] for p in lm["points"]] == pytest.approx(
        [2.02, 2.22, 2.12, 2.62, 2.32], abs=1e-12)
    ind = lm["chart"]["individuals"]
    assert ind["centre"] == pytest.approx(2.26, abs=1e-12)
    assert (ind["ucl"], ind["lcl"]) == (pytest.approx(2.9913830, abs=1e-7),
                                        pytest.approx(1.5286170, abs=1e-7))
    assert lm["chart"]["moving_range"]["ucl"] == pytest.approx(0.898425, abs=1e-9)
    assert lm["usl"] == 3.0 and lm["capability"]["cp"] is None
    assert lm["capability"]["cpk"] == pytest.approx(1.0117818, abs=1e-7)  # (3 - 2.26)/3σ
    bl = d["metrics"]["backlash_arcmin"]
    assert bl["chart"]["individuals"]["centre"] == pytest.approx(2.24, abs=1e-12)
    assert bl["capability"]["cpk"] is None  # no backlash limit in the campaigns
    st_ = d["metrics"]["stiffness_Nm_per_arcmin"]
    assert st_["chart"]["individuals"]["centre"] == pytest.approx(30.0)
    assert st_["lsl"] == 20.0 and st_["capability"]["cpk"] is None  # zero spread
    # the seed 000 batch band of pair 1 at 10 N·m, ±3 %: as `rig campaign run` prints it
    band = lm["batch"]["band"]
    assert band["band_95_arcmin"] == pytest.approx([3.909, 6.411], abs=1e-3)
    assert doc["constants"] == {"d2": 1.128, "D4": 3.267, "sigma_limits": 3.0}
    page = (tmp_path / "spc.html").read_text()
    assert page.count("data:image/png;base64,") == 3
    assert "3.909 .. 6.411 arcmin" in page and "WE4" in page and "1.012" in page
    assert "SYN-2" not in page


def test_rig_spc_errors(tmp_path):
    run = [sys.executable, "-c", "from rig.cli import main; main()", "spc"]
    out = subprocess.run([*run, "--store", str(tmp_path / "none")], cwd=tmp_path,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "no store at" in out.stderr
    from rig.store import Store

    Store(tmp_path / "s")
    out = subprocess.run([*run, "--store", str(tmp_path / "s"), "--since", "yesterday"],
                         cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "since: 'yesterday' is not an ISO 8601" in out.stderr


def test_the_control_page_serves_the_same_quality_view(make_store, tmp_path):
    """``GET /api/spc`` is ``rig spc --json``'s document; ``GET /spc`` its charts as a page
    with a way back to the control page (computed in the page's worker process)."""
    from fastapi.testclient import TestClient

    from rig.web.app import create_app
    from rig.web.settings import resolve_settings

    root = tmp_path / "store"
    st = make_store(root)
    small_line(st)
    app = create_app(resolve_settings(store_root=st.root, token="spc-page-token"), store=st)
    with TestClient(app) as client:
        doc = client.get("/api/spc", params={"design": "SYN-1", "since": "2000-01-01"}).json()
        page = client.get("/spc", params={"design": "SYN-1"})
        everything = client.get("/api/spc").json()
        bad = client.get("/api/spc", params={"since": "yesterday"})
        control_page = client.get("/").text
    assert 'href="/spc"' in control_page  # the control page's header links to the view
    (d,) = doc["designs"]
    lm = d["metrics"]["lost_motion_arcmin"]
    assert [p["value"] for p in lm["points"]] == pytest.approx(
        [2.02, 2.22, 2.12, 2.62, 2.32], abs=1e-12)
    assert lm["chart"]["individuals"]["ucl"] == pytest.approx(2.9913830, abs=1e-7)
    assert lm["capability"]["cpk"] == pytest.approx(1.0117818, abs=1e-7)
    assert page.status_code == 200 and page.text.count("data:image/png;base64,") == 3
    assert 'href="/"' in page.text and "3.909 .. 6.411 arcmin" in page.text
    assert {x["design"] for x in everything["designs"]} == {"SYN-1", "SYN-2"}
    assert bad.status_code == 422


def test_the_view_uses_the_newest_reanalysis(tmp_path):
    """After a model or software update `rig reanalyse` stores new metrics beside the old:
    the quality view charts the newest (by hand: unit P-3's run at 2.62 re-analysed to 2.40
    leaves its other run, 2.52, the worst; the centre line moves from 2.26 to 2.24), and says
    how many runs it took from there."""
    from rig.reports.spc import spc_report
    from rig.store import Store

    st = Store(tmp_path / "store")
    small_line(st)
    p3 = [r for r in st.list_runs(serial="P-3")]
    worst = max(p3, key=lambda r: r.metrics["lost_motion_arcmin"])
    st.add_result(run_id=worst.run_id, software_version="0.0.1",
                  metrics={"lost_motion_arcmin": 9.0})
    st.add_result(run_id=worst.run_id, software_version="9.9.9",
                  metrics={"lost_motion_arcmin": 2.40})
    doc = spc_report(st, design="SYN-1")
    (d,) = doc["designs"]
    lm = d["metrics"]["lost_motion_arcmin"]
    others = [r for r in p3 if r.run_id != worst.run_id]
    expected_p3 = max([2.40] + [r.metrics["lost_motion_arcmin"] for r in others])
    assert [p["value"] for p in lm["points"]][3] == pytest.approx(expected_p3, abs=1e-12)
    assert lm["chart"]["individuals"]["centre"] == pytest.approx(
        (2.02 + 2.22 + 2.12 + expected_p3 + 2.32) / 5, abs=1e-12)
    assert doc["n_runs_reanalysed"] == 1


# ------------------------------------------------------------- issue 21 item 18: the SPC page


def test_a_quantity_that_cannot_be_negative_gets_no_negative_lower_limit():
    """x = 0.1, 1.0, 0.2, 0.9, 0.1: mean 2.3 / 5 = 0.46, MR-bar = 3.2 / 4 = 0.8, 3 sigma =
    2.4 / 1.128 = 2.1276596; centre - 3 sigma = -1.6676596 < 0: with the bound 0 the LCL is 0
    (one-sided), the UCL stays 0.46 + 2.1276596 = 2.5876596."""
    x = [0.1, 1.0, 0.2, 0.9, 0.1]
    free = imr_chart(x)
    assert free.lcl == pytest.approx(-1.6676596, abs=1e-7) and not free.lcl_clipped
    bounded = imr_chart(x, lower_bound=0.0)
    assert bounded.lcl == 0.0 and bounded.lcl_clipped
    assert bounded.ucl == pytest.approx(2.5876596, abs=1e-7) == free.ucl
    assert bounded.to_dict()["individuals"]["lcl_clipped"] is True
    far = imr_chart(X, lower_bound=0.0)  # 2.24 - 0.731 > 0: a two-sided chart as before
    assert far.lcl == pytest.approx(1.5086170, abs=1e-7) and not far.lcl_clipped


def test_spc_charts_of_lost_motion_backlash_stiffness_have_no_negative_lcl(tmp_path):
    """Units of a near-zero-backlash design (backlash = play 0.1, 1.0, 0.2, 0.9, 0.1 arcmin,
    lost motion 0.02 more): both charts' centre - 3 sigma is below 0 (above); the LCL is 0
    on the JSON and on the page, which says why. Stiffness (30 for all) stays two-sided."""
    from rig.reports.spc import spc_report
    from rig.reports.spc.html import render_html
    from rig.store import Store
    from rig.store.synthetic_runs import write_campaign

    st = Store(tmp_path / "store")
    for k, play in enumerate([0.1, 1.0, 0.2, 0.9, 0.1]):
        write_campaign(st, f"Z-{k}", play_arcmin=play, positions_deg=(0.0,), design="ZB-1",
                       unit_data=UNIT, n_quarter=40)
    (d,) = spc_report(st)["designs"]
    for metric in ("lost_motion_arcmin", "backlash_arcmin"):
        ind = d["metrics"][metric]["chart"]["individuals"]
        assert ind["lcl"] == 0.0 and ind["lcl_clipped"] is True, metric
        assert ind["ucl"] == pytest.approx(ind["centre"] + 2.4 / 1.128, abs=1e-9)
    stiff = d["metrics"]["stiffness_Nm_per_arcmin"]["chart"]["individuals"]
    assert stiff["lcl"] == pytest.approx(30.0) and stiff["lcl_clipped"] is False
    page = render_html(spc_report(st))
    assert page.count("<td>0 (one-sided)</td>") == 2
    assert "the LCL is 0 and the chart is one-sided" in page
    assert "<td>-" not in page  # no negative figure in the tables


def test_each_unit_test_is_charted_against_its_own_campaigns_limits(tmp_path):
    """Units P-0..P-2 tested with a lost-motion limit of 3 arcmin, then P-3 and P-4 with 2
    (worst lost motion 2.02, 2.22, 2.12 | 2.62, 2.32). Each point carries its campaign's limit
    and verdict; no single USL is applied to all. Capability per set of limits, with the
    chart's sigma_within 0.275 / 1.128 (3 sigma = 0.825 / 1.128): limit 3, mean 2.12:
    Cpk = 0.88 * 1.128 / 0.825 = 1.2032; limit 2, mean 2.47: Cpk = -0.47 * 1.128 / 0.825 =
    -0.6426182."""
    from rig.reports.spc import spc_report
    from rig.reports.spc.html import render_html
    from rig.store import Store
    from rig.store.synthetic_runs import write_campaign

    st = Store(tmp_path / "store")
    plays = [[2.0, 1.9], [2.1, 2.2], [2.1, 1.8], [2.6, 2.5], [2.3, 2.2]]
    for k, p in enumerate(plays):
        write_campaign(st, f"P-{k}", play_arcmin=p, design="SYN-1", unit_data=UNIT,
                       limits={"lost_motion_arcmin_max": 3.0 if k < 3 else 2.0},
                       n_quarter=60)
    (d,) = spc_report(st)["designs"]
    lm = d["metrics"]["lost_motion_arcmin"]
    assert [p["usl"] for p in lm["points"]] == [3.0, 3.0, 3.0, 2.0, 2.0]
    assert [p["verdict"] for p in lm["points"]] == ["OK", "OK", "OK", "NOT OK", "NOT OK"]
    assert [t["limits"] for t in d["tests"]] == [{"lost_motion_arcmin_max": 3.0}] * 3 + [
        {"lost_motion_arcmin_max": 2.0}] * 2
    assert lm["usl"] is None and lm["limits_differ"] is True
    assert lm["capability"]["cpk"] is None  # no one limit for the whole chart
    by = {c["usl"]: c for c in lm["capability_by_limits"]}
    assert (by[3.0]["n"], by[2.0]["n"]) == (3, 2)
    assert by[3.0]["cpk"] == pytest.approx(1.2032, abs=1e-7)
    assert by[2.0]["cpk"] == pytest.approx(-0.6426182, abs=1e-7)
    assert d["limit_sets"] == [{"limits": {"lost_motion_arcmin_max": 3.0}, "n_tests": 3},
                               {"limits": {"lost_motion_arcmin_max": 2.0}, "n_tests": 2}]
    page = render_html(spc_report(st))
    assert "lost_motion_arcmin_max 3 (3 unit tests); lost_motion_arcmin_max 2 (2 unit tests)" \
        in page
    assert "<td>each unit's own</td>" in page and "<td>1.203</td>" in page


def test_the_x_axis_is_the_test_order_and_each_point_names_its_serial(tmp_path):
    """The charts' x axis is the test order 1..5 with integer ticks; the page puts a hover
    target on every drawn point (the PNG's pixel there is the points' colour) naming the test
    order, the serial, the value and the verdict."""
    import io

    import matplotlib.image
    import numpy as np
    from matplotlib.colors import to_rgb

    from rig.reports.spc import spc_report
    from rig.reports.spc.html import POINT_COLOUR, draw_chart, hover_targets, render_html
    from rig.store import Store

    st = Store(tmp_path / "store")
    small_line(st)
    doc = spc_report(st, design="SYN-1")
    lm = doc["designs"][0]["metrics"]["lost_motion_arcmin"]
    assert [p["order"] for p in lm["points"]] == [1, 2, 3, 4, 5]
    image = draw_chart("lost_motion_arcmin", lm)
    assert image.xticks == [1.0, 2.0, 3.0, 4.0, 5.0]
    rgba = matplotlib.image.imread(io.BytesIO(image.png))
    assert rgba.shape[:2] == (image.height, image.width)
    for px, py in image.points:
        colour = rgba[int(round(py)), int(round(px)), :3]
        assert np.abs(colour - np.array(to_rgb(POINT_COLOUR))).max() < 0.15, (px, py)
    targets = hover_targets(image, lm, "arcmin")
    assert [t["text"] for t in targets] == [
        f"unit test {k + 1}: P-{k} · {v} arcmin · OK"
        for k, v in enumerate(["2.02", "2.22", "2.12", "2.62", "2.32"])]
    page = render_html(doc)
    assert 'title="unit test 4: P-3 · 2.62 arcmin · OK"' in page
    assert page.count('class="pt') == 15  # 5 points on each of the 3 charts


def test_the_heading_names_the_design(tmp_path):
    """Units whose runs record no design name are named by their gear data (and can be
    asked for by that name); runs without any unit data say so, never "Design (none)"."""
    from rig.reports.spc import spc_report
    from rig.reports.spc.html import render_html
    from rig.store import Store
    from rig.store.synthetic_runs import write_campaign

    st = Store(tmp_path / "store")
    for k, play in enumerate([2.0, 2.2, 2.1]):
        write_campaign(st, f"G-{k}", play_arcmin=play, positions_deg=(0.0,), design=None,
                       unit_data=UNIT, n_quarter=40)
    for k, play in enumerate([2.0, 2.4]):
        write_campaign(st, f"N-{k}", play_arcmin=play, positions_deg=(0.0,), design=None,
                       n_quarter=40)
    gear = "internal_involute, 45/40 teeth, module 1 mm"
    doc = spc_report(st)
    assert [(d["design"], d["design_named_by"], d["n_tests"]) for d in doc["designs"]] == [
        ("(not recorded)", "none", 2), (gear, "gear data", 3)]
    page = render_html(doc)
    assert f"<h2>Design {gear}: 3 unit tests, 3 runs</h2>" in page
    assert "<h2>Design not recorded: 2 unit tests, 2 runs</h2>" in page
    assert "Design (none)" not in page
    only = spc_report(st, design=gear)
    assert [(d["design"], d["n_tests"]) for d in only["designs"]] == [(gear, 3)]


def test_a_run_outside_campaigns_is_judged_by_its_own_run_json_limits(tmp_path):
    """Two campaigns with a lost-motion limit of 3 arcmin, then one run measured on its own
    (no campaign) with 2.5 in its run.json: its point carries 2.5, not a campaign's 3."""
    from rig.reports.spc import spc_report
    from rig.store import Store
    from rig.store.synthetic_runs import COLUMNS, closed_form_metrics, loop_samples, write_campaign

    st = Store(tmp_path / "store")
    for k, play in enumerate([2.0, 2.2]):
        write_campaign(st, f"C-{k}", play_arcmin=play, positions_deg=(0.0,), design="SYN-1",
                       unit_data=UNIT, n_quarter=40, limits={"lost_motion_arcmin_max": 3.0})
    meta = {"unit": {**UNIT, "serial": "S-1", "design": "SYN-1"}, "operator": "t",
            "test": {"rated_torque_Nm": 10.0, "input_angle_deg": 0.0},
            "limits": {"lost_motion_arcmin_max": 2.5, "backlash_arcmin_max": None,
                       "stiffness_Nm_per_arcmin_min": None}}
    with st.begin_run(meta, COLUMNS) as rec:
        for row in loop_samples(2.1, 30.0, 10.0, 40).tolist():
            rec.append(row)
        rec.finish(result=closed_form_metrics(2.1, 30.0, 10.0), extra={"outcome": "ok"})
    (d,) = spc_report(st)["designs"]
    lm = d["metrics"]["lost_motion_arcmin"]
    assert [(p["unit_serial"], p["usl"]) for p in lm["points"]] == [
        ("C-0", 3.0), ("C-1", 3.0), ("S-1", 2.5)]
    assert lm["limits_differ"] is True and lm["usl"] is None


PAIR3 = json.loads((REPO / "rig/examples/units/seed000-pair3.json").read_text())


def _two_builds(st, design: str | None) -> None:
    """Seed 000 pair 1 (center distance 2.5 mm, lost motion about 4.3') and pair 3 (2.5222 mm,
    compensated by eq. 9: about 1.8'): three units of each, one position each."""
    from rig.store.synthetic_runs import write_campaign

    for k, play in enumerate([4.3, 4.5, 4.2]):
        write_campaign(st, f"A-{k}", play_arcmin=play, positions_deg=(0.0,), design=design,
                       unit_data=UNIT, n_quarter=40)
    for k, play in enumerate([1.8, 1.7, 1.9]):
        write_campaign(st, f"C-{k}", play_arcmin=play, positions_deg=(0.0,), design=design,
                       unit_data=PAIR3, n_quarter=40)


@pytest.mark.parametrize("name", [None, "GB-45/40"])
def test_pair1_and_pair3_are_two_designs_with_their_own_limits(tmp_path, name):
    """Issue 33 item 17: seed 000's pair 1 and pair 3 share teeth (45/40) and module (1 mm),
    and may share a design name, but are two builds (center distance 2.5 vs 2.5222 mm): two
    groups, each charted against its own control limits."""
    from rig.reports.spc import spc_report
    from rig.store import Store

    st = Store(tmp_path / "store")
    _two_builds(st, name)
    doc = spc_report(st)
    base = name or "internal_involute, 45/40 teeth, module 1 mm"
    assert [(d["design"], d["n_tests"]) for d in doc["designs"]] == [
        (f"{base} [center_distance_mm 2.5]", 3), (f"{base} [center_distance_mm 2.5222]", 3)]
    one, three = doc["designs"]
    from rig.runformat.design import design_key

    assert (one["design_key"], three["design_key"]) == (design_key(UNIT), design_key(PAIR3))
    assert one["design_geometry"]["center_distance_mm"] == 2.5
    assert three["design_geometry"]["center_distance_mm"] == 2.5222
    assert {t["unit_serial"] for t in one["tests"]} == {"A-0", "A-1", "A-2"}
    assert {t["unit_serial"] for t in three["tests"]} == {"C-0", "C-1", "C-2"}
    lm1 = one["metrics"]["lost_motion_arcmin"]["chart"]["individuals"]
    lm3 = three["metrics"]["lost_motion_arcmin"]["chart"]["individuals"]
    assert lm3["ucl"] < 2.5 < lm1["lcl"]  # each build's own limits, none pooled
    # either build can be asked for by its label or its key
    for ask in (three["design"], three["design_key"]):
        assert [d["design"] for d in spc_report(st, design=ask)["designs"]] == [
            three["design"]]


def test_old_runs_without_the_full_geometry_group_sensibly(tmp_path):
    """A unit recording only part of the geometry (an older run: no center distance, or only
    the design name) joins the one build of its name that agrees with what it records; where
    two builds agree it stays a design of its own, labelled with what it lacks."""
    from rig.reports.spc import spc_report
    from rig.store import Store
    from rig.store.synthetic_runs import write_campaign

    old = {k: v for k, v in UNIT.items() if k != "center_distance_mm"}
    st = Store(tmp_path / "one")
    for k, play in enumerate([4.3, 4.5]):
        write_campaign(st, f"A-{k}", play_arcmin=play, positions_deg=(0.0,), design="GB",
                       unit_data=UNIT, n_quarter=40)
    write_campaign(st, "OLD-1", play_arcmin=4.4, positions_deg=(0.0,), design="GB",
                   unit_data=old, n_quarter=40)
    write_campaign(st, "OLD-2", play_arcmin=4.1, positions_deg=(0.0,), design="GB",
                   n_quarter=40)  # a name, no geometry at all
    (d,) = spc_report(st)["designs"]
    assert (d["design"], d["n_tests"], d["n_runs_partial_geometry"]) == ("GB", 4, 2)

    st = Store(tmp_path / "two")
    _two_builds(st, "GB")
    write_campaign(st, "OLD-1", play_arcmin=4.4, positions_deg=(0.0,), design="GB",
                   unit_data=old, n_quarter=40)
    got = [(d["design"], d["n_tests"]) for d in spc_report(st)["designs"]]
    assert got == [("GB [center_distance_mm 2.5]", 3), ("GB [center_distance_mm 2.5222]", 3),
                   ("GB [center_distance_mm not recorded]", 1)]


def test_the_design_key_is_the_build_geometry_only():
    from rig.runformat.design import design_key

    key = design_key(UNIT)
    assert key is not None and key.startswith("g-") and len(key) == 12
    # the same build: other serial, names, inspection data, key order, number spelling
    same = {**{k: UNIT[k] for k in reversed(list(UNIT))}, "serial": "X", "design": "D",
            "module_mm": 1, "runout_internal_mm": 0.03, "m_value_internal_mm": [42.5]}
    assert design_key(same) == key
    assert design_key(PAIR3) != key
    assert design_key({"serial": "X", "design": "D"}) is None
    assert design_key({**UNIT, "kind": "cycloid"}) != key
