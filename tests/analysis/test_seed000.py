"""Seed 000 (internal involute pair): eqs. (1)-(16) against the paper's Tables 2-3 and closed
forms, and the ``rig model`` command on the shipped unit files."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from analysis.errors import AnalysisError
from analysis.models import seed000_geometry as geo
from analysis.models.seed000 import (
    InternalPairUnit,
    design_chain,
    format_arcmin,
    runout_center_distance_mm,
)
from tests.support.paths import REPO

UNITS = REPO / "rig" / "examples" / "units"
ALPHA = math.radians(20.0)

# Seed 000 Table 3 (paper values) and the text's measured lost motion (Conclusion 3 / Fig. 6).
PAPER_SHIFT_MM = {1: (0.019, -0.016), 2: (0.017, -0.014)}
PAPER_ECCENTRIC_MM = {1: 2.572, 2: 2.565}
PAPER_LOST_MOTION = {1: "6'20\"", 2: "6'10\"", 3: "2'3\"", 4: "2'23\""}
PAPER_MEASURED = {1: "6'52\"", 2: "6'37\"", 3: "2'19\"", 4: "2'46\""}
PAPER_M_DEVIATION_MM = {1: (0.045, -0.032), 2: (0.042, -0.024)}


def arcmin(text: str) -> float:
    """6'20" -> 6.333 arcmin."""
    minutes, seconds = text.rstrip('"').split("'")
    return int(minutes) + int(seconds) / 60.0


def load(n: int) -> dict:
    return json.loads((UNITS / f"seed000-pair{n}.json").read_text())


@pytest.fixture(scope="module")
def designs():
    return {n: design_chain(load(n)) for n in (1, 2, 3, 4)}


def test_standard_m_values_match_the_paper():
    """Eqs. (12)-(14) with x = 0, d_p = 1.732: 42.434 (z = 45, odd, eq. 13) and 42.436 mm."""
    m_int = geo.m_value_mm(45, 1.0, ALPHA, 1.732, 0.0, internal=True)
    m_ext = geo.m_value_mm(40, 1.0, ALPHA, 1.732, 0.0, internal=False)
    print(f"M0 internal {m_int:.5f} mm (paper 42.434), external {m_ext:.5f} mm (paper 42.436)")
    assert round(m_int, 3) == pytest.approx(42.434, abs=1e-9)
    assert round(m_ext, 3) == pytest.approx(42.436, abs=1e-9)


@settings(max_examples=200, deadline=None)
@example(angle=math.radians(20.0))
@example(angle=math.radians(14.5))
@example(angle=1e-3)
@example(angle=1.49)
@given(angle=st.floats(min_value=1e-3, max_value=1.49))
def test_inverse_involute_returns_the_angle(angle):
    """inv^-1(inv(a)) = a to the last bits over (0, 1.5) rad, as the closed form inv(a) =
    tan(a) - a defines it (eqs. 12-14 read the pressure angle at the pin centre with it)."""
    back = geo.inverse_involute(geo.involute(angle))
    # tan(a) - a loses digits to cancellation at small angles (about a^2 / 3 of them): the
    # inverse is as good as inv itself there: about ulp(a) / a^2 (2e-13 rad at 1e-3 rad)
    assert abs(back - angle) <= 4.0 * math.ulp(angle) * (1.0 + 1.0 / angle**2)


@pytest.mark.parametrize("value", [0.0, -1e-3, geo.involute(1.5), math.nan])
def test_inverse_involute_refuses_a_value_with_no_pressure_angle(value):
    with pytest.raises(AnalysisError, match="no pressure angle"):
        geo.inverse_involute(value)


