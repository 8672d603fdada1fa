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
import json
from pathlib import Path
from typing import Any

import numpy as np

from rig.core.errors import RigError
from rig.core.ids import id_from_text, id_problem
from rig.core.json_files import read_json_file
from rig.core.ranges import (
    ANGLE_READING_DEG,
    TEMPERATURE_READING_C,
    TORQUE_READING_MAX_RATED,
)
from rig.io.map import (
    ABSOLUTE_ZERO_C,
    COLUMN_KINDS,
    RunImportError,
    convert_unit,
    load_map,
    resolve_unit,
)
from rig.io.read import SourceData, read_source
from rig.io.safe_write import atomic_folder, check_target
from rig.runformat import (
    REQUIRED_COLUMNS,
    RUN_JSON,
    SAMPLES_CSV,
    SAMPLES_PARQUET,
    Run,
    write_samples_parquet,
)
from rig.runformat.csvwrite import csv_line, samples_text
from rig.runformat.meta_check import unit_problems

__all__ = ["MIN_STEP_S", "check_run_id", "import_run", "read_unit", "store_imported",
           "write_imported"]


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
    return id_from_text(path.stem, "imported")


def check_run_id(run_id: str, where: str) -> str:
    """``run_id`` if it is a valid run id (:mod:`rig.core.ids`), else one line naming ``where``
    it came from (``--run-id``, the map's ``run_id``)."""
    problem = id_problem(run_id, "run")
    if problem is not None:
        raise RunImportError(f"{where}: {problem}")
    return run_id


def import_run(source: str | Path, map_path: str | Path, unit_path: str | Path,
               run_id: str | None = None) -> Run:
    """The run the file ``source`` holds, read through the map ``map_path``, for the unit of
    ``unit_path``. ``run_id``: default the map's ``run_id``, else the file's stem."""
    src, map_file = Path(source), Path(map_path)
    if run_id is not None:
        check_run_id(run_id, "--run-id")
    mapping = load_map(map_file)
    unit = read_unit(unit_path)
    if mapping.file_format(src) == "csv" and mapping.columns.t_s is None:
        raise RunImportError(f"{map_file}: columns.t_s: a delimited file needs its time "
                             "column mapped (only a TDMS file can take the time from its "
                             "waveform timing)")
    data = read_source(src, mapping)
    refs = mapping.columns.model_dump(exclude_none=True)
    for name in COLUMN_KINDS:  # a rig-run/1 column by its own name (a rig export): as mapped
        if name not in refs and isinstance(data.extra.get(name), np.ndarray):
            data.values[name] = data.extra.pop(name)
    columns: dict[str, np.ndarray] = {}
    for name in COLUMN_KINDS:
        if name in data.values:
            kind = COLUMN_KINDS[name]
            unit_name = resolve_unit(kind, refs.get(name, {}).get("unit"),
                                     data.units.get(name), data.where(name, None))
            columns[name] = convert_unit(data.values[name], kind, unit_name)
    _check_samples(columns, data, mapping.test.rated_torque_Nm)
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
            extra_columns=_extra_columns(data),
        )
    except ValueError as exc:
        raise RunImportError(f"{src}: {exc}") from None


def _extra_columns(data: SourceData) -> dict[str, np.ndarray | list[str]]:
    """The file's unmapped columns, kept under their own names (rig-run/1 keeps extra
    columns); one named like a run column the map fills from another column is kept as
    ``<name>_file``. (An unmapped numeric column named like a run column the map does not
    fill is that run column, in the run's unit: :func:`import_run`.)"""
    out: dict[str, np.ndarray | list[str]] = {}
    for name, values in data.extra.items():
        key = name
        while key in COLUMN_KINDS or key in out:
            key = f"{key}_file"
        out[key] = values
    return out


MIN_STEP_S = 1e-9
"""The smallest time step (s) a sampled file can hold: 1 ns, a 1 GHz sample rate."""


