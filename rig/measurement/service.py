"""The measurement service: open a rig (real, or the simulated one for the duration), run a
plan or a campaign on it with the engine into the store, and collect the results.

A campaign: :func:`run_campaign`; a single run: :func:`rig.measurement.single_run.measure_run`.
Both are called by the command line (``rig campaign run``, ``rig measure``), the Python API
(``rig.connect``) and the control page. A simulated rig runs as its own process (``rig sim``)
with a plant whose unit is the campaign's unit.
"""

from __future__ import annotations

import contextlib
import copy
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from analysis.loop import PROFILES
from rig.core.errors import RigError
from rig.core.json_files import json_safe
from rig.core.realtime import apply_realtime_priority
from rig.engine import Engine, EngineOptions
from rig.engine.devices import DevicesIO
from rig.engine.events import ProgressEvent
from rig.hardware.config import RigConfig, dump_rig_toml, load_rig_config
from rig.hardware.devices import RigDevices, open_rig
from rig.hardware.simulated_tolerances import SIMULATED_HEARTBEAT_MS, SIMULATED_MISSED_PERIODS
from rig.plans import Plan
from rig.plans.campaign_file import CampaignFile, Limits, SimulationSection, batch_band, summarise
from rig.results.outcome import campaign_outcome, run_outcome
from rig.store import Store
from simulators.plant.config import (
    DEFAULT_PLANT_TOML,
    PlantConfig,
    PlantConfigError,
    load_plant_config,
    plant_config_from_mapping,
)

Progress = Callable[[ProgressEvent], None]


def _deep_merge(base: dict[str, Any], extra: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(base)
    for key, value in extra.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _deep_merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def plant_config_for(unit: dict[str, Any], simulation: SimulationSection | None = None,
                     source: str = "<campaign>") -> PlantConfig:
    """The simulated plant for ``unit``: the default plant (simulators/default_plant.toml)
    with the unit replaced and the campaign's ``[simulation.plant]`` tables merged in."""
    base = load_plant_config(DEFAULT_PLANT_TOML).model_dump(exclude={"source"})
    base["unit"] = {k: v for k, v in unit.items()}
    sim = simulation or SimulationSection()
    data = _deep_merge(base, sim.plant)
    if sim.seed is not None:
        data["noise"] = {**data.get("noise", {}), "seed": sim.seed}
    try:
        return plant_config_from_mapping(data, f"{source} [simulation.plant]")
    except PlantConfigError as exc:
        raise RigError(str(exc)) from exc


def write_plant_toml(config: PlantConfig, path: Path) -> Path:
    """Write ``config`` as a plant TOML that :func:`load_plant_config` reads back."""
    data = config.model_dump(exclude={"source"})
    tables = {name: data[name] for name in ("unit", "rig", "housing", "noise", "effects",
                                            "measurement", "cycloid", "beveloid",
                                            "planetary")}
    path.write_text(dump_rig_toml(tables, "plant written by rig measure / rig campaign run"),
                    encoding="utf-8")
    return path


@dataclass
class RigSession:
    """An opened rig: the drivers, the engine's view of them, and the simulated rig if any."""

    devices: RigDevices
    io: DevicesIO
    rig_config_path: Path
    simulated: Any = None
    plant_config: PlantConfig | None = None
    stale_timeout_s: float = 1.0
    notes: list[str] = field(default_factory=list)


@contextlib.contextmanager
def open_session(*, rig: Path | None = None, simulated: bool = False,
                 plant: PlantConfig | None = None) -> Iterator[RigSession]:
    """Open the rig of ``rig`` (a rig TOML), or start the simulated rig (its own process,
    ``plant`` as its plant) for the duration; yield a :class:`RigSession`."""
    if simulated == (rig is not None):
        raise RigError("say which rig: --simulated (start the simulated rig) or --rig FILE "
                       "(a rig configuration), not both or neither")
    with contextlib.ExitStack() as stack:
        sim = None
        if simulated:
            from rig.hardware.simrig import SimulatedRig

            tmp = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="rig-measure-")))
            plant_path = None
            if plant is not None:
                plant_path = write_plant_toml(plant, tmp / "plant.toml")
            sim = SimulatedRig(plant_path, in_process=False, rig_config_path=tmp / "rig.toml",
                               sync_period_s=SIMULATED_SYNC_PERIOD_S,
                               stream_rate_Hz=SIMULATED_STREAM_RATE_HZ)
            stack.enter_context(sim)
            rig = sim.rig_config_path
        assert rig is not None
        config = load_rig_config(rig)
        apply_realtime_priority(config.rig.realtime_priority)
        if simulated:
            config = relaxed_heartbeats(config)
        devices = stack.enter_context(open_rig(config))
        stale = SIMULATED_STALE_TIMEOUT_S if simulated else 1.0
        yield RigSession(devices, DevicesIO(devices), Path(rig), sim, plant, stale)


