"""backlash-rig: run format, sequencer, campaigns, store, CLI and web page.

``import rig`` is also the Python API for scripts and notebooks (docs/python-api.md)::

    run = rig.open("rig/examples/runs/pair1-pos000")    # or a campaign, or a store id
    run.to_pandas()          # samples with a twist_arcmin column
    run.results()            # one tidy row per run: metrics ± u, model, limits, outcome
    rig.analyse(run).to_dict() == the JSON of `rig analyse --json`

The API (:mod:`rig.api`) is imported on first use, so ``import rig`` (and ``rig version``)
stays fast. The packages and their layers: docs/architecture.md.
"""

import importlib
from typing import Any

__version__ = "0.1.0"

__all__ = [
    "Analysis", "Campaign", "Connection", "Diagnosis", "Model", "Run", "Store", "TWIST_COLUMN",
    "__version__", "analyse", "connect", "diagnose", "model", "open",
]

_API_NAMES = frozenset(__all__) - {"__version__"}


def __getattr__(name: str) -> Any:
    if name in _API_NAMES:
        value = getattr(importlib.import_module("rig.api"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'rig' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | _API_NAMES)