@settings(max_examples=60, deadline=None)
@example(z=20, x=-0.25, internal=True)  # pin does not fit: error
@example(z=45, x=0.0, internal=True)
@given(
    z=st.integers(min_value=20, max_value=120),
    x=st.floats(min_value=-0.3, max_value=0.3),
    internal=st.booleans(),
)
def test_eq14_shift_round_trips_through_the_m_value(z, x, internal):
    """M(x) by eqs. (12)-(14), then alpha_M and x back from M: the same x. Where eq. (14) has
    no pin-centre angle (the pin does not fit the space: inv(alpha_M) <= 0) it is an error."""
    pin = 1.728
    sign = -1.0 if internal else 1.0
    inv_m = (geo.involute(ALPHA) + sign * pin / (z * math.cos(ALPHA)) - sign * math.pi / (2 * z)
             + 2 * x * math.tan(ALPHA) / z)
    if inv_m <= 0:
        with pytest.raises(AnalysisError, match="no pressure angle"):
            geo.m_value_mm(z, 1.0, ALPHA, pin, x, internal=internal)
        return
    m = geo.m_value_mm(z, 1.0, ALPHA, pin, x, internal=internal)
    alpha_m = geo.pin_pressure_angle_rad(m, z, 1.0, ALPHA, pin, internal=internal)
    assert geo.shift_coeff_from_pin_angle(
        alpha_m, z, 1.0, ALPHA, pin, internal=internal
    ) == pytest.approx(x, abs=1e-9)


def test_shift_changes_m_value_as_the_closed_form_derivative():
    """dM/dx = 2 m sin(alpha) / sin(alpha_M) (times cos(90/z) for odd z), from eqs. (12)-(14)."""
    for z, internal in ((40, False), (45, True)):
        h = 1e-6
        m_plus = geo.m_value_mm(z, 1.0, ALPHA, 1.732, h, internal=internal)
        m_minus = geo.m_value_mm(z, 1.0, ALPHA, 1.732, -h, internal=internal)
        alpha_m = geo.pin_pressure_angle_rad(
            geo.m_value_mm(z, 1.0, ALPHA, 1.732, 0.0, internal=internal), z, 1.0, ALPHA, 1.732,
            internal=internal,
        )
        odd = math.cos(math.pi / (2 * z)) if z % 2 else 1.0
        expected = 2.0 * math.sin(ALPHA) / math.sin(alpha_m) * odd
        assert (m_plus - m_minus) / (2 * h) == pytest.approx(expected, rel=1e-6)


def test_table3_reproduced(designs):
    """Table 3 of seed 000: ours beside the paper's, with the differences and the measured values.

    Conventions: shifts from the smallest ring and largest pinion M value; eq. (9) with both
    bearings' clearances; the theoretical lost motion = eqs. (2)+(3) play plus the worst-case
    runout term of eq. (7) (pairs 3, 4: the compensated remainder, the runout term alone)."""
    rows = []
    for n in (1, 2):
        d = designs[n]
        for gear, paper in zip(("internal", "external"), PAPER_SHIFT_MM[n], strict=True):
            ours = d.equivalent_shift_mm[gear]
            rows.append((f"pair {n} equivalent shift {gear} (mm)", paper, ours, ours - paper))
            assert abs(ours - paper) <= 0.002
        for gear, paper in zip(("internal", "external"), PAPER_M_DEVIATION_MM[n], strict=True):
            ours = d.m_value_deviation_mm[gear]
            rows.append((f"pair {n} M value deviation {gear} (mm)", paper, ours, ours - paper))
            assert ours == pytest.approx(paper, abs=1e-9)

        # eqs. (15) printed + (16) + (9) from Table 3's own shift amounts (the paper's path)
        x1, x2 = PAPER_SHIFT_MM[n]
        unit = d.unit
        angle = geo.working_pressure_angle_rad(x1, x2, 45, 40, ALPHA, "paper")
        a_zero = geo.zero_backlash_center_distance_mm(2.5, ALPHA, angle)
        a_set = geo.recommended_eccentric_distance_mm(
            a_zero, unit.runout_internal_mm, unit.runout_external_mm, unit.bearing_clearance_mm
        )
        paper = PAPER_ECCENTRIC_MM[n]
        rows.append((f"pair {n} a'' printed eq. 15, Table 3 shifts", paper, a_set, a_set - paper))
        assert abs(a_set - paper) <= 0.005
        # the same from our own shifts (the pinion shift of pair 1 is 2 um off the paper's)
        ours = d.recommended_eccentric_distance_mm["paper"]
        rows.append((f"pair {n} a'' printed eq. 15, our shifts", paper, ours, ours - paper))
        assert abs(ours - paper) <= 0.006
        std = d.recommended_eccentric_distance_mm["standard"]
        rows.append((f"pair {n} a'' standard eq. 15, our shifts", paper, std, std - paper))

    for n in (1, 2, 3, 4):
        d = designs[n]
        paper = arcmin(PAPER_LOST_MOTION[n])
        ours = d.design_lost_motion_arcmin if n <= 2 else d.compensated_lost_motion_arcmin
        assert abs(ours - paper) * 60.0 <= 10.0
        rows.append((f"pair {n} lost motion (arcmin), measured {PAPER_MEASURED[n]}", paper, ours,
                     ours - paper))

    print("\nSeed 000 Table 3: paper, ours, difference")
    for label, paper, ours, diff in rows:
        extra = ""
        if "lost motion" in label:
            extra = f"   {format_arcmin(paper)} vs {format_arcmin(ours)} ({diff * 60:+.1f}\")"
        print(f"  {label:58s} {paper:9.4f} {ours:9.4f} {diff:+8.4f}{extra}")


