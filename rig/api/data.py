"""Runs and campaigns as the Python API hands them out (``rig.open``): samples as Arrow or
pandas tables with the twist as a column, the tidy results table, the reports and plots.

These are thin wrappers: the files are read by :mod:`rig.runformat` (``raw`` is what it
read), the numbers come from the services behind the CLI (:mod:`rig.api.reports`).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
import pyarrow as pa

from rig import runformat as rf
from rig.api.plots import axes_or_new, draw_positions_table
from rig.api.reports import (
    Analysis,
    Diagnosis,
    Model,
    analyse,
    diagnose,
    model,
    one_run_campaign,
)
from rig.results.analyse import TWIST_COLUMN, sample_twist_arcmin
from rig.results.table import results_frame

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["TWIST_COLUMN", "Campaign", "Run"]



def _arrow_column(values: rf.Column) -> pa.Array:
    if isinstance(values, np.ndarray):
        return pa.array(values, type=pa.float64())
    return pa.array(list(values), type=pa.string())


class Run:
    """One run (a rig-run/1 folder, a bare CSV, or a run of the store).

    ``raw``: the :class:`rig.runformat.Run` read from the files; ``result``: the measurement's
    JSON (``rig measure --json``) when the run was measured by :meth:`rig.connect`'s
    ``measure``, else None.
    """

    def __init__(self, raw: rf.Run, *, result: dict[str, Any] | None = None) -> None:
        self.raw = raw
        self.result = result
        self._twist: np.ndarray | None = None

    @property
    def run_id(self) -> str:
        return self.raw.run_id

    @property
    def label(self) -> str:
        """The run's label in its campaign (``pos090-a100-r0``), else its run id."""
        return str(self.raw.meta.get("label") or self.raw.run_id)

    @property
    def meta(self) -> dict[str, Any]:
        """run.json as read (unit, test, sensors, result, outcome ...)."""
        return self.raw.meta

    @property
    def unit(self) -> dict[str, Any]:
        return self.raw.unit

    @property
    def test(self) -> dict[str, Any]:
        return self.raw.test

    @property
    def path(self) -> Path | None:
        return self.raw.path

    @property
    def columns(self) -> list[str]:
        """The sample columns of the file, in order (a ``twist_arcmin`` column the file
        holds, as an export writes it, is left out: it is recomputed)."""
        return [c for c in self.raw.columns if c != TWIST_COLUMN]

    @property
    def n_samples(self) -> int:
        return self.raw.n_samples

    @property
    def twist_arcmin(self) -> np.ndarray:
        """Output twist in arcmin, as ``rig analyse`` computes it (uses ``test.ratio``),
        centred on the loop (:func:`rig.results.analyse.sample_twist_arcmin`)."""
        if self._twist is None:
            self._twist = sample_twist_arcmin(self.raw)
        return self._twist

    def to_arrow(self) -> pa.Table:
        """The samples as a pyarrow Table: the file's columns (numbers as float64, NaN a
        missing value; text columns as strings), then ``twist_arcmin``."""
        names = [*self.columns, TWIST_COLUMN]
        arrays = [_arrow_column(self.raw.data[c]) for c in self.columns]
        arrays.append(pa.array(self.twist_arcmin, type=pa.float64()))
        return pa.Table.from_arrays(arrays, names=names)

    def to_pandas(self) -> pd.DataFrame:
        """The samples as a pandas DataFrame (columns of :meth:`to_arrow`)."""
        return self.to_arrow().to_pandas()

    def te(self) -> pd.DataFrame:
        """The transmission error of a TE run (``test.kind = "transmission_error"``) against
        the output angle: columns ``output_angle_deg`` (deg, the grid over one revolution),
        ``te_forward_arcsec`` and ``te_reverse_arcsec`` (arcsec, revolution-averaged, each
        centred on its mean; docs/transmission-error.md)."""
        from rig.results.te import analyse_te_run

        return analyse_te_run(self.raw, with_model=False).te_frame()

    def analyse(self, **options: Any) -> Analysis:
        """``rig analyse`` of this run (:func:`rig.analyse`)."""
        return analyse(self, **options)

    def results(self, **options: Any) -> pd.DataFrame:
        """The tidy results table: one row (:mod:`rig.results.table`)."""
        return results_frame(one_run_campaign(self.raw), **options)

    def model(self) -> Model:
        """The seed 000 model of this run's unit (:func:`rig.model`)."""
        return model(self)

    def plot(self, ax: Axes | None = None, **options: Any) -> Axes:
        """Torque (N·m) against twist (arcmin): the loop with the model loop and the ±p %
        band, drawn into ``ax`` (a new figure if None). ``options``: as :meth:`analyse`."""
        return self.analyse(**options).plot(axes_or_new(ax))

    def __repr__(self) -> str:
        return f"<Run {self.run_id}: {self.n_samples} samples, columns {self.raw.columns}>"


