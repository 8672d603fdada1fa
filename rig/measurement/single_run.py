"""One run, measured the one way: ``rig measure``, ``rig.connect(...).measure(...)`` and the
control page's single run all call :func:`measure_run` (a campaign: :func:`run_campaign` of
:mod:`rig.measurement.service`).

A :class:`MeasureRequest` holds what the run needs (the loop or the transmission error test,
the unit, limits, profile, operator, calibration override, the simulated plant); the caller
opens the rig (:func:`open_run_session`, or a session it already holds) and passes its hooks:
``progress`` (the engine's events), ``on_engine`` (the engine before it starts: pause, resume,
abort) and the store (a live tap wraps it on the page).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from analysis.loop import PROFILES
from rig.core.errors import RigError
from rig.engine import Engine, EngineOptions
from rig.measurement.service import (
    Progress,
    RigSession,
    measure_plan,
    open_session,
    plant_config_for,
    run_meta,
    run_result,
    simulated_truth,
)
from rig.plans import TE_KIND, LoopParams, Plan, TEParams, hysteresis_plan, te_plan
from rig.plans.campaign_file import Limits
from rig.results.outcome import campaign_outcome
from rig.store import Store
from simulators.plant.config import PlantConfig, PlantConfigError, load_plant_config

LOOP_KIND = "lost_motion"
"""run.json ``test.kind`` of a hysteresis loop run (:data:`rig.plans.TE_KIND`: a transmission
error run)."""

CLI_OVERRIDE_HOW = "--calibration-override REASON"
"""How ``rig measure`` (and a script) overrides an expired calibration."""


@dataclass(frozen=True)
class MeasureRequest:
    """What one run needs. ``te`` given: a transmission error run (``loop`` and
    ``position_deg`` unused), else the hysteresis loop ``loop`` with the input locked at
    ``position_deg`` (deg) first. ``unit``: run.json ``unit``; ``limits`` the verdict's;
    ``profile`` the lost-motion band; ``torque_limit_Nm`` may only lower the rig's (N*m);
    ``override_how`` tells the operator how to override an expired calibration; ``plant``:
    the simulated rig's plant (:func:`with_simulated_plant`)."""

    loop: LoopParams | None = None
    te: TEParams | None = None
    position_deg: float | None = None
    unit: Mapping[str, Any] = field(default_factory=dict)
    limits: Limits = field(default_factory=Limits)
    profile: str = "nabtesco"
    operator: str | None = None
    calibration_override: str | None = None
    override_how: str = CLI_OVERRIDE_HOW
    torque_limit_Nm: float | None = None
    plant: PlantConfig | None = None

    def __post_init__(self) -> None:
        if self.loop is None and self.te is None:
            raise RigError("a run needs its loop (LoopParams) or its transmission error "
                           "test (TEParams)")

    @property
    def test(self) -> str:
        """run.json ``test.kind``: ``transmission_error`` or ``lost_motion``."""
        return TE_KIND if self.te is not None else LOOP_KIND

    @property
    def rated_torque_Nm(self) -> float:
        """The rated torque of the test (N*m)."""
        params = self.te if self.te is not None else self.loop
        assert params is not None
        return float(params.rated_torque_Nm)

    def plan(self) -> Plan:
        """The engine plan: the one choice between a transmission error run and a loop."""
        if self.te is not None:
            return te_plan(self.te)
        assert self.loop is not None
        return hysteresis_plan(self.loop, self.position_deg)

    def engine_options(self, session: RigSession) -> EngineOptions:
        """The engine's options on ``session``: the profile, limits and torque limit, the
        session's stale timeout and, on the simulated rig, each run's generator block."""
        truth = simulated_truth(session, PROFILES.get(self.profile, 3.0), self.rated_torque_Nm,
                                [self.position_deg if self.position_deg is not None else 0.0])
        return EngineOptions(torque_limit_Nm=self.torque_limit_Nm, profile=self.profile,
                             stale_timeout_s=session.stale_timeout_s,
                             limits=self.limits.model_dump(), run_meta=truth)


def unit_data(unit: str | Path | Mapping[str, Any] | None) -> dict[str, Any]:
    """The run's unit data (run.json ``unit``): a mapping, or a JSON file's object; {} for
    None."""
    if isinstance(unit, Mapping):
        return dict(unit)
    if unit is None:
        return {}
    from rig.core.json_files import read_json_file

    data = read_json_file(unit, RigError, "unit data")
    if not isinstance(data, dict):
        raise RigError(f"{unit}: the unit data must be a JSON object")
    return data