def test_lead_quick_checks_closed_form(designs):
    """Pair 1: E_M = 0.077 mm -> j_t = 1000 tan20 * 0.077 = 28.03 um -> 6.876 * 28.03 / 45."""
    d = designs[1]
    j_t = 1000 * math.tan(ALPHA) * 0.077
    assert d.backlash_budget_um["tooth_thickness"] == pytest.approx(j_t, rel=1e-9)
    assert d.nominal_play_arcmin == pytest.approx(6.876 * j_t / 45, rel=1e-9)
    runout = 2 * math.tan(ALPHA) * (0.022 + 0.015) / 2 * 1000
    assert d.backlash_budget_um["runout_worst_case"] == pytest.approx(runout, rel=1e-9)
    assert d.design_lost_motion_arcmin == pytest.approx(6.876 * (j_t + runout) / 45, rel=1e-9)
    assert d.design_lost_motion_arcmin == pytest.approx(6.341, abs=0.002)
    assert designs[2].design_lost_motion_arcmin == pytest.approx(6.06, abs=0.005)
    assert format_arcmin(d.design_lost_motion_arcmin) == "6'20\""


def test_eq1_printed_factor_is_the_rounded_exact_one():
    exact = geo.EQ1_EXACT_FACTOR
    assert exact == pytest.approx(6.8755, abs=1e-4)  # printed 6.876
    assert geo.backlash_arcmin_from_um(45.0, 1.0, 45) == pytest.approx(6.876)


def test_eq4_period_is_eight_crank_revolutions_not_twenty():
    assert geo.center_distance_period_rev(45, 40) == 8
    theta = np.linspace(0.0, 2 * np.pi, 97)
    kw = dict(eccentric_distance_mm=2.5, eccentricity_internal_mm=0.0125,
              eccentricity_external_mm=0.009, z_internal=45, z_external=40, beta_rad=0.3)
    base = runout_center_distance_mm(theta, **kw)
    for rev in range(1, 8):
        shifted = runout_center_distance_mm(theta + 2 * np.pi * rev, **kw)
        assert np.max(np.abs(shifted - base)) > 1e-4, f"repeats after {rev} revolutions"
    assert np.allclose(runout_center_distance_mm(theta + 16 * np.pi, **kw), base, atol=1e-12)
    # the printed "20 r" is not a period
    assert np.max(np.abs(runout_center_distance_mm(theta + 40 * np.pi, **kw) - base)) > 1e-3


def test_eq4_extremes_are_eqs_5_and_6():
    """Eq. (4) over 8 revolutions: max = eq. (5) when beta = 0 (at theta = 0); min = eq. (6)
    when beta puts B outward as O1O2 points back (beta = -pi/8 at theta = pi); for any beta the
    curve stays between them."""
    o, e1, e2 = 2.5, 0.0125, 0.009
    kw = dict(eccentric_distance_mm=o, eccentricity_internal_mm=e1,
              eccentricity_external_mm=e2, z_internal=45, z_external=40)
    theta = np.linspace(0.0, 16 * np.pi, 16 * 2000 + 1)
    top = geo.center_distance_max_mm(o, e1, e2)
    bottom = geo.center_distance_min_mm(o, e1, e2)
    assert top == pytest.approx(2.5215) and bottom == pytest.approx(2.4785)
    assert runout_center_distance_mm(theta, beta_rad=0.0, **kw).max() == pytest.approx(top)
    assert runout_center_distance_mm(
        np.array([np.pi]), beta_rad=-np.pi / 8, **kw
    )[0] == pytest.approx(bottom, abs=1e-12)
    for beta in np.linspace(0, 2 * np.pi, 7):
        curve = runout_center_distance_mm(theta, beta_rad=beta, **kw)
        assert curve.max() <= top + 1e-12 and curve.min() >= bottom - 1e-12
        # the swing of |AB| over the shaft angle is close to Fr1 + Fr2 = 2 (e1 + e2)
        assert curve.max() - curve.min() == pytest.approx(2 * (e1 + e2), rel=0.02)