def _check_samples(columns: dict[str, np.ndarray], data: SourceData,
                   rated_torque_Nm: float) -> None:
    """What rig-run/1 and a measured loop need, each refusal naming the file, the line (or
    sample) and the column: finite time, torque and output angle; time strictly ascending in
    steps of at least :data:`MIN_STEP_S`; temperatures finite and above absolute zero
    (blank = not measured); every reading in its physical range (:mod:`rig.core.ranges`:
    torques within ``TORQUE_READING_MAX_RATED`` x ``rated_torque_Nm`` N·m, angles and
    temperatures); at least ``MIN_LOOP_SAMPLES`` samples; a torque that moves."""
    from rig.results.analyse import MIN_LOOP_SAMPLES

    n = len(columns["t_s"])
    if n == 0:
        raise RunImportError(f"{data.where('t_s', None)}: no samples")
    for name in REQUIRED_COLUMNS:
        bad = np.flatnonzero(~np.isfinite(columns[name]))
        if bad.size:
            i = int(bad[0])
            raise RunImportError(f"{data.where(name, i)}: {name} needs a finite value, got "
                                 f"{float(data.values[name][i])!r}")
    t = columns["t_s"]
    steps = np.diff(t)
    bad = np.flatnonzero(~(steps > 0))
    if bad.size:
        i = int(bad[0]) + 1
        raise RunImportError(f"{data.where('t_s', i)}: time must be strictly ascending: "
                             f"{float(data.values['t_s'][i])!r} after "
                             f"{float(data.values['t_s'][i - 1])!r}")
    bad = np.flatnonzero(steps < MIN_STEP_S)
    if bad.size:
        i = int(bad[0]) + 1
        raise RunImportError(f"{data.where('t_s', i)}: a time step of {float(steps[i - 1]):g} s "
                             f"(from {float(data.values['t_s'][i - 1])!r} to "
                             f"{float(data.values['t_s'][i])!r}) is below {MIN_STEP_S:g} s: "
                             "no sampled measurement; is the time column's unit right?")
    if "temperature_C" in columns:
        temp = columns["temperature_C"]
        with np.errstate(invalid="ignore"):
            bad = np.flatnonzero(np.isinf(temp) | (temp < ABSOLUTE_ZERO_C))
        if bad.size:
            i = int(bad[0])
            raise RunImportError(f"{data.where('temperature_C', i)}: temperature "
                                 f"{float(temp[i])!r} °C is not a temperature (finite, at "
                                 f"least {ABSOLUTE_ZERO_C} °C); is the column's unit right?")
    _check_ranges(columns, data, rated_torque_Nm)
    if n < MIN_LOOP_SAMPLES:
        raise RunImportError(f"{data.where('torque_Nm', None)}: {n} sample"
                             f"{'' if n == 1 else 's'}; a hysteresis loop needs at least "
                             f"{MIN_LOOP_SAMPLES}")
    torque = columns["torque_Nm"]
    if not np.any(torque):
        raise RunImportError(f"{data.where('torque_Nm', None)}: the torque is 0 N·m in all {n} "
                             "samples: no loop was measured (is the right column mapped?)")
    if float(np.ptp(torque)) == 0.0:
        raise RunImportError(f"{data.where('torque_Nm', None)}: the torque is "
                             f"{float(torque[0])!r} N·m in all {n} samples: no loop was "
                             "measured")