def default_unit(plant_file: Path | None = None) -> dict[str, Any]:
    """The unit of the plant TOML ``plant_file``, else of the default plant."""
    try:
        plant = load_plant_config(plant_file) if plant_file is not None else load_plant_config()
    except PlantConfigError as exc:
        raise RigError(str(exc)) from exc
    return dict(plant.unit)


def with_simulated_plant(request: MeasureRequest, plant_file: Path | None = None
                         ) -> MeasureRequest:
    """``request`` on the simulated rig: the plant TOML ``plant_file``, else the default
    plant around the request's unit (its own unit when the request gives none); the run's
    unit is then the plant's when the request gives none."""
    try:
        plant = (load_plant_config(plant_file) if plant_file is not None
                 else plant_config_for(dict(request.unit) or load_plant_config().unit))
    except PlantConfigError as exc:
        raise RigError(str(exc)) from exc
    return replace(request, plant=plant, unit=dict(request.unit) or dict(plant.unit))


def refuse_expired_calibration(request: MeasureRequest, calibration: Any) -> None:
    """:class:`rig.hardware.calibration.CalibrationExpired` when a sensor calibration of
    ``calibration`` (a rig configuration's) is past due and the request gives no reason."""
    from rig.hardware.calibration import calibration_meta

    calibration_meta(calibration, request.calibration_override, request.operator,
                     how=request.override_how)


@contextlib.contextmanager
def open_run_session(request: MeasureRequest, *, rig: Path | None = None,
                     simulated: bool = False) -> Iterator[RigSession]:
    """Open the rig of the rig TOML ``rig`` (an expired calibration is refused before it is
    opened), or start the simulated rig with the request's plant, for the duration."""
    if rig is not None:
        from rig.hardware.config import load_rig_config

        refuse_expired_calibration(request, load_rig_config(rig).calibration)
    with open_session(rig=rig, simulated=simulated, plant=request.plant) as session:
        yield session


@dataclass(frozen=True)
class MeasuredRun:
    """What :func:`measure_run` measured: the engine's end ``state`` ("completed" or
    "aborted") and ``reason``, and each recorded run's ``rig measure --json`` document."""

    state: str
    reason: str | None
    runs: list[dict[str, Any]]
    limits: Limits

    @property
    def result(self) -> dict[str, Any]:
        """The run's ``rig measure --json`` document; RigError when no run was recorded."""
        if not self.runs:
            raise RigError(f"no run was recorded: {self.reason}")
        return self.runs[-1]

    def summary(self) -> dict[str, Any]:
        """Status, reason, passed, outcome, limits, failures and the runs, as a campaign's
        result says them (rig/results/outcome.py)."""
        runs = self.runs
        passed = self.state == "completed" and bool(runs) and all(r["passed"] for r in runs)
        failures = [c for r in runs for c in r["failures"]]
        if self.state == "aborted" and self.reason:
            failures.append(f"run aborted: {self.reason}")
        return {"status": self.state, "reason": self.reason, "passed": passed,
                "outcome": campaign_outcome([r["outcome"] for r in runs], self.state),
                "limits": self.limits.model_dump(), "failures": failures, "runs": runs}


def measure_run(request: MeasureRequest, session: RigSession, store: Store, *,
                progress: Progress | None = None,
                on_engine: Callable[[Engine], None] | None = None) -> MeasuredRun:
    """Measure the request's run on ``session`` into ``store`` with a new engine; run.json
    carries the unit, operator, calibrations (an expired one refused without the request's
    override) and, simulated, the plant. ``progress`` receives the engine's events,
    ``on_engine`` the engine before it starts."""
    meta = run_meta(dict(request.unit), session, request.operator,
                    request.calibration_override, override_how=request.override_how)
    engine, outcomes = measure_plan(session, store, request.plan(), meta,
                                    options=request.engine_options(session),
                                    progress=progress, on_engine=on_engine)
    state = "completed" if engine.state == "completed" else "aborted"
    runs = [run_result(o.to_dict(), request.limits) for o in outcomes]
    return MeasuredRun(state, engine.stopping_reason, runs, request.limits)
