"""Benchmarks: ``python -m bench [NAME ...]`` prints one JSON line per figure.

Each module ``bench/bench_*.py`` defines ``run() -> Iterable[dict]`` yielding
``{"name": ..., "value": ..., "unit": ...}`` (more keys welcome, e.g. ``"target"``).
"""
