"""``rig.analyse``, ``rig.diagnose`` and ``rig.model``: the CLI's reports as Python objects.

Each object's ``to_dict()`` is the JSON document the matching command writes
(``rig analyse --json``, ``rig diagnose --json``, ``rig model --json``): the same services
(:mod:`rig.analyse`, :mod:`rig.diagnose`, :func:`analysis.models.seed000.design_chain`)
build them, so a notebook and the command line never disagree.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd

from analysis.diagnosis import Diagnosis as DiagnosisResult
from analysis.errors import AnalysisError
from analysis.models.seed000 import Seed000Design, design_chain
from rig.core.errors import RigError
from rig.core.json_files import finite_for_json
from rig.results.analyse import RunAnalysis
from rig.results.diagnose import diagnose_campaign, diagnose_path, report_dict
from rig.results.table import result_row, rows_frame
from rig.runformat import CAMPAIGN_FORMAT, Campaign, Run, is_campaign, read_run_or_campaign
from rig.runformat.meta_check import unit_problems

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["Analysis", "Diagnosis", "Model", "analyse", "as_campaign", "diagnose", "model",
           "one_run_campaign"]


def one_run_campaign(run: Run) -> Campaign:
    """A run as the one-run campaign :func:`rig.runformat.read_run_or_campaign` makes of it."""
    name = run.path.name if run.path is not None and run.path.is_dir() else run.run_id
    meta = {"format": CAMPAIGN_FORMAT, "name": run.run_id, "runs": [name]}
    return Campaign(meta=meta, runs=[run], path=run.path, notes=[f"single run {run.run_id}"])


def as_campaign(source: Any) -> tuple[Campaign, bool]:
    """(campaign, single) of a path, a rig.runformat Run/Campaign or an API Run/Campaign;
    ``single``: a single run (``rig analyse`` then writes one run's JSON object)."""
    raw = getattr(source, "raw", source)
    if isinstance(raw, Run):
        return one_run_campaign(raw), True
    if isinstance(raw, Campaign):
        return raw, False
    if isinstance(raw, str | Path):
        return read_run_or_campaign(raw), not is_campaign(raw)
    raise TypeError(f"expected a run or campaign (path, rig.open(...) object), "
                    f"got {type(source).__name__}")


class Analysis:
    """Loop metrics of a run or campaign beside the model (``rig analyse``).

    ``runs``: one :class:`rig.results.analyse.RunAnalysis` per run (twist in arcmin, the
    :class:`analysis.loop.LoopResult`, the model). ``to_dict()``: the ``--json`` document.
    """

    def __init__(self, campaign: Campaign, runs: list[RunAnalysis], single: bool) -> None:
        self.campaign = campaign
        self.runs = runs
        self.single = single

    def to_dict(self) -> dict[str, Any]:
        """``rig analyse --json``: one run's object, or ``{"campaign", "runs"}``."""
        if self.single:
            payload: dict[str, Any] = self.runs[0].to_dict()
        else:
            payload = {"campaign": self.campaign.meta.get("name"),
                       "runs": [item.to_dict() for item in self.runs]}
        return finite_for_json(payload)

    def to_pandas(self) -> pd.DataFrame:
        """The tidy results table of these analyses (see :mod:`rig.results.table`)."""
        return rows_frame([result_row(item.run, item, campaign_meta=self.campaign.meta)
                           for item in self.runs])

    def plot(self, ax: Axes | None = None) -> Axes:
        """The loops (torque in N·m vs twist in arcmin) with the model, into ``ax`` (a new
        figure if None); returns the axes."""
        from rig.api.plots import axes_or_new
        from rig.reports.loop_plots import draw_loops
        from rig.results.te import TERunAnalysis

        if isinstance(self.runs[0], TERunAnalysis):
            from rig.reports.te_plots import draw_te

            return draw_te(axes_or_new(ax), self.runs[0])
        title = None if self.single else f"Hysteresis loops: campaign {self.campaign.name}"
        return draw_loops(axes_or_new(ax), self.runs, title=title)

    def __repr__(self) -> str:
        return f"<Analysis of {len(self.runs)} run(s): {self.campaign.name}>"


class Diagnosis:
    """The sim-to-real gap diagnosis of a campaign (``rig diagnose``): ``result`` is the
    :class:`analysis.diagnosis.Diagnosis`; ``to_dict()`` the rig-diagnosis/1 report."""

    def __init__(self, campaign: Campaign, result: DiagnosisResult) -> None:
        self.campaign = campaign
        self.result = result
        self._report = report_dict(campaign, result)

    def to_dict(self) -> dict[str, Any]:
        """``rig diagnose --json``: the rig-diagnosis/1 report (NaN written as None)."""
        return finite_for_json(self._report)

    @property
    def verdict(self) -> str:
        return str(self._report["verdict"])

    @property
    def reason(self) -> str:
        return str(self._report.get("reason", ""))

    def __repr__(self) -> str:
        return f"<Diagnosis of {self.campaign.name}: {self.verdict}>"


class Model:
    """The seed 000 design chain and nominal model of a unit (``rig model``): ``design`` is
    the :class:`analysis.models.seed000.Seed000Design`; ``to_dict()`` the ``--json``."""

    def __init__(self, unit: dict[str, Any], design: Seed000Design) -> None:
        self.unit = unit
        self.design = design

    @property
    def assumptions(self) -> list[str]:
        return list(self.design.assumptions)

    def to_dict(self) -> dict[str, Any]:
        """``rig model --json`` (read back: tuples are lists, as in the file)."""
        return json.loads(json.dumps(self.design.to_dict()))

    def __repr__(self) -> str:
        lm = self.design.design_lost_motion_arcmin
        return f"<Model seed000: design lost motion {lm} arcmin>"


def analyse(run_or_path: Any, **options: Any) -> Analysis:
    """Loop metrics of a run or campaign (a path, ``rig.open(...)``, or a rig.runformat
    object), as ``rig analyse``; of a transmission error run, its TE analysis
    (:class:`rig.results.te.TERunAnalysis`). ``options`` (hysteresis runs): ``profile``
    ("nabtesco" ±3 %,
    "harmonic-drive" ±4 %), ``percent``, ``rated_torque_Nm``, ``hd_T1_Nm``, ``hd_T2_Nm``."""
    from rig.results.any_run import analyse_any_run

    campaign, single = as_campaign(run_or_path)
    return Analysis(campaign, [analyse_any_run(run, **options) for run in campaign.runs],
                    single)


def diagnose(campaign_or_path: Any) -> Diagnosis:
    """Diagnose the sim-to-real gap of a campaign (or one run), as ``rig diagnose``."""
    raw = getattr(campaign_or_path, "raw", campaign_or_path)
    if isinstance(raw, str | Path):
        return Diagnosis(*diagnose_path(raw))
    campaign, _ = as_campaign(raw)
    return Diagnosis(campaign, diagnose_campaign(campaign))


def model(unit_mapping_or_path: Any) -> Model:
    """The seed 000 model of a unit: a unit mapping, a run.json mapping (its ``unit``), a unit
    or run.json file, or a run from ``rig.open``; as ``rig model``."""
    source = unit_mapping_or_path
    if isinstance(source, str | Path):
        from rig.runformat.unit_file import load_unit_mapping

        where, mapping = str(source), load_unit_mapping(Path(source))
    elif isinstance(source, Mapping):
        where, mapping = "unit", dict(source)
        if isinstance(mapping.get("unit"), Mapping):
            where, mapping = "run.json unit", dict(mapping["unit"])
        problems = unit_problems(mapping)
        if problems:
            raise RigError(f"{where}: {problems[0]}")
    elif isinstance(getattr(source, "raw", None), Run):
        where, mapping = f"run {source.raw.run_id}", dict(source.raw.unit)
    else:
        raise TypeError(f"expected a unit mapping, a unit/run.json path or a run, got "
                        f"{type(source).__name__}")
    try:
        design = design_chain(mapping)
    except AnalysisError as exc:
        raise AnalysisError(f"{where}: {exc}") from None
    return Model(mapping, design)