def test_eq15_standard_and_printed_forms():
    """Small shifts: standard a' - a0 -> m (x1 - x2); printed -> m (x1 - x2) / tan(alpha)."""
    dx = 1e-4
    for form, expected in (("standard", dx), ("paper", dx / math.tan(ALPHA))):
        angle = geo.working_pressure_angle_rad(dx, 0.0, 45, 40, ALPHA, form)
        a_zero = geo.zero_backlash_center_distance_mm(2.5, ALPHA, angle)
        assert a_zero - 2.5 == pytest.approx(expected, rel=1e-3)
    with pytest.raises(AnalysisError):
        geo.working_pressure_angle_rad(0.01, 0.0, 45, 40, ALPHA, "other")  # type: ignore[arg-type]


def test_standard_form_is_about_50um_lower_and_interferes_at_the_paper_distance(designs):
    for n in (1, 2):
        d = designs[n]
        gap_um = 1000 * (d.zero_backlash_center_distance_mm["paper"]
                         - d.zero_backlash_center_distance_mm["standard"])
        assert 40.0 < gap_um < 60.0
        check = d.fit_check["standard_form_at_paper_eccentric_distance"]
        assert check["verdict"] == "interference" and check["margin_um"] < -40.0
    # the unit set at the paper's own 2.572 mm: the printed form clears, the standard interferes
    d = design_chain({**load(1), "center_distance_mm": 2.572})
    at = d.fit_check["at_center_distance"]
    assert at["standard"]["verdict"] == "interference"
    assert at["paper"]["verdict"] == "clearance"
    assert d.design_lost_motion_arcmin is None  # eqs. (2)-(3) give negative play there
    assert any("interference" in a for a in d.assumptions)


def test_eq9_puts_the_largest_center_distance_at_the_zero_backlash_one(designs):
    for n in (1, 2):
        d = designs[n]
        for form in ("standard", "paper"):
            a_set = d.recommended_eccentric_distance_mm[form]
            unit = design_chain(
                {**load(n), "center_distance_mm": a_set}
            ).fit_check["at_center_distance"][form]
            assert unit["margin_um"] == pytest.approx(0.0, abs=1e-6)


def test_pair_files_3_and_4_sit_at_the_standard_recommendation(designs):
    for compensated, original in ((3, 1), (4, 2)):
        target = designs[original].recommended_eccentric_distance_mm["standard"]
        assert designs[compensated].unit.center_distance_mm == pytest.approx(target, abs=1e-4)
        assert designs[compensated].unit.center_distance_mm <= target  # rounded down: no contact
        verdict = designs[compensated].fit_check["at_center_distance"]["standard"]
        assert verdict["verdict"] == "clearance"


def test_bearing_clearance_override_moves_eq9_by_half_the_sum(designs):
    base = designs[1].recommended_eccentric_distance_mm["standard"]
    more = design_chain(load(1), bearing_clearance_mm=[0.010, 0.010])
    assert more.recommended_eccentric_distance_mm["standard"] - base == pytest.approx(
        (0.020 - 0.011) / 2
    )
    with pytest.raises(AnalysisError, match="bearing_clearance_mm"):
        design_chain(load(1), bearing_clearance_mm=[-0.001])


def test_unknown_data_is_said_not_zeroed():
    unit, assumptions = InternalPairUnit.from_mapping(
        {"z_internal": 45, "z_external": 40, "module_mm": 1.0, "colour": "blue"}
    )
    text = "\n".join(assumptions)
    assert "unknown unit key 'colour' ignored" in text
    assert "face_width_mm missing" in text and "runout_internal_mm missing" in text
    assert unit.center_distance_mm == 2.5 and unit.pressure_angle_deg == 20.0
    d = design_chain({"z_internal": 45, "z_external": 40, "module_mm": 1.0})
    assert d.equivalent_shift_coeff == {"internal": 0.0, "external": 0.0}
    assert d.zero_backlash_center_distance_mm["standard"] == pytest.approx(2.5)
    assert d.design_lost_motion_arcmin is None and d.torsional_stiffness_Nm_per_arcmin is None
    assert d.recommended_eccentric_distance_mm == {"standard": None, "paper": None}
    assert any("runouts unknown" in a for a in d.assumptions)


