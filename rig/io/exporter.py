"""``rig export``: a run or a campaign in the formats other tools read.

A run (its sample columns, then ``twist_arcmin``: the twist in arcmin centred on the loop,
:func:`rig.results.analyse.sample_twist_arcmin`, the column the Python API's ``.to_pandas()``
adds; a
``twist_arcmin`` the run already holds is recomputed, never doubled; a transmission error run
also ``te_arcsec`` before it, each sample's TE, :func:`rig.results.te.sample_te_arcsec`):

- ``csv``: a rig-run/1 run folder (run.json + samples.csv), :func:`rig.runformat.write_run`;
  its columns read back bit for bit.
- ``parquet``: one file of the samples (float64 columns, text columns as strings) whose
  schema metadata ``run.json`` holds the run.json text.
- ``mat``: MATLAB (``scipy.io.savemat``, v5): one variable per column (numeric columns as
  column vectors, text columns as cell arrays; a name MATLAB does not accept is changed, the
  ``columns`` / ``variables`` cells pair them), ``run_id`` and ``meta_json``, the run.json
  text (``jsondecode(meta_json)`` in MATLAB).
- ``xlsx``: sheet ``samples`` and sheet ``meta`` (dotted key, value; lists as JSON text).
  Numbers carry 16 significant digits (openpyxl writes ``%.16g``, Excel's own precision):
  within 1e-15 relative, not bit for bit; use csv, parquet or mat for that.

A campaign: its tidy results table (:mod:`rig.results.table`, one row per run, the table of
``rig.open(...).results()``) as CSV, Parquet, MATLAB (one variable per column) or XLSX
(sheets ``results`` and ``campaign``).
Units follow the column names (s, N·m, deg, °C, arcmin, J).
"""

from __future__ import annotations

import gc
import json
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from rig.core.errors import RigError
from rig.core.ids import id_from_text, id_problem
from rig.io.safe_write import atomic_file, atomic_folder, check_target
from rig.runformat import Campaign, Run, write_run

__all__ = ["FORMATS", "XLSX_MAX_ROWS", "ExportError", "default_out", "export_campaign",
           "export_run", "matlab_names", "meta_rows", "resolve_target", "with_twist"]

FORMATS = ("csv", "parquet", "mat", "xlsx")
XLSX_MAX_ROWS = 1_048_576
"""Rows of an Excel sheet, the header included."""


class ExportError(RigError):
    """A run or campaign that cannot be written in the format asked (one line, exit 2)."""


def _check_format(fmt: str) -> str:
    if fmt not in FORMATS:
        raise ExportError(f"--format {fmt!r}: use one of {', '.join(FORMATS)}")
    return fmt


def default_out(name: str, fmt: str, campaign: bool) -> Path:
    """``<name>`` (a run folder) for a run as csv, else ``<name>[-results].<fmt>``."""
    if fmt == "csv" and not campaign:
        return Path(name)
    return Path(f"{name}-results.{fmt}" if campaign else f"{name}.{fmt}")


RUN_MAT_VARIABLES = ("run_id", "meta_json", "columns", "variables")
"""The variables a run's .mat holds besides its columns."""
CAMPAIGN_MAT_VARIABLES = ("meta_json", "columns", "variables")
"""The variables a campaign's .mat holds besides its table's columns (its ``run_id`` is the
table's column)."""


def matlab_names(columns: list[str], reserved: tuple[str, ...] = RUN_MAT_VARIABLES
                 ) -> list[str]:
    """Valid, distinct MATLAB variable names for ``columns`` (at most 63 characters, a
    letter first, letters, digits and ``_``), none of ``reserved`` (the file's other
    variables)."""
    out: list[str] = []
    for name in columns:
        base = re.sub(r"\W", "_", name, flags=re.ASCII)
        if not base or not base[0].isalpha():
            base = f"c_{base}"
        base = base[:63]
        candidate, n = base, 1
        while candidate in out or candidate in reserved:
            n += 1
            candidate = f"{base[:60]}_{n}"
        out.append(candidate)
    return out


