"""backlash-rig: run format, sequencer, campaigns, store, CLI and web page.

``import rig`` is also the Python API for scripts and notebooks (docs/python-api.md)::

    run = rig.open("rig/examples/runs/pair1-pos000")    # or a campaign, or a store id
    run.to_pandas()          # samples with a twist_arcmin column
    run.results()            # one tidy row per run: metrics ± u, model, limits, outcome
    rig.analyse(run).to_dict() == the JSON of `rig analyse --json`

The API is imported on first use, so ``import rig`` (and ``rig version``) stays fast.
``rig.analyse`` and ``rig.diagnose`` are the API functions when called and the modules
:mod:`rig.analyse` / :mod:`rig.diagnose` for attribute access (``rig.analyse.analyse_run``).
"""

import importlib
import sys
import types
from typing import Any

__version__ = "0.1.0"

__all__ = [
    "Analysis", "Campaign", "Connection", "Diagnosis", "Model", "Run", "Store", "TWIST_COLUMN",
    "__version__", "analyse", "connect", "diagnose", "model", "open",
]

_API_NAMES = frozenset(__all__) - {"__version__", "analyse", "diagnose"}


class _FunctionAndModule:
    """``rig.analyse`` / ``rig.diagnose``: calling it calls :mod:`rig.api`'s function of that
    name; any attribute is the submodule's (``rig.analyse.analyse_run`` keeps working)."""

    def __init__(self, name: str) -> None:
        object.__setattr__(self, "_name", name)

    def _module(self) -> types.ModuleType:
        return importlib.import_module(f"rig.{self._name}")

    @property
    def __wrapped__(self) -> Any:  # inspect.signature and help() show the API function
        return getattr(importlib.import_module("rig.api"), self._name)

    @property
    def __doc__(self) -> str | None:  # type: ignore[override]
        return self.__wrapped__.__doc__

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return self.__wrapped__(*args, **kwargs)

    def __getattr__(self, attr: str) -> Any:
        return getattr(self._module(), attr)

    def __setattr__(self, attr: str, value: Any) -> None:
        setattr(self._module(), attr, value)

    def __delattr__(self, attr: str) -> None:
        delattr(self._module(), attr)

    def __dir__(self) -> list[str]:
        return dir(self._module())

    def __repr__(self) -> str:
        return f"<function rig.{self._name} (and module rig.{self._name})>"


analyse = _FunctionAndModule("analyse")
diagnose = _FunctionAndModule("diagnose")


class _Package(types.ModuleType):
    """The ``rig`` package: importing the submodule ``rig.analyse`` or ``rig.diagnose`` does not
    replace the API entry of that name (it reaches the submodule's attributes)."""

    def __setattr__(self, name: str, value: Any) -> None:
        if name in ("analyse", "diagnose") and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)


def __getattr__(name: str) -> Any:
    if name in _API_NAMES:
        value = getattr(importlib.import_module("rig.api"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'rig' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | _API_NAMES)


sys.modules[__name__].__class__ = _Package
