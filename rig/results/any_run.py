"""The one choice between a transmission error run and a hysteresis loop run when a run is
analysed (``rig analyse``, ``rig.analyse``, the campaign's results table, ``rig reanalyse``)."""

from __future__ import annotations

from typing import Any

from rig.results.analyse import RunAnalysis, analyse_run
from rig.results.te import TERunAnalysis, analyse_te_run, is_te_run
from rig.runformat import Run


def analyse_any_run(run: Run, **loop_options: Any) -> RunAnalysis | TERunAnalysis:
    """A transmission error run's TE analysis (run.json ``test.kind`` "transmission_error"),
    else the loop's with ``loop_options`` (:func:`rig.results.analyse.analyse_run`: profile,
    percent, rated_torque_Nm, hd_T1_Nm, hd_T2_Nm)."""
    if is_te_run(run):
        return analyse_te_run(run)
    return analyse_run(run, **loop_options)


def result_record(analysis: RunAnalysis | TERunAnalysis) -> dict[str, Any]:
    """What the store keeps of an analysis (a run's ``result``): a TE run's record
    (:meth:`TERunAnalysis.result_record`), a loop's ``rig analyse --json`` object."""
    if isinstance(analysis, TERunAnalysis):
        return analysis.result_record()
    return analysis.to_dict()