def _check_ranges(columns: dict[str, np.ndarray], data: SourceData,
                  rated_torque_Nm: float) -> None:
    """Every reading in its physical range (:mod:`rig.core.ranges`), the first one outside
    named by file, line (or sample) and column, in the run's unit."""
    limit = TORQUE_READING_MAX_RATED * rated_torque_Nm
    ranges = {"torque_Nm": (-limit, limit, f"N·m (at most {TORQUE_READING_MAX_RATED:g} x the "
                                           f"rated {rated_torque_Nm:g} N·m in magnitude)"),
              "output_angle_deg": (ANGLE_READING_DEG.low, ANGLE_READING_DEG.high, "deg"),
              "input_angle_deg": (ANGLE_READING_DEG.low, ANGLE_READING_DEG.high, "deg"),
              "temperature_C": (TEMPERATURE_READING_C.low, TEMPERATURE_READING_C.high, "°C")}
    for name, (low, high, unit) in ranges.items():
        if name not in columns:
            continue
        values = columns[name]
        with np.errstate(invalid="ignore"):
            bad = np.flatnonzero((values < low) | (values > high))
        if bad.size:
            i = int(bad[0])
            raise RunImportError(f"{data.where(name, i)}: {name} {float(values[i])!r} is no "
                                 f"reading: expected from {low:g} to {high:g} {unit}; is the "
                                 "column's unit right?")


CSV_CHUNK_ROWS = 200_000
"""Rows formatted at a time when a run folder is written (the text of a whole large run is
never held at once)."""


def write_imported(run: Run, folder: str | Path, *, force: bool = False,
                   source: Path | None = None) -> Path:
    """Write ``run`` as a rig-run/1 folder (run.json + samples.csv, as
    :func:`rig.runformat.write_run` writes them); the folder. Never into a store or a run
    folder, an existing folder only with ``force`` (:func:`rig.io.safe_write.check_target`),
    all or nothing."""
    out = check_target(Path(folder), folder=True, force=force,
                       sources=[source] if source is not None else [])
    with atomic_folder(out) as tmp:
        with open(tmp / SAMPLES_CSV, "w", encoding="utf-8", newline="") as f:
            f.write(csv_line(run.columns))
            for start in range(0, run.n_samples, CSV_CHUNK_ROWS):
                part = {c: run.data[c][start:start + CSV_CHUNK_ROWS] for c in run.columns}
                text = samples_text(run.columns, part)
                f.write(text[text.index("\n") + 1:])
        (tmp / RUN_JSON).write_text(json.dumps(run.meta, indent=2, ensure_ascii=False) + "\n",
                                    encoding="utf-8")
    return out


def store_imported(run: Run, store_root: str | Path, *,
                   samples: str | Path | None = None,
                   campaign_id: str | None = None) -> str:
    """Add ``run`` to the store as a completed run (samples in Parquet, as measured runs);
    its metrics from ``rig analyse`` go to run.json ``result`` (None if they cannot be
    computed, the reason logged in ``result_error``). Returns the store's run id.

    The samples are written straight to the run's ``samples.parquet`` (not streamed row by
    row through the recorder's CSV): the recorder then finds the Parquet file in place and
    only drops its empty CSV (:func:`rig.store.files.finalise_samples`)."""
    from rig.store import Store

    st = Store(store_root, samples=samples)
    st.check_writable("the imported run")
    meta = {k: v for k, v in run.meta.items() if k not in ("format", "run_id", "started_at")}
    meta.setdefault("label", run.run_id)
    result, extra = _result(run)
    from rig.results.outcome import run_outcome  # the verdict, as a measured run records it

    limits = meta.get("limits") if isinstance(meta.get("limits"), dict) else None
    extra["outcome"] = run_outcome({**meta, "status": "completed", "result": result or {}},
                                   limits)[0]
    recorder = st.begin_run(meta, list(run.columns), campaign_id=campaign_id)
    with recorder:
        write_samples_parquet(recorder.path / SAMPLES_PARQUET, list(run.columns), run.data)
        recorder.n_samples = run.n_samples
        recorder.finish("completed", result=result, extra=extra)
    return recorder.run_id


def _result(run: Run) -> tuple[dict[str, Any] | None, dict[str, Any]]:
    """The analysed metrics (with uncertainty and model) for run.json ``result``."""
    from analysis.errors import AnalysisError
    from rig.core.json_files import finite_for_json
    from rig.results.analyse import METRIC_KEYS, analyse_run

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