class Campaign:
    """Runs of one unit (a rig-campaign/1 folder or a campaign of the store).

    ``raw``: the :class:`rig.runformat.Campaign`; ``runs``: its runs as :class:`Run`;
    ``result``: the campaign's JSON (``rig campaign run --json``) when it was measured by
    :meth:`rig.connect`'s ``campaign``, else None. Index it by position, run id or label.
    """

    def __init__(self, raw: rf.Campaign, *, result: dict[str, Any] | None = None) -> None:
        self.raw = raw
        self.result = result
        self.runs = [Run(r) for r in raw.runs]

    @property
    def name(self) -> str:
        return self.raw.name

    @property
    def meta(self) -> dict[str, Any]:
        """campaign.json as read (limits, summary, outcome ... for a measured campaign)."""
        return self.raw.meta

    @property
    def path(self) -> Path | None:
        return self.raw.path

    def __len__(self) -> int:
        return len(self.runs)

    def __iter__(self) -> Iterator[Run]:
        return iter(self.runs)

    def __getitem__(self, key: int | str) -> Run:
        if isinstance(key, int):
            return self.runs[key]
        for run in self.runs:
            if key in (run.run_id, run.label):
                return run
        raise KeyError(f"no run {key!r} in campaign {self.name}")

    def to_arrow(self) -> pa.Table:
        """The samples of every run in one table: ``run_id`` first, then the run's columns
        and ``twist_arcmin`` (a column some runs lack is null in theirs)."""
        tables = []
        for run in self.runs:
            table = run.to_arrow()
            ids = pa.array([run.run_id] * table.num_rows, type=pa.string())
            tables.append(table.add_column(0, "run_id", ids))
        return pa.concat_tables(tables, promote_options="default")

    def to_pandas(self) -> pd.DataFrame:
        """The samples as a pandas DataFrame (columns of :meth:`to_arrow`)."""
        return self.to_arrow().to_pandas()

    def analyse(self, **options: Any) -> Analysis:
        """``rig analyse`` of the campaign (:func:`rig.analyse`)."""
        return analyse(self, **options)

    def diagnose(self) -> Diagnosis:
        """``rig diagnose`` of the campaign (:func:`rig.diagnose`)."""
        return diagnose(self)

    def results(self, **options: Any) -> pd.DataFrame:
        """The tidy results table: one row per run (:mod:`rig.results.table`)."""
        return results_frame(self.raw, **options)

    def plot(self, ax: Axes | None = None, **options: Any) -> Axes:
        """Every run's loop (torque in N·m vs twist in arcmin) in one axes, with the model."""
        return self.analyse(**options).plot(axes_or_new(ax))

    def plot_positions(self, ax: Axes | None = None, **options: Any) -> Axes:
        """Lost motion (arcmin ± u) against the input angle (deg), with the nominal model, the
        production batch band the campaign stored (``summary.batch``) and the limit."""
        summary = self.meta.get("summary") or {}
        model_lm = (summary.get("model") or {}).get("lost_motion_arcmin")
        return draw_positions_table(ax, self.results(**options), batch=summary.get("batch"),
                                    model_arcmin=model_lm,
                                    title=f"Lost motion against position: {self.name}")

    def __repr__(self) -> str:
        return f"<Campaign {self.name}: {len(self.runs)} runs>"
