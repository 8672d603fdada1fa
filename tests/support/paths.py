"""Where the tests find the repository and their data, wherever a test module sits."""

from __future__ import annotations

from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
"""The repository's root folder (the checkout)."""
TESTS = REPO / "tests"
"""The test suite's folder."""
TEST_DATA = TESTS / "data"
"""Recorded campaigns, development-set cases and an old store kept for the tests."""
