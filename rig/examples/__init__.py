"""Bundled example runs and units (see ``python -m rig.examples.generate``)."""

from __future__ import annotations

from pathlib import Path

EXAMPLES_DIR = Path(__file__).resolve().parent
RUNS_DIR = EXAMPLES_DIR / "runs"
UNITS_DIR = EXAMPLES_DIR / "units"