SIMULATED_SYNC_PERIOD_S = 0.004
SIMULATED_STREAM_RATE_HZ = 250.0
SIMULATED_STALE_TIMEOUT_S = 2.0


def relaxed_heartbeats(config: RigConfig) -> RigConfig:
    """The simulated rig shares a (possibly loaded, 2-core) machine with the measuring
    process: its encoders' heartbeat is set to 500 ms (fault after 3 missed, 1.5 s) instead
    of 100 ms (0.25 s), and a position PDO may be missing for 400 periods (1.6 s at the
    simulated 4 ms SYNC) instead of 100, so that a scheduling stall of a loaded machine is
    not taken for a lost device. A real rig keeps its configuration's values."""
    copies: dict[str, Any] = {}
    for name in ("encoder", "input_encoder"):
        enc = getattr(config, name)
        if enc is None:
            continue
        update: dict[str, Any] = {
            "missed_periods": max(enc.missed_periods, SIMULATED_MISSED_PERIODS)}
        if 0 < enc.heartbeat_ms < SIMULATED_HEARTBEAT_MS:
            update.update(heartbeat_ms=SIMULATED_HEARTBEAT_MS, heartbeat_timeout_periods=3.0)
        copies[name] = enc.model_copy(update=update)
    return config.model_copy(update=copies)


def run_meta(unit: dict[str, Any], session: RigSession, operator: str | None = None,
             calibration_override: str | None = None, *,
             override_how: str = "--calibration-override REASON") -> dict[str, Any]:
    """run.json keys every run of a session carries (unit, rig id, operator, the sensors'
    calibrations, simulation). :class:`rig.hardware.calibration.CalibrationExpired` when a
    calibration is past due and no ``calibration_override`` reason is given (``override_how``
    tells the operator how to give one); with a reason, ``calibration_override`` records it."""
    from rig.hardware.calibration import calibration_meta

    config = session.devices.config
    meta: dict[str, Any] = {"unit": unit, "rig_id": config.rig.rig_id}
    if operator:
        meta["operator"] = operator
    meta.update(calibration_meta(config.calibration, calibration_override, operator,
                                 how=override_how))
    if session.plant_config is not None:
        # the kind of unit the simulated devices simulate: a run whose unit is of another
        # kind measured that plant, not its unit (rig/results/outcome.py plant_mismatch)
        meta["simulation"] = {
            "plant_kind": str(session.plant_config.unit.get("kind") or "internal_involute"),
            "plant": json_safe(session.plant_config.model_dump(exclude={"source", "unit"}))}
    return meta


def simulated_truth(session: RigSession, pct: float, rated_torque_Nm: float,
                    positions_deg: list[float], temperatures_C: list[float] | None = None,
                    ) -> Callable[[dict[str, Any]], dict[str, Any]] | None:
    """On the simulated rig: each run's ``generator`` block, what the plant injected and its
    true loop at the run's lock angle and temperature (simulators/plant/truth.py); None on a
    real rig. The blocks of every planned position and temperature are computed here, before
    the engine starts: a run's start never waits for them (the drive's keepalive would)."""
    config = session.plant_config
    if config is None:
        return None
    from simulators.plant.truth import generator_block

    temps: list[float | None] = list(temperatures_C) if temperatures_C else [None]
    blocks = {(round(float(a), 6), t): generator_block(
        config, input_angle_deg=float(a), temperature_C=t, rated_torque_Nm=rated_torque_Nm,
        pct=pct) for a in positions_deg for t in temps}

    def meta(test: dict[str, Any]) -> dict[str, Any]:
        angle = test.get("input_angle_deg")
        angle = round(float(angle), 6) if isinstance(angle, int | float) else 0.0
        temp = test.get("temperature_C")
        if temps == [None] or not isinstance(temp, int | float):
            key_t = temps[0]
        else:
            key_t = min((t for t in temps if t is not None), key=lambda t: abs(t - temp))
        block = blocks.get((angle, key_t))
        return {} if block is None else {"generator": block}

    return meta