def meta_rows(meta: dict[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    """``meta`` flattened to (dotted key, value) rows: objects opened, lists and null as
    JSON text."""
    rows: list[tuple[str, Any]] = []
    for key, value in meta.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, dict) and value:
            rows += meta_rows(value, f"{dotted}.")
        elif isinstance(value, str | int | float) and not isinstance(value, bool):
            rows.append((dotted, value))
        else:
            rows.append((dotted, json.dumps(value, ensure_ascii=False)))
    return rows


def _meta_json(meta: dict[str, Any]) -> str:
    return json.dumps(meta, ensure_ascii=False)


def with_twist(run: Run) -> Run:
    """``run`` with :data:`rig.results.analyse.TWIST_COLUMN` as its last column (same meta); a
    transmission error run also with ``te_arcsec`` (:func:`rig.results.te.sample_te_arcsec`) before
    it."""
    from rig.results.analyse import TWIST_COLUMN, sample_twist_arcmin
    from rig.results.te import TE_COLUMN, is_te_run, sample_te_arcsec

    added = [TE_COLUMN, TWIST_COLUMN] if is_te_run(run) else [TWIST_COLUMN]
    columns = [c for c in run.columns if c not in added]
    data = {c: run.data[c] for c in columns}
    if is_te_run(run):
        data[TE_COLUMN] = sample_te_arcsec(run)
    data[TWIST_COLUMN] = sample_twist_arcmin(run)
    return Run(meta=run.meta, columns=[*columns, *added], data=data, path=run.path,
               notes=list(run.notes))


def export_run(run: Run, fmt: str, out: Path | None = None, *, force: bool = False) -> Path:
    """Write ``run`` as ``fmt`` to ``out`` (default :func:`default_out`); the path.

    Never into a store or a run folder (:func:`rig.io.safe_write.check_target`); an existing
    ``out`` only with ``force``; all or nothing (a failed write leaves ``out`` as it was)."""
    fmt = _check_format(fmt)
    if out is None:
        problem = id_problem(run.run_id, "run")
        if problem is not None:
            raise ExportError(f"{problem}; give --out")
        out = default_out(run.run_id, fmt, False)
    sources = [run.path] if run.path is not None else []
    out = check_target(Path(out), folder=fmt == "csv", force=force, sources=sources)
    run = with_twist(run)
    if fmt == "csv":
        with atomic_folder(out) as tmp:
            write_run(run, tmp)
        return out
    if fmt == "xlsx" and run.n_samples + 1 > XLSX_MAX_ROWS:
        raise ExportError(f"run {run.run_id}: {run.n_samples} samples do not fit an Excel "
                          f"sheet ({XLSX_MAX_ROWS - 1} rows at most); export csv or parquet")
    with atomic_file(out) as tmp:
        if fmt == "parquet":
            arrays = [pa.array(run.data[c], type=pa.float64()
                               if isinstance(run.data[c], np.ndarray) else pa.string())
                      for c in run.columns]
            table = pa.Table.from_arrays(arrays, names=list(run.columns))
            table = table.replace_schema_metadata({"run.json": _meta_json(run.meta)})
            pq.write_table(table, tmp)
        elif fmt == "mat":
            names = matlab_names(run.columns)
            variables: dict[str, Any] = {
                var: (run.data[c].reshape(-1, 1) if isinstance(run.data[c], np.ndarray)
                      else _cell(run.data[c]))
                for var, c in zip(names, run.columns, strict=True)
            }
            variables.update(run_id=run.run_id, meta_json=_meta_json(run.meta),
                             columns=_cell(run.columns), variables=_cell(names))
            _savemat(tmp, variables)
        else:
            samples = pd.DataFrame({c: run.data[c] for c in run.columns}, columns=run.columns)
            meta = pd.DataFrame(meta_rows(run.meta), columns=["key", "value"])
            _xlsx(tmp, {"samples": samples, "meta": meta})
    return out


def export_campaign(campaign: Campaign, fmt: str, out: Path | None = None, *,
                    force: bool = False) -> Path:
    """Write the campaign's results table as ``fmt`` (csv, parquet, mat, xlsx); the path.
    Where and how as :func:`export_run`."""
    from rig.results.table import TEXT_COLUMNS, results_frame

    fmt = _check_format(fmt)
    if out is None:
        name = campaign.meta.get("campaign_id") or campaign.name
        out = default_out(id_from_text(name, "campaign"), fmt, True)
    sources = [campaign.path] if campaign.path is not None else []
    out = check_target(Path(out), folder=False, force=force, sources=sources)
    table = results_frame(campaign)
    with atomic_file(out) as tmp:
        if fmt == "csv":
            table.to_csv(tmp, index=False)
        elif fmt == "parquet":
            arrow = pa.Table.from_pandas(table, preserve_index=False)
            arrow = arrow.replace_schema_metadata({"campaign.json": _meta_json(campaign.meta)})
            pq.write_table(arrow, tmp)
        elif fmt == "mat":
            names = matlab_names(list(table.columns), CAMPAIGN_MAT_VARIABLES)
            variables: dict[str, Any] = {}
            for var, col in zip(names, table.columns, strict=True):
                values = table[col]
                if col in TEXT_COLUMNS:
                    variables[var] = _cell(["" if v is None else str(v) for v in values])
                else:
                    numbers = values.to_numpy(dtype=np.float64, na_value=np.nan)
                    variables[var] = numbers.reshape(-1, 1)
            variables.update(meta_json=_meta_json(campaign.meta),
                             columns=_cell(list(table.columns)), variables=_cell(names))
            _savemat(tmp, variables)
        else:
            meta = pd.DataFrame(meta_rows(campaign.meta), columns=["key", "value"])
            _xlsx(tmp, {"results": table, "campaign": meta})
    return out


def _cell(texts: list[str]) -> np.ndarray:
    """A MATLAB cell column of strings."""
    cell = np.empty((len(texts), 1), dtype=object)
    for i, text in enumerate(texts):
        cell[i, 0] = text
    return cell


def _savemat(out: Path, variables: dict[str, Any]) -> None:
    from scipy.io import savemat

    with open(out, "wb") as f:  # our own handle: a failed write raises here, not in a __del__
        savemat(f, variables, do_compression=True, oned_as="column")


def _xlsx(out: Path, sheets: dict[str, pd.DataFrame]) -> None:
    """Write the sheets; a failure is one OSError. After a failed write openpyxl leaves a
    half-written zip and a worksheet generator behind, whose clean-up prints "Exception
    ignored" tracebacks: while writing, those clean-ups are silent, and they are collected
    before the error goes on."""
    failure: OSError | None = None
    hook = sys.unraisablehook
    sys.unraisablehook = lambda _info: None
    try:
        try:
            with open(out, "wb") as f, pd.ExcelWriter(f, engine="openpyxl") as writer:
                for sheet, frame in sheets.items():
                    frame.to_excel(writer, sheet_name=sheet, index=False)
        except Exception as exc:  # OSError from the disk, or what openpyxl makes of it
            reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
            failure = OSError(getattr(exc, "errno", None), reason)
        gc.collect()
    finally:
        sys.unraisablehook = hook
    if failure is not None:
        raise failure


def resolve_target(target: str, store: str | Path, samples: str | Path | None = None
                   ) -> tuple[Path, bool]:
    """(folder, is a campaign) of a run or campaign folder (or its run.json /
    campaign.json), else of a run or campaign id of the store ``store``."""
    from rig.runformat import CAMPAIGN_JSON, RUN_JSON, is_campaign
    from rig.store import Store, StoreError, UnknownIdError

    path = Path(target)
    if path.exists():
        if path.is_file() and path.name in (RUN_JSON, CAMPAIGN_JSON):
            path = path.parent
        if is_campaign(path):
            return path, True
        if not (path / RUN_JSON).is_file():
            raise ExportError(f"{target}: not a run folder (no {RUN_JSON}) or a campaign "
                              f"folder (no {CAMPAIGN_JSON})")
        return path, False
    problem = id_problem(target, "run")
    if problem is not None:
        raise ExportError(f"{target!r}: no such folder, and not an id of the store: {problem}")
    try:
        st = Store(store, create=False, recover=False, samples=samples)
    except StoreError as exc:
        raise ExportError(f"{target}: no such folder, and as an id: {exc}") from None
    try:
        return st.get_run(target).path, False
    except UnknownIdError:
        pass
    try:
        return st.get_campaign(target).path, True
    except UnknownIdError:
        raise ExportError(f"{target}: no such folder, and no run or campaign with that id "
                          f"in the store {st.location}") from None
