"""Run the benchmarks and print JSON lines ``{"name", "value", "unit", ...}``.

Usage: ``python -m bench`` (all) or ``python -m bench loop montecarlo`` (modules whose
name contains any of the words; a word that is a module's whole name after ``bench_``
selects that module alone: ``python -m bench te`` is bench_te, not also montecarlo).
"""

from __future__ import annotations

import importlib
import json
import pkgutil
import sys
from pathlib import Path


def main(argv: list[str]) -> int:
    here = Path(__file__).resolve().parent
    names = sorted(
        info.name for info in pkgutil.iter_modules([str(here)]) if info.name.startswith("bench_")
    )
    if argv:
        names = [n for n in names if any(
            n == f"bench_{word}" if f"bench_{word}" in names else word in n for word in argv)]
    failed = 0
    for name in names:
        module = importlib.import_module(f"bench.{name}")
        try:
            for row in module.run():
                print(json.dumps(row), flush=True)
        except Exception as exc:  # report and go on with the other benchmarks
            failed += 1
            print(json.dumps({"name": name, "error": f"{type(exc).__name__}: {exc}"}), flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