def measure_plan(session: RigSession, store: Store, plan: Plan, meta: dict[str, Any], *,
                 campaign_id: str | None = None, options: EngineOptions | None = None,
                 progress: Progress | None = None,
                 on_engine: Callable[[Engine], None] | None = None) -> tuple[Engine, list]:
    """Run ``plan`` with a new engine; return the engine (state, stopping reason) and the
    run outcomes. ``on_engine`` receives the engine before it starts (to pause/abort it)."""
    engine = Engine(session.io, store, meta=meta, campaign_id=campaign_id, options=options)
    if progress is not None:
        engine.subscribe(progress)
    if on_engine is not None:
        on_engine(engine)
    outcomes = engine.run(plan)
    return engine, outcomes


def run_result(outcome_dict: dict[str, Any], limits: Limits) -> dict[str, Any]:
    """A single run's JSON (``rig measure --json``): the ``rig analyse --json`` keys, status,
    reason, the limit verdict and the ``outcome`` ("ok", "not_ok", "incomplete", "no_limits":
    rig/results/outcome.py) with the ``limits`` in force; ``passed``: completed and no limit
    failed."""
    outcome, causes, notes = run_outcome(outcome_dict, limits.model_dump())
    return {**outcome_dict, "passed": outcome in ("ok", "no_limits"), "outcome": outcome,
            "limits": limits.model_dump(), "failures": causes, "not_applicable": notes}


def run_campaign(camp: CampaignFile, session: RigSession, store: Store, *,
                 progress: Progress | None = None,
                 on_engine: Callable[[Engine], None] | None = None,
                 override_how: str = "campaign key calibration_override = \"REASON\"",
                 ) -> dict[str, Any]:
    """Run a campaign into a rig-campaign/1 folder of the store; return its results.
    campaign.json and every run.json carry the operator, the unit (serial) and the sensors'
    calibrations (an expired one needs the campaign's ``calibration_override``)."""
    plan = camp.build_plan()
    unit = camp.unit_data()
    meta = run_meta(unit, session, camp.operator, camp.calibration_override,
                    override_how=override_how)  # refused before the campaign exists
    cmeta = {"description": camp.description, "unit": unit, "plan": plan.meta(),
             "limits": camp.limits.model_dump(), "campaign_file": camp.source,
             "profile": camp.profile, "operator": camp.operator,
             "rig_id": meta["rig_id"]}
    for key in ("calibration", "calibration_override"):
        if key in meta:
            cmeta[key] = meta[key]
    campaign_id = store.create_campaign(camp.name, meta=json_safe(cmeta))
    try:  # from here on anything that fails closes the campaign (never left `running`)
        options = EngineOptions(torque_limit_Nm=camp.torque_limit_Nm, profile=camp.profile,
                                stale_timeout_s=session.stale_timeout_s,
                                limits=camp.limits.model_dump(),
                                run_meta=simulated_truth(
                                    session, PROFILES.get(camp.profile, 3.0),
                                    camp.plan.rated_torque_Nm,
                                    camp.axes.positions_deg or [0.0],
                                    camp.axes.temperatures_C))
        engine, outcomes = measure_plan(
            session, store, plan, meta,
            campaign_id=campaign_id, options=options, progress=progress, on_engine=on_engine)
    except BaseException as exc:  # refused before it ran, Ctrl-C, a bug: close the campaign
        with contextlib.suppress(Exception):
            store.finish_campaign(campaign_id, "aborted",
                                  {"reason": f"{type(exc).__name__}: {exc}"},
                                  extra={"outcome": "incomplete"})
        raise
    runs = [o.to_dict() for o in outcomes]
    summary = summarise(runs, camp.limits)
    summary["batch"] = batch_band(unit, camp.plan.rated_torque_Nm,
                                  PROFILES.get(camp.profile, 3.0))
    from analysis.models.by_kind import MODEL_NAMES

    kind = str(unit.get("kind") or "internal_involute")
    summary["unit_kind"] = kind
    summary["model_name"], summary["band_source"] = MODEL_NAMES.get(kind, (kind, ""))
    status = "completed" if engine.state == "completed" else "aborted"
    reason = engine.stopping_reason
    summary["outcome"] = campaign_outcome([r["outcome"] for r in runs], status)
    if status == "aborted":
        summary["passed"] = False
        summary["failures"].append(f"campaign aborted: {reason}")
    store.finish_campaign(campaign_id, status, summary=json_safe({**summary, "reason": reason}),
                          extra={"outcome": summary["outcome"]})
    info = store.get_campaign(campaign_id)
    return json_safe({"campaign": camp.name, "campaign_id": campaign_id, "path": str(info.path),
                      "status": status, "reason": reason, **summary, "runs": runs})
