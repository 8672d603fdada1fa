"""``rig import``: another lab's file (delimited text or NI TDMS) as a rig-run/1 run.

:func:`import_run` reads the file through its map (:mod:`rig.io.map`), converts the units to
the run's (s, N·m, deg, °C), checks what rig-run/1 requires (finite time, torque and output
angle; strictly ascending time) and returns a :class:`rig.runformat.Run` whose run.json
carries the unit of ``--unit``, the map's ``test`` and ``sensors`` and
``source: {file, map, format, sha256}``. :func:`write_imported` writes it as a run folder;
:func:`store_imported` adds it to a store as a finished run.
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path
from typing import Any

import numpy as np

from rig.errors import RigError
from rig.io.map import COLUMN_KINDS, RunImportError, convert_unit, load_map
from rig.io.read import read_source
from rig.json_files import read_json_file
from rig.run_meta_check import unit_problems
from rig.runformat import REQUIRED_COLUMNS, Run, write_run

__all__ = ["import_run", "read_unit", "store_imported", "write_imported"]


def read_unit(path: str | Path) -> dict[str, Any]:
    """The unit data (run.json ``unit`` object) of a JSON file; one-line error otherwise."""
    unit = read_json_file(path, RunImportError, "unit data")
    if not isinstance(unit, dict):
        raise RunImportError(f"{path}: the unit data must be a JSON object, got "
                             f"{type(unit).__name__}")
    problems = unit_problems(unit)
    if problems:
        raise RunImportError(f"{path}: {problems[0]}")
    return unit


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _default_run_id(path: Path) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", path.stem).strip("._") or "imported"


def import_run(source: str | Path, map_path: str | Path, unit_path: str | Path,
               run_id: str | None = None) -> Run:
    """The run the file ``source`` holds, read through the map ``map_path``, for the unit of
    ``unit_path``. ``run_id``: default the map's ``run_id``, else the file's stem."""
    src, map_file = Path(source), Path(map_path)
    mapping = load_map(map_file)
    unit = read_unit(unit_path)
    data = read_source(src, mapping)
    refs = mapping.columns.model_dump(exclude_none=True)
    columns: dict[str, np.ndarray] = {}
    for name in COLUMN_KINDS:
        if name in data.values:
            unit_name = refs.get(name, {}).get("unit")
            columns[name] = convert_unit(data.values[name], COLUMN_KINDS[name], unit_name)
    if len(columns["t_s"]) == 0:
        raise RunImportError(f"{data.where('t_s', None)}: no samples")
    for name in REQUIRED_COLUMNS:
        bad = np.flatnonzero(~np.isfinite(columns[name]))
        if bad.size:
            i = int(bad[0])
            raise RunImportError(f"{data.where(name, i)}: {name} needs a finite value, got "
                                 f"{float(data.values[name][i])!r}")
    t = columns["t_s"]
    bad = np.flatnonzero(~(np.diff(t) > 0))
    if bad.size:
        i = int(bad[0]) + 1
        raise RunImportError(f"{data.where('t_s', i)}: time must be strictly ascending: "
                             f"{float(data.values['t_s'][i])!r} after "
                             f"{float(data.values['t_s'][i - 1])!r}")
    source_meta = {"file": str(src), "map": str(map_file), "format": data.format,
                   "sha256": _sha256(src)}
    try:
        return Run.from_arrays(
            run_id or mapping.run_id or _default_run_id(src),
            columns.pop("t_s"), columns.pop("torque_Nm"), columns.pop("output_angle_deg"),
            input_angle_deg=columns.get("input_angle_deg"),
            temperature_C=columns.get("temperature_C"),
            unit=unit, test=mapping.test_meta(), sensors=mapping.sensors or None,
            extra_meta={"source": source_meta},
        )
    except ValueError as exc:
        raise RunImportError(f"{src}: {exc}") from None


def write_imported(run: Run, folder: str | Path) -> Path:
    """Write ``run`` as a rig-run/1 folder (run.json + samples.csv); the folder."""
    out = Path(folder)
    if out.exists() and not out.is_dir():
        raise RunImportError(f"{out}: exists and is not a folder")
    return write_run(run, out)


def store_imported(run: Run, store_root: str | Path, *,
                   samples: str | Path | None = None,
                   campaign_id: str | None = None) -> str:
    """Add ``run`` to the store as a completed run (samples in Parquet, as measured runs);
    its metrics from ``rig analyse`` go to run.json ``result`` (None if they cannot be
    computed, the reason logged in ``result_error``). Returns the store's run id."""
    from rig.store import Store

    st = Store(store_root, samples=samples)
    meta = {k: v for k, v in run.meta.items() if k not in ("format", "run_id", "started_at")}
    meta.setdefault("label", run.run_id)
    result, extra = _result(run)
    from rig.outcome import run_outcome  # the verdict, as a measured run records it

    limits = meta.get("limits") if isinstance(meta.get("limits"), dict) else None
    extra["outcome"] = run_outcome({**meta, "status": "completed", "result": result or {}},
                                   limits)[0]
    recorder = st.begin_run(meta, list(run.columns), campaign_id=campaign_id)
    with recorder:
        arrays = [run.data[c] for c in run.columns]
        for row in zip(*(a.tolist() if isinstance(a, np.ndarray) else a for a in arrays),
                       strict=True):
            recorder.append(row)
        recorder.finish("completed", result=result, extra=extra)
    return recorder.run_id


def _result(run: Run) -> tuple[dict[str, Any] | None, dict[str, Any]]:
    """The analysed metrics (with uncertainty and model) for run.json ``result``."""
    from analysis.errors import AnalysisError
    from rig.analyse import METRIC_KEYS, analyse_run
    from rig.json_files import finite_for_json

    try:
        d = analyse_run(run).to_dict()
    except (RigError, AnalysisError, ValueError) as exc:
        return None, {"result_error": str(exc)}
    result = {k: d.get(k) for k in METRIC_KEYS}
    result["uncertainty"] = d.get("uncertainty") or {}
    if d.get("errors"):
        result["errors"] = d["errors"]
    result["model"] = d.get("model")
    return finite_for_json(result), {}
