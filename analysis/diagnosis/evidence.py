"""Calibrated evidence of the candidates against a reference model (the null, or the model
with the effects already chosen): the columns each candidate adds, weighted and made
orthogonal to the reference's, scored on the reference's residuals and calibrated by
:mod:`analysis.diagnosis.calibration`."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from analysis.diagnosis.calibration import (
    REPLICATES,
    Calibrated,
    blocks_of,
    calibrate,
    null_basis,
    omnibus_blocks,
)
from analysis.diagnosis.fit import (
    NONLINEAR,
    LinearFit,
    Stack,
    _grid,
    column_names,
    run_columns,
    run_floating,
    teeth_of,
)

#: Grid points of a nonlinear parameter scored (the profile's own grid, thinned to this).
GRID_POINTS = 16


def _thin(grid: np.ndarray, most: int = GRID_POINTS) -> np.ndarray:
    if grid.size <= most:
        return grid
    return np.unique(np.quantile(grid, np.linspace(0.0, 1.0, most)))


def calibrated_evidence(stack: Stack, ref: LinearFit, ref_effects: Sequence[str],
                        names: Sequence[str], replicates: int = REPLICATES, seed: int = 0,
                        omnibus: bool = False
                        ) -> tuple[dict[str, Calibrated], Calibrated | None]:
    """Each candidate's calibrated evidence against the reference fit ``ref`` (of
    ``("backlash", *ref_effects)``), and, with ``omnibus``, the lack-of-fit test's."""
    teeth = teeth_of(stack)
    base_effects = ("backlash", *ref_effects)
    ref_names = column_names(stack, base_effects, teeth)
    # every point counts. Where the reference leaves the unit floating in the play its
    # residual is the censored one of the reference fit (only a position past the centre
    # of the play costs: there a torque-sensor offset shows, the unit held on the other
    # flank), and it informs neither the reference's coefficients nor its run offsets
    rows_X, rows_w, rows_run, rows_e, floats = [], [], [], [], []
    tq, fl, br, amp = [], [], [], []
    for i, run in enumerate(stack.runs):
        floating = run_floating(run, ref.nl)
        X = run_columns(stack, run, base_effects, ref.nl, teeth)
        w_run = np.full(X.shape[0], 1.0 / run.sigma_arcmin)
        floats.append(floating)
        rows_X.append(np.where(floating[:, None], 0.0, X))
        rows_w.append(w_run)
        rows_run.append(np.where(floating, -1, i))
        rows_e.append(np.asarray(ref.residual.get(run.run_id, np.zeros(X.shape[0]))) * w_run)
        tq.append(run.torque_Nm)
        fl.append(2.0 * X[:, 0])
        br.append(run.branch)
        amp.append(np.full(X.shape[0], run.amplitude_Nm))
    Xr = np.vstack(rows_X)
    w = np.concatenate(rows_w)
    run_index = np.concatenate(rows_run)
    if run_index.size < 10:
        return {}, None
    Qb = null_basis(Xr, run_index, stack.n_runs, w)
    e = np.concatenate(rows_e)
    e = e - Qb @ (Qb.T @ e)
    bounds = np.cumsum([0, *[r.size for r in rows_run]])
    slices = [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    floating_ref = np.concatenate(floats)

    def stacked(effects: Sequence[str], nl: dict[str, float]) -> np.ndarray:
        return np.vstack([run_columns(stack, run, effects, nl, teeth) for run in stack.runs])

    def floating_at(nl: dict[str, float]) -> np.ndarray:
        return np.concatenate([run_floating(run, nl) for run in stack.runs])

    fitted = stacked(base_effects, ref.nl) @ ref.beta
    blocks: dict[str, list[np.ndarray]] = {}
    for name in names:
        if name in ref_effects:
            continue
        effects = (*base_effects, name)
        cols = column_names(stack, effects, teeth)
        own = [j for j, c in enumerate(cols) if c not in ref_names]
        sets: list[np.ndarray] = []
        if name in NONLINEAR:
            key = NONLINEAR[name][0]
            for v in _thin(_grid(stack, name)):
                nl = {**ref.nl, key: float(v)}
                if own:
                    sets.append(np.where(floating_ref[:, None], 0.0,
                                         stacked(effects, nl)[:, own]))
                elif abs(float(v) - ref.nl.get(key, 0.0)) > 0:
                    # friction and an offset move the flank switches: the column is the change
                    # of the reference prediction with the parameter switched to v (none
                    # where the unit floats under both)
                    change = stacked(base_effects, nl) @ ref.beta - fitted
                    sets.append(np.where(floating_ref & floating_at(nl), 0.0, change))
        elif own:
            sets.append(np.where(floating_ref[:, None], 0.0, stacked(effects, ref.nl)[:, own]))
        blocks[name] = blocks_of(sets, w, Qb)
    blocks[OMNIBUS] = omnibus_blocks(np.concatenate(tq), np.concatenate(fl), np.concatenate(br),
                                     np.concatenate(amp), run_index, stack.n_runs, w, Qb)
    cal = calibrate(blocks, e, slices, replicates, seed, apart=(OMNIBUS,),
                    one_sided=ONE_SIDED)
    omni = cal.pop(OMNIBUS, None)
    return cal, (omni if omnibus else None)


OMNIBUS = "lack_of_fit"
#: Candidates whose columns are one signed direction each: a friction or an offset of the
#: grid's value (the change of the prediction it makes), a stiffening's or a soft stage's
#: extra compliance (bounded at zero).
ONE_SIDED = ("friction", "torque_sensor_offset", "stiffness_nonlinearity", "bearing_clearance")