@pytest.mark.parametrize(
    ("change", "key"),
    [
        ({"z_internal": 40.5}, "z_internal"),
        ({"z_internal": True}, "z_internal"),
        ({"z_external": 50}, "z_internal"),
        ({"module_mm": -1}, "module_mm"),
        ({"module_mm": None}, "module_mm"),
        ({"pressure_angle_deg": 60}, "pressure_angle_deg"),
        ({"m_value_internal_mm": [42.4, "x"]}, "m_value_internal_mm[1]"),
        ({"m_value_external_mm": []}, "m_value_external_mm"),
        ({"runout_internal_mm": -0.01}, "runout_internal_mm"),
        ({"kind": "cycloid"}, "kind"),
    ],
)
def test_bad_values_name_the_key(change, key):
    with pytest.raises(AnalysisError, match=key.replace("[", r"\[").replace("]", r"\]")):
        InternalPairUnit.from_mapping({**load(1), **change})


def test_m_values_without_pin_diameter_are_an_error():
    unit = {k: v for k, v in load(1).items() if k != "pin_diameter_mm"}
    with pytest.raises(AnalysisError, match="pin_diameter_mm"):
        design_chain(unit)


def test_unit_round_trips_through_its_mapping():
    unit, assumptions = InternalPairUnit.from_mapping(load(2))
    assert assumptions == []
    again, _ = InternalPairUnit.from_mapping(unit.to_mapping())
    assert again == unit


# ---- the `rig model` command ------------------------------------------------------------------

KEYS = (
    "equivalent_shift_mm", "zero_backlash_center_distance_mm",
    "recommended_eccentric_distance_mm", "design_lost_motion_arcmin",
    "compensated_lost_motion_arcmin", "nominal_play_arcmin",
    "torsional_stiffness_Nm_per_arcmin", "assumptions", "center_distance_period_rev",
)


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_rig_model_on_the_pair_files(n, tmp_path):
    from rig.cli import app

    out = tmp_path / "model.json"
    result = CliRunner().invoke(app, ["model", str(UNITS / f"seed000-pair{n}.json"),
                                      "--json", str(out)])
    assert result.exit_code == 0, result.output
    assert "Seed 000 model" in result.output
    doc = json.loads(out.read_text())
    for key in KEYS:
        assert key in doc
    assert set(doc["zero_backlash_center_distance_mm"]) == {"standard", "paper"}
    assert set(doc["equivalent_shift_mm"]) == {"internal", "external"}
    assert doc["center_distance_period_rev"] == 8
    assert doc["assumptions"] == []
    assert doc["torsional_stiffness_Nm_per_arcmin"] > 27.0
    paper = arcmin(PAPER_LOST_MOTION[n])
    key = "design_lost_motion_arcmin" if n <= 2 else "compensated_lost_motion_arcmin"
    assert abs(doc[key] - paper) * 60 <= 10.0


def test_rig_model_reads_a_whole_run_json(tmp_path):
    run = {"format": "rig-run/1", "run_id": "x", "unit": load(1), "test": {}}
    path = tmp_path / "run.json"
    path.write_text(json.dumps(run))
    out = tmp_path / "m.json"
    proc = subprocess.run(
        [sys.executable, "-c", "from rig.cli import main; main()", "model", str(path),
         "--json", str(out)],
        capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert json.loads(out.read_text())["nominal_play_arcmin"] == pytest.approx(4.2823, abs=1e-4)


@pytest.mark.parametrize(
    ("content", "expect"),
    [
        ('{"unit": {\n  "z_internal": 45,,\n}}', "bad.json:2:"),
        ('{"z_internal": 45, "z_external": 50, "module_mm": 1}', "z_internal"),
        ("[1, 2]", "expected a JSON object"),
    ],
)
def test_rig_model_bad_file_is_one_line_exit_2(content, expect, tmp_path):
    path = tmp_path / "bad.json"
    path.write_text(content)
    proc = subprocess.run(
        [sys.executable, "-c", "from rig.cli import main; main()", "model", str(path)],
        capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and expect in lines[0] and str(path) in lines[0]
