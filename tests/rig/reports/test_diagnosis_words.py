"""The diagnosis report's sentence in plain words (rig/reports/diagnosis_html.py)."""

from __future__ import annotations

from rig.reports.diagnosis_html import _plain_words

UNEXPLAINED = {"verdict": "unexplained", "gap_before": {"rms_arcsec": 3.2},
               "noise_arcsec": 0.4}


def test_unexplained_with_no_candidate_close_says_so() -> None:
    """Issue 33 item 19: with no candidate close the report printed "closest: )."."""
    for report in ({**UNEXPLAINED, "candidates": []}, UNEXPLAINED):
        text = _plain_words(report)
        assert "closest: )" not in text and "()" not in text, text
        assert text.endswith("no effect of the vocabulary comes close."), text


def test_unexplained_names_the_closest_candidates_escaped() -> None:
    text = _plain_words({**UNEXPLAINED, "candidates": ["thermal", "<b>x</b>"]})
    assert "(closest: thermal, &lt;b&gt;x&lt;/b&gt;)." in text, text
