"""The page's hold on the rig: one opened rig session, at most one measurement at a time.

:class:`RigController` opens the rig (the simulated one, or a rig TOML) with
:func:`rig.measurement.service.open_session`, watches the devices while idle (heartbeats, last
values), and measures single runs and campaigns with the measurement service
(:func:`rig.measurement.single_run.measure_run`, :func:`rig.measurement.service.run_campaign`)
on a thread of its own: the engine handed to the controller before it starts (pause, resume,
abort), its events forwarded to the pages, the store wrapped by
:class:`rig.web.live_tap.TapStore` so that the rows recorded are also drawn live.

Device access: while a measurement runs only the engine talks to the serial transducer and
consumes the encoders' samples; the monitor then reads only what cannot disturb it (encoder
health, drive status over the shared Modbus link) and takes the live numbers from the rows
being recorded.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import threading
import time
import unicodedata
from collections.abc import Callable
from contextlib import AbstractContextManager
from typing import Any

from drivers.errors import DeviceError
from rig.core.errors import RigError
from rig.core.json_files import json_safe
from rig.core.ranges import plan_duration_problem
from rig.engine import Engine
from rig.engine.events import ProgressEvent
from rig.engine.safety import PlanRejected, preflight
from rig.hardware.calibration import CalibrationExpired, calibration_meta, calibration_status
from rig.measurement.service import RigSession, run_campaign
from rig.measurement.single_run import MeasureRequest, measure_run
from rig.plans import TE_KIND, CampaignAxes, Plan, campaign_plan, te_campaign_plan
from rig.plans.campaign_file import campaign_from_mapping
from rig.plans.estimate import estimate
from rig.store import Store
from rig.web.faults import explain
from rig.web.live import LiveHub
from rig.web.live_tap import TapStore
from rig.web.models import InputLockRequest, RunRequest

log = logging.getLogger(__name__)

PREVIEW_LINES = 400
MONITOR_PERIOD_S = 0.5
LIVE_METRICS_PERIOD_S = 2.0
LOCK_ANSWER_S = 0.5
"""An input lock answers when its move ends within this (s), else at once with ``moving``:
a lock to +-3599 deg turns for 10-20 s (issue 33 item 7)."""
LOCK_PROGRESS_PERIOD_S = 0.25
"""The input angle of a lock move is sent to the pages this often (s)."""

SessionFactory = Callable[[], AbstractContextManager[RigSession]]
UnitSessionFactory = Callable[[dict[str, Any]], AbstractContextManager[RigSession]]
"""A new simulated rig whose plant is the given unit's (rig/web/simulated.py)."""


def plant_kind(session: RigSession) -> str | None:
    """The unit kind the simulated rig's plant simulates (None: a real rig)."""
    if session.plant_config is None:
        return None
    return str(session.plant_config.unit.get("kind") or "internal_involute")


OVERRIDE_HOW = ("Set up: tick 'start with expired calibration' and give the reason, "
                "or have the sensor calibrated")
"""How the page's operator overrides an expired calibration."""


class ControlError(RigError):
    """A command that cannot be done now (HTTP 409): says why and what to do."""


def _shown(value: str) -> str:
    """A client's text echoed in a one-line message: quoted, control characters and quotes
    escaped (JSON string syntax), at most 40 characters of it."""
    text = json.dumps(value[:40], ensure_ascii=True)
    return text if len(value) <= 40 else text[:-1] + '..."'


def start_identity_problem(req: RunRequest) -> str | None:
    """Why a measurement may not start without knowing who measures which unit (one line
    naming the field, its echoed value escaped), or None: ``operator`` and ``unit.serial``
    are needed, not blank, the operator without control characters (the serial's pattern is
    the model's)."""
    operator = req.operator
    if operator is None:
        return "operator: expected the name of who runs the test, got none"
    if not operator.strip():
        return f"operator: expected the name of who runs the test, got {_shown(operator)}"
    if any(unicodedata.category(c) == "Cc" for c in operator):
        return (f"operator: expected a name without control characters, got "
                f"{_shown(operator)}")
    serial = getattr(req.unit, "serial", None)
    if serial is None or not str(serial).strip():
        return "unit.serial: expected the serial number of the unit under test, got none"
    return None


def single_run_request(req: RunRequest) -> MeasureRequest:
    """The measurement service's request of a single run (``kind`` "run") set up on the
    page."""
    te = req.te_params() if req.test == TE_KIND else None
    return MeasureRequest(loop=None if te is not None else req.plan.loop_params(), te=te,
                          position_deg=req.position_deg, unit=req.unit.mapping(),
                          limits=req.limits.limits(), profile=req.profile,
                          operator=req.operator, calibration_override=req.calibration_override,
                          override_how=OVERRIDE_HOW, torque_limit_Nm=req.torque_limit_Nm)


def build_plan(req: RunRequest) -> Plan:
    """The engine plan of a request: one run (:meth:`MeasureRequest.plan`), or a campaign
    over ``axes``; with ``test`` "transmission_error" of transmission error runs."""
    if req.kind == "run":
        return single_run_request(req).plan()
    if req.test == TE_KIND:
        return te_campaign_plan(req.te_params(), CampaignAxes(
            repeats=req.axes.repeats, temperatures_C=list(req.axes.temperatures_C)))
    return campaign_plan(req.plan.loop_params(), req.axes.axes())


def compute_preview(req: RunRequest, facts: dict[str, Any]) -> dict[str, Any]:
    """Steps, duration estimate and whether the plan fits the rig described by ``facts``
    (:meth:`RigController.preview_facts`); ControlError while a fault is latched."""
    faults = facts.get("faults") or []
    if faults:
        listed = "; ".join(f"{f['device']}: {f['detail']}" for f in faults)
        raise ControlError(f"preview refused: a fault is latched ({listed}). Remove its "
                           f"cause, then Reset faults (POST /api/devices/reset-faults)")
    plan = build_plan(req)
    steps = list(plan.steps())
    est = estimate(steps)
    problems: list[str] = []
    limit = None
    if facts.get("connected"):
        limit = facts["torque_limit_Nm"]
        if req.torque_limit_Nm is not None:
            limit = min(limit, req.torque_limit_Nm)
        try:
            preflight(steps, limit, has_input_motor=facts["has_input_motor"],
                      has_climate=facts["has_climate"],
                      has_input_encoder=facts.get("has_input_encoder", True))
        except PlanRejected as exc:
            problems.append(str(exc))
    else:
        problems.append("no rig connected: the plan cannot be checked against a rig")
    long = plan_duration_problem(est.total_s, req.confirm_long, "confirm_long")
    if long is not None:
        problems.append(long)
    model, assumptions = model_summary(req) if req.test != TE_KIND else (None, [])
    batch = None
    if model is not None:
        from rig.plans.campaign_file import batch_band

        batch = batch_band(req.unit.mapping(), req.plan.rated_torque_Nm,
                           model["lost_motion_pct"])
    listing = [line.strip() for line in plan.listing()[:PREVIEW_LINES]]
    effects = None
    if req.kind == "campaign" and req.test != TE_KIND:
        from rig.plans.diagnosability import effects_of_design

        # what the gap diagnosis of these runs can and cannot test (issue 31 item 7)
        effects = effects_of_design(req.unit.mapping(), req.plan.rated_torque_Nm,
                                    req.axes.axes()).to_dict()
    return json_safe({
        "name": plan.name, "n_steps": len(steps), "n_runs": est.n_runs,
        "estimated_s": est.total_s, "dwell_s": est.dwell_s, "steps": listing,
        "truncated": len(steps) > len(listing), "torque_limit_Nm": limit,
        "amplitude_Nm": (req.te_params().brake_torque_Nm if req.test == TE_KIND
                         else req.plan.loop_params().amplitude_Nm),
        "fits": not problems, "problems": problems, "assumptions": assumptions,
        "model": model, "batch": batch, "diagnosis_design": effects,
    })


def unit_design(req: RunRequest) -> dict[str, Any]:
    """What a single run's result says of the unit's design, as a campaign's does
    (rig/measurement/service.py): ``unit_kind``, ``model_name`` and ``band_source`` (the names of
    :data:`analysis.models.by_kind.MODEL_NAMES`) and ``batch``, the kind's batch band
    (:func:`rig.plans.campaign_file.batch_band`: arcmin at the plan's rated torque and profile;
    None when
    the unit's data cannot give one)."""
    from analysis.models.by_kind import MODEL_NAMES
    from rig.plans.campaign_file import batch_band
    from rig.results.analyse import resolve_profile

    unit = req.unit.mapping()
    kind = str(unit.get("kind") or "internal_involute")
    names = MODEL_NAMES.get(kind, (kind, ""))
    _, pct = resolve_profile(req.profile, None)
    try:
        batch = batch_band(unit, req.plan.rated_torque_Nm, pct)
    except Exception as exc:  # noqa: BLE001 (the run is measured: its result stands without)
        log.warning("no batch band for the run's result: %s", exc)
        batch = None
    return {"unit_kind": kind, "model_name": names[0], "band_source": names[1],
            "batch": batch}


def model_summary(req: RunRequest) -> tuple[dict[str, Any] | None, list[str]]:
    """The reference nominal model's loop for the unit (arcmin, N*m/arcmin), or None."""
    from rig.results.analyse import nominal_model_for_unit, resolve_profile

    model, assumptions = nominal_model_for_unit(req.unit.mapping(), req.plan.rated_torque_Nm)
    if model is None:
        return None, assumptions
    _, pct = resolve_profile(req.profile, None)
    from analysis.models.by_kind import MODEL_NAMES

    kind = str(req.unit.mapping().get("kind") or "internal_involute")
    names = MODEL_NAMES.get(kind, (kind, ""))
    out: dict[str, Any] = {"lost_motion_pct": pct, "kind": kind, "model_name": names[0],
                           "band_source": names[1]}
    for key in ("play_arcmin", "backlash_arcmin", "stiffness_Nm_per_arcmin"):
        value = getattr(model, key, None)
        out[key] = value if isinstance(value, int | float) else None
    out["lost_motion_arcmin"] = model.lost_motion_arcmin(req.plan.rated_torque_Nm, pct)
    return json_safe(out), assumptions


ARCMIN_PER_DEG = 60.0


def wrapped_arcmin(value: float) -> float:
    """An angle difference (arcmin) wrapped to (-10800, 10800]: half a turn either way."""
    return -((-value + 10800.0) % 21600.0 - 10800.0)


def settled_output_arcmin(encoder: Any, *, period_s: float = 0.1, within_arcmin: float = 0.05,
                          timeout_s: float = 3.0) -> float:
    """The output angle (arcmin) once it has stopped moving (two readings ``period_s`` apart
    within ``within_arcmin``; the last reading after ``timeout_s``): the reference of the
    twist after the input was locked (the output follows the input through the gear)."""
    last = encoder.read().angle_deg * ARCMIN_PER_DEG
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        time.sleep(period_s)
        now = encoder.read().angle_deg * ARCMIN_PER_DEG
        if abs(now - last) <= within_arcmin:
            return now
        last = now
    return last


def finished_run(data: dict[str, Any]) -> dict[str, Any]:
    """What the page lists of a run as it finishes (``run_finished`` event data): label,
    position (deg), amplitude (%), status, outcome, lost motion and its uncertainty (arcmin)."""
    u = (data.get("uncertainty") or {}).get("lost_motion_arcmin")
    return json_safe({k: data.get(k) for k in (
        "run_id", "label", "input_angle_deg", "amplitude_pct", "status", "reason", "outcome",
        "lost_motion_arcmin")} | {"lost_motion_u_arcmin": u})


class RigController:
    """See the module docstring. ``session_factory`` None: no rig (history only).

    ``unit_session_factory``: on the simulated rig, how to start it again with a unit's plant
    (:func:`rig.web.simulated.unit_session_factory`): a measurement of a unit of another kind
    than the plant's restarts it with the unit's plant first (issue 33 item 10). Without it
    such a run is measured on the plant there is and its verdict is INCOMPLETE
    (:func:`rig.results.outcome.plant_mismatch`)."""

    def __init__(self, store: Store, hub: LiveHub, session_factory: SessionFactory | None,
                 *, simulated: bool = False, description: str = "",
                 unit_session_factory: UnitSessionFactory | None = None) -> None:
        self.store = store
        self.hub = hub
        self.session_factory = session_factory
        self.unit_session_factory = unit_session_factory
        self.simulated = simulated
        self.description = description
        self.session: RigSession | None = None
        self.open_error: str | None = None
        self.state = "no_rig" if session_factory is None else "starting"
        self.message = ("no rig: history only" if session_factory is None
                        else "connecting to the rig ...")
        self._stack = contextlib.ExitStack()
        self._lock = threading.RLock()
        self._device_lock = threading.Lock()  # idle monitor vs a measurement starting
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._engine: Engine | None = None
        self._tap: TapStore | None = None
        self._run_thread: threading.Thread | None = None
        self._progress: ProgressEvent | None = None
        self._current: dict[str, Any] | None = None
        self._fault_reason: str | None = None
        self._last_result: dict[str, Any] | None = None
        self._devices: list[dict[str, Any]] = []
        self._idle_rows: list[dict[str, Any]] = []
        """The device rows of the last pass while idle (kept during a measurement)."""
        self._live: dict[str, Any] = {}
        self._safe: bool | None = None
        self._lock_confirmed = False
        self._lock_angle: float | None = None
        self._lock_by_motor = False
        self._lock_move: dict[str, Any] | None = None
        """The input motor turning to the lock angle now: target, angle (deg), its end."""
        self._lock_move_result: tuple[bool, str] = (False, "")
        """The last lock move's end: (failed, what the answer says)."""
        self._lock_failed: str | None = None
        self._lock_cancel: str | None = None
        self._twist_ref_arcmin: float | None = None
        """The output angle (arcmin) the twist is counted from: read at zero torque when the
        input lock is confirmed (before that, the first reading after the rig opened), and
        again at the first sample of a run whose input position differs (a campaign locks
        the input at each of its positions, turning the output with it)."""
        self._twist_ref_input_deg: float | None = None
        """The input angle (deg) the twist reference was read at (None: not known)."""
        self._profile: str | None = None
        self._measuring = False
        self._monitor_lock = threading.Lock()
        self._estop_pending: str | None = None
        self._estop_latched: str | None = None
        """An E-stop pressed while idle: acknowledged by a fault reset, like a drive fault."""

    # ------------------------------------------------------------------ lifecycle

    def start(self) -> None:
        """Open the rig on a thread (the page is up meanwhile) and start the monitor."""
        if self.session_factory is None:
            return
        thread = threading.Thread(target=self._open_and_monitor, name="rig web monitor",
                                  daemon=True)
        thread.start()
        self._threads.append(thread)

    def close(self) -> None:
        """Stop any measurement (safe state), stop the monitor, close the rig."""
        self._stop.set()
        self._stop_lock_move("the control page was shut down")
        engine = self._engine
        if engine is not None:
            engine.abort("the control page was shut down")
        run_thread = self._run_thread
        if run_thread is not None:
            run_thread.join(timeout=30.0)
        for thread in self._threads:
            thread.join(timeout=30.0)
        with self._lock:
            self._stack.close()
            self.session = None

    def _open_and_monitor(self) -> None:
        assert self.session_factory is not None
        try:
            session = self._stack.enter_context(self.session_factory())
        except Exception as exc:  # any failure to open is shown on the page, not raised
            log.exception("the rig did not open")
            with self._lock:
                self.open_error = f"{type(exc).__name__}: {exc}"
                self.state = "no_rig"
                self.message = f"the rig did not open: {exc}"
            return
        with self._lock:
            self.session = session
            self.state = "idle"
            self.message = "rig connected"
            self._lock_by_motor = session.devices.input_motor is not None
        self.hub.add_event({"type": "state", "state": "idle"})
        next_metrics = time.monotonic()
        while not self._stop.wait(MONITOR_PERIOD_S):
            self._monitor_once()
            if self._busy() and time.monotonic() >= next_metrics:
                next_metrics = time.monotonic() + LIVE_METRICS_PERIOD_S
                self._live_metrics()

    # ------------------------------------------------------------------ monitor

    def _monitor_once(self) -> None:
        with self._monitor_lock:
            self._monitor_locked()

    def _monitor_locked(self) -> None:
        session = self.session
        if session is None:
            return
        devices = session.devices
        busy = self._measuring
        rows: list[dict[str, Any]] = []
        live: dict[str, Any] = {}
        for name in ("encoder", "input_encoder"):
            enc = getattr(devices, name)
            if enc is None:
                continue
            h = enc.health()
            rows.append({"name": name.replace("_", " "), "connected": h.ok or h.samples > 0,
                         "ok": h.ok, "heartbeat_age_s": h.heartbeat_age_s,
                         "detail": h.last_error or f"NMT {h.nmt_state}, {h.samples} samples"})
        if not busy and self._device_lock.acquire(timeout=1.0):
            try:
                devices.alive()
                live.update(self._idle_values(devices, rows))
            finally:
                self._device_lock.release()
        else:
            tap = self._tap
            latest = tap.recorder.latest if tap is not None and tap.recorder else None
            if tap is not None and tap.recorder is not None:
                self._twist_ref_from_run(tap.recorder)
            if latest is not None:
                live.update(torque_Nm=latest[1], output_arcmin=latest[2])
                if len(latest) > 4:
                    live["temperature_C"] = latest[4]
            rows.append({"name": "torque transducer", "connected": True, "ok": True,
                         "detail": "streaming to the measurement"})
        drive = devices.drive
        if drive is not None:
            try:
                st = drive.status()
                if not busy and (st.enabled or st.setpoint_Nm != 0) and not st.faulted:
                    st = self._unexpected_drive(drive, st)
                live.update(setpoint_Nm=st.setpoint_Nm, drive_enabled=st.enabled)
                self._safe = (not st.enabled) and st.setpoint_Nm == 0
                rows.append({"name": "loading drive", "connected": True, "ok": not st.faulted,
                             "detail": ("enabled" if st.enabled else "disabled") +
                             f", setpoint {st.setpoint_Nm:+.3f} N*m" +
                             (f", fault {st.fault_code.name}" if st.faulted else "")})
            except DeviceError as exc:
                self._safe = None
                rows.append({"name": "loading drive", "connected": False, "ok": False,
                             "detail": str(exc)})
        self._twist_from_angle(live, busy)
        if busy:
            rows = self._with_idle_rows(rows)
        else:
            self._idle_rows = json_safe(rows)
        with self._lock:
            self._devices = json_safe(rows)
            self._live = json_safe(live)
        self.hub.add_event({"type": "status"})

    def _with_idle_rows(self, rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
        """The device rows during a measurement: every device of the last idle pass keeps its
        row, in the same order (those the measurement owns are not polled meanwhile: said so,
        with their health as last read), the rows read now replacing their idle ones."""
        fresh = {r["name"]: r for r in rows}
        out = []
        for old in self._idle_rows:
            new = fresh.pop(old["name"], None)
            out.append(new if new is not None else {
                **old, "heartbeat_age_s": None,
                "detail": "in use by the measurement (not polled); before it: "
                          + str(old.get("detail", ""))})
        return out + list(fresh.values())

    def _twist_ref_from_run(self, recorder: Any) -> None:
        """During a measurement: a run at another input position than the reference's counts
        the twist from its own first sample (zero torque, right after the engine locked the
        input there). Without this, after a campaign over 0-270 deg the twist read the
        output's turn through the gear, -2025 arcmin at 270 deg (issue 33 item 16)."""
        first = recorder.first
        test = (recorder.meta or {}).get("test") or {}
        angle = test.get("input_angle_deg")
        if first is None or not isinstance(angle, int | float) or not math.isfinite(first[2]):
            return
        with self._lock:
            if (self._twist_ref_input_deg is not None
                    and abs(float(angle) - self._twist_ref_input_deg) < 0.5):
                return
            self._twist_ref_arcmin = first[2]
            self._twist_ref_input_deg = float(angle)

    def _twist_from_angle(self, live: dict[str, Any], busy: bool) -> None:
        """``live``: the raw output angle (``output_arcmin``) becomes ``output_angle_deg`` and
        the twist (arcmin) counted from the reference, wrapped to +-180 deg."""
        raw = live.pop("output_arcmin", None)
        if raw is None or not math.isfinite(raw):
            return
        live["output_angle_deg"] = raw / ARCMIN_PER_DEG
        if self._twist_ref_arcmin is None and not busy:
            self._twist_ref_arcmin = raw
        inp = live.get("input_angle_deg")
        if not busy and isinstance(inp, int | float) and math.isfinite(inp) and (
                self._twist_ref_arcmin is not None):
            # at rest (safe state: no torque) with the input where a measurement left it,
            # elsewhere than where the reference was read: the twist counts from here
            with self._lock:
                if self._twist_ref_input_deg is None:
                    self._twist_ref_input_deg = float(inp)
                elif abs(float(inp) - self._twist_ref_input_deg) >= 0.5:
                    self._twist_ref_arcmin = raw
                    self._twist_ref_input_deg = float(inp)
        if self._twist_ref_arcmin is not None:
            live["twist_arcmin"] = wrapped_arcmin(raw - self._twist_ref_arcmin)

    def _idle_values(self, devices: Any, rows: list[dict[str, Any]]) -> dict[str, Any]:
        """Last values while no measurement runs (each device read once)."""
        live: dict[str, Any] = {}
        readers: list[tuple[str, Callable[[], None]]] = []
        if devices.encoder is not None:
            def enc() -> None:
                live["output_arcmin"] = devices.encoder.read().angle_deg * ARCMIN_PER_DEG
            readers.append(("", enc))
        if devices.input_encoder is not None:
            def inp() -> None:
                live["input_angle_deg"] = devices.input_encoder.read().angle_deg
            readers.append(("", inp))
        if devices.transducer is not None:
            def tt() -> None:
                live["torque_Nm"] = devices.transducer.read().torque_Nm
                live.setdefault("temperature_C", devices.transducer.temperature_C())
            readers.append(("torque transducer", tt))
        if devices.torque_sensor is not None:
            def ts() -> None:
                live["crosscheck_torque_Nm"] = devices.torque_sensor.read().torque_Nm
            readers.append(("torque sensor", ts))
        if devices.climate is not None:
            def cl() -> None:
                live["temperature_C"] = devices.climate.state().housing_C
            readers.append(("climate chamber", cl))
        if devices.input_motor is not None:
            def im() -> None:
                s = devices.input_motor.state()
                live["input_angle_deg"] = s.angle_deg
                rows.append({"name": "input motor", "connected": True, "ok": not s.fault,
                             "detail": ("locked" if s.locked else "not locked") +
                             f" at {s.angle_deg:.2f} deg"})
            readers.append(("", im))
        for name, read in readers:
            try:
                read()
                if name:
                    rows.append({"name": name, "connected": True, "ok": True, "detail": "ok"})
            except DeviceError as exc:
                rows.append({"name": name or exc.device, "connected": False, "ok": False,
                             "detail": str(exc)})
        return live

    def _live_metrics(self) -> None:
        """Analyse the run being recorded as far as it goes (from the store: what is on disk)
        and send its metrics: they fill in as the loop closes (unavailable ones are None)."""
        from rig.results.analyse import analyse_run

        with self._lock:
            profile = self._profile
        tap = self._tap
        recorder = tap.recorder if tap is not None else None
        if recorder is None or recorder.finished:
            return
        if ((recorder.meta.get("test") or {}).get("kind")) == TE_KIND:
            return  # a transmission error run has no loop: its figures come at its end
        try:
            run = self.store.load_run(recorder.run_id)
            if run.n_samples < 50:
                return
            metrics = json_safe(analyse_run(run, profile=profile).to_dict())
        except Exception as exc:  # a loop half measured is often not analysable yet
            log.debug("live metrics of %s not available yet: %s", recorder.run_id, exc)
            return
        self.hub.add_event({"type": "metrics", "run_id": recorder.run_id, "partial": True,
                            "metrics": metrics})

    # ------------------------------------------------------------------ status

    def faults(self) -> list[dict[str, str]]:
        """Latched faults now (device and what it says; the E-stop pressed while idle): while
        any is latched, nothing starts until the operator resets them."""
        with self._lock:
            found = [{"device": d["name"], "detail": str(d.get("detail", ""))}
                     for d in self._devices if not d.get("ok", True)]
            if self._estop_latched:
                found.append({"device": "E-stop", "detail": self._estop_latched})
        return found

    def _refuse_if_faulted(self, what: str) -> None:
        faults = self.faults()
        if faults:
            listed = "; ".join(f"{f['device']}: {f['detail']}" for f in faults)
            raise ControlError(f"{what} refused: a fault is latched ({listed}). Remove its "
                               f"cause, then Reset faults (POST /api/devices/reset-faults)")

    def reset_faults(self, operator: str | None = None) -> dict[str, Any]:
        """Acknowledge and reset latched faults (the drive's fault latch, an E-stop pressed
        while idle); the drive stays disabled at zero torque. Logged in the store's audit
        trail with who and when. 409 while a measurement runs."""
        session = self._require_session()
        if self._busy():
            raise ControlError("a measurement is running: abort it before resetting faults")
        before = self.faults()
        errors: list[str] = []
        drive = session.devices.drive
        with self._device_lock:
            if drive is not None:
                try:
                    drive.reset_fault()
                    drive.safe_state()
                except DeviceError as exc:
                    errors.append(str(exc))
        with self._lock:
            self._estop_latched = None
            self._fault_reason = None
            if not self._busy() and self.state in ("idle", "completed", "aborted", "fault"):
                self.state = "idle"
        self._monitor_once()
        after = self.faults()
        rig_id = session.devices.config.rig.rig_id
        self.store.record_action("fault reset", target=f"rig {rig_id}", detail={
            "operator": operator, "before": before, "after": after, "errors": errors})
        cleared = [f for f in before if f not in after]
        message = ("faults reset: " + ", ".join(f["device"] for f in cleared) if cleared
                   else "no fault was latched") if not after else (
            "still faulted: " + "; ".join(f"{f['device']}: {f['detail']}" for f in after)
            + " (the cause is still there)")
        self.hub.add_event({"type": "state", "state": self.state})
        return {"ok": not after, "message": message, "cleared": cleared, "still": after}

    def _unexpected_drive(self, drive: Any, st: Any) -> Any:
        """Fault-matrix row 12: the drive enabled (or a setpoint set) while this station
        commands nothing, by hand or by another master. The idle page feeds the watchdog, so
        the drive's own watchdog would never take it off: bring it to the safe state now
        and say so; its status after."""
        if not self._device_lock.acquire(timeout=1.0):
            return st
        try:
            drive.safe_state()
            after = drive.status()
        except DeviceError as exc:
            log.error("drive found enabled while idle; safe state not confirmed: %s", exc)
            return st
        finally:
            self._device_lock.release()
        self.message = (f"the loading drive was enabled ({st.setpoint_Nm:+.3g} N*m) while this "
                        "station commanded nothing: brought to the safe state (zero torque, "
                        "disabled)")
        log.warning(self.message)
        self.hub.add_event({"type": "state", "state": self.state})
        return after

    def status(self, operator: bool) -> dict[str, Any]:
        """The page's view of the rig now (the ``Status`` model)."""
        faults = self.faults()
        with self._lock:
            progress = self._progress
            session = self.session
            state = self.state
            if faults and state in ("idle", "completed", "aborted"):
                state = "fault"  # never "idle" while a device is faulted
            out = {
                "state": state, "operator": operator, "faults": faults,
                "rig": (session.io.description if session is not None else
                        (self.description or None)),
                "rig_id": session.devices.config.rig.rig_id if session is not None else None,
                "calibration": ([] if session is None else
                                calibration_status(session.devices.config.calibration)),
                "simulated": self.simulated,
                "torque_limit_Nm": session.io.torque_limit_Nm if session is not None else None,
                "devices": list(self._devices), "live": dict(self._live), "safe": self._safe,
                "progress": None if progress is None else {
                    "step": progress.step, "n_steps": progress.n_steps,
                    "elapsed_s": progress.elapsed_s, "remaining_s": progress.remaining_s,
                    "description": progress.description or progress.message,
                    "run_label": progress.run_label, "run_id": progress.run_id},
                "fault": None if (f := explain(self._fault_reason)) is None else f.to_dict(),
                "input_lock": {"confirmed": self._lock_confirmed, "angle_deg": self._lock_angle,
                               "by_motor": self._lock_by_motor,
                               "moving": None if (m := self._lock_move) is None else {
                                   "target_deg": m["target_deg"],
                                   "angle_deg": m["angle_deg"]},
                               "failed": self._lock_failed},
                "current": None if self._current is None else dict(self._current),
                "last_result": self._last_result,
                "message": self.message,
            }
        return json_safe(out)

    def _require_session(self) -> RigSession:
        session = self.session
        if session is None:
            why = self.open_error or self.message
            raise ControlError(f"no rig is connected ({why})")
        return session

    def _busy(self) -> bool:
        return self._measuring

    # ------------------------------------------------------------------ preview

    def preview_facts(self) -> dict[str, Any]:
        """What a plan preview needs of the rig (cheap: no plan is built here, so previews
        can be computed outside the engine's process): the torque limit (N*m), the input
        motor and climate chamber, and the latched faults."""
        session = self.session
        return {"connected": session is not None,
                "torque_limit_Nm": None if session is None else session.io.torque_limit_Nm,
                "has_input_motor": bool(session is not None and session.io.has_input_motor),
                "has_climate": bool(session is not None and session.io.has_climate),
                "has_input_encoder": bool(session is not None
                                          and session.io.has_input_encoder),
                "faults": self.faults()}

    def preview(self, req: RunRequest) -> dict[str, Any]:
        """Steps, duration estimate and whether the plan fits the rig (nothing moves)."""
        return compute_preview(req, self.preview_facts())

    # ------------------------------------------------------------------ commands

    def start_measurement(self, req: RunRequest) -> dict[str, Any]:
        """Start a run or a campaign on a thread; 409 (ControlError) when not possible."""
        with self._lock:
            session = self._require_session()
            if self._busy():
                raise ControlError(f"a measurement is already {self.state}: abort it first")
            self._refuse_if_faulted("start")
            if self._lock_move is not None:
                raise ControlError(f"the input is still moving to "
                                   f"{self._lock_move['target_deg']:.3f} deg: start once it "
                                   f"is locked")
            if not self._lock_confirmed:
                raise ControlError("confirm the input lock first (Devices: Confirm input "
                                   "lock): a test may start only with the input locked")
            try:
                calibration_meta(session.devices.config.calibration, req.calibration_override,
                                 req.operator, how=OVERRIDE_HOW)
            except CalibrationExpired as exc:
                raise ControlError(str(exc)) from exc
            plan = build_plan(req)
            steps = list(plan.steps())
            est = estimate(steps)
            long = plan_duration_problem(est.total_s, req.confirm_long, "confirm_long")
            if long is not None:
                raise ControlError(long)
            limit = session.io.torque_limit_Nm
            if req.torque_limit_Nm is not None:
                limit = min(limit, req.torque_limit_Nm)
            try:
                preflight(steps, limit, has_input_motor=session.io.has_input_motor,
                          has_climate=session.io.has_climate)
            except PlanRejected as exc:
                raise ControlError(str(exc)) from exc
            self.state = "running"
            self.message = f"{req.kind} starting"
            self._fault_reason = None
            self._progress = None
            self._current = {"kind": req.kind, "test": req.test, "run_id": None,
                             "campaign_id": None,
                             "plan": plan.name, "n_steps": len(steps),
                             "estimated_s": est.total_s,
                             "n_runs": est.n_runs, "measuring": None, "finished": []}
            self._tap = TapStore(self.store, self.hub)
            self._profile = req.profile
            self._measuring = True
            self._estop_pending = None
            thread = threading.Thread(target=self._measure, args=(req, session),
                                      name="rig web measurement", daemon=True)
            self._run_thread = thread
        self.hub.add_event({"type": "state", "state": "running"})
        thread.start()
        return {"ok": True, "message": f"{req.kind} started: {plan.name}, {len(steps)} steps"}

    def _measure(self, req: RunRequest, session: RigSession) -> None:
        tap = self._tap
        assert tap is not None
        result: dict[str, Any] | None = None
        reason: str | None = None
        state = "aborted"
        with self._device_lock:
            try:
                session = self._plant_of_the_unit(req, session)
                if req.kind == "run":
                    result, state, reason = self._measure_run(req, session, tap)
                else:
                    result, state, reason = self._measure_campaign(req, session, tap)
            except (RigError, DeviceError, ValueError) as exc:
                reason = str(exc)
                log.error("measurement failed: %s", exc)
            except Exception as exc:  # a bug: shown on the page, the rig made safe
                reason = f"{type(exc).__name__}: {exc}"
                log.exception("measurement failed")
            finally:
                session.devices.safe_state()
        with self._lock:
            self.state = state
            self._engine = None
            self._fault_reason = reason if state != "completed" else None
            self._last_result = json_safe(result) if result is not None else None
            self.message = f"{req.kind} {state}" + (f": {reason}" if reason else "")
            if self._lock_by_motor:
                self._lock_confirmed = False  # the plan moved the input: confirm it again
            self._measuring = False
            self._estop_pending = None
        self._monitor_once()  # the devices as the end left them (safe state), at once
        self.hub.add_event({"type": "state", "state": state, "result": self._last_result})

    def _plant_of_the_unit(self, req: RunRequest, session: RigSession) -> RigSession:
        """The session to measure ``req``'s unit on: on the simulated rig whose plant is of
        another unit kind, a new simulated rig with the unit's plant (the old one closed, the
        input locked again where it was); else ``session``. Measurement thread, device lock
        held."""
        kind = str(req.unit.mapping().get("kind") or "internal_involute")
        have = plant_kind(session)
        if have is None or have == kind or self.unit_session_factory is None:
            return session
        with self._lock:
            self.message = f"restarting the simulated rig with the unit's plant ({kind})"
        self.hub.add_event({"type": "state", "state": "running", "message": self.message})
        log.info("simulated rig: %s plant, the unit is a %s: restarting it", have, kind)
        with self._monitor_lock:  # the idle monitor never reads a closing rig
            with self._lock:
                self.session = None
            self._stack.close()
            self._stack = contextlib.ExitStack()
            try:
                session = self._stack.enter_context(
                    self.unit_session_factory(req.unit.mapping()))
            except Exception as exc:
                log.exception("the simulated rig did not start with the unit's plant")
                if self.session_factory is not None:  # the rig as it was, for the next try
                    with self._lock:
                        self.session = self._stack.enter_context(self.session_factory())
                raise ControlError(f"the simulated rig did not start with the unit's "
                                   f"{kind} plant: {exc}") from exc
            with self._lock:
                self.session = session
                self._lock_by_motor = session.devices.input_motor is not None
        motor = session.devices.input_motor
        if motor is not None:  # the operator's lock, at the same input angle
            motor.lock_at(self._lock_angle if self._lock_angle is not None else 0.0, 30.0)
        ref = None
        with contextlib.suppress(DeviceError):
            ref = settled_output_arcmin(session.devices.encoder)
        with self._lock:
            if ref is not None and math.isfinite(ref):
                self._twist_ref_arcmin = ref
                self._twist_ref_input_deg = self._lock_angle
            self.message = f"{req.kind} starting on the simulated {kind} plant"
        return session

    def _measure_run(self, req: RunRequest, session: RigSession, tap: TapStore
                     ) -> tuple[dict[str, Any], str, str | None]:
        measured = measure_run(single_run_request(req), session, tap, progress=self._on_event,
                               on_engine=self._set_engine)
        result = {"kind": "run", **measured.summary()}
        if req.test != TE_KIND:
            result.update(unit_design(req))
        return result, measured.state, measured.reason

    def _measure_campaign(self, req: RunRequest, session: RigSession, tap: TapStore
                          ) -> tuple[dict[str, Any], str, str | None]:
        data: dict[str, Any] = {
            "name": req.name, "operator": req.operator, "profile": req.profile,
            "torque_limit_Nm": req.torque_limit_Nm, "unit": req.unit.mapping(),
            "plan": req.plan.loop_params().model_dump(), "axes": req.axes.model_dump(),
            "limits": req.limits.model_dump(),
            "calibration_override": req.calibration_override,
        }
        if req.test == TE_KIND:
            data.update(test=TE_KIND, te=req.te.model_dump(exclude_none=True),
                        axes={"repeats": req.axes.repeats,
                              "temperatures_C": list(req.axes.temperatures_C)})
        camp = campaign_from_mapping({k: v for k, v in data.items() if v is not None},
                                     source="<control page>")
        result = run_campaign(camp, session, tap, progress=self._on_event,
                              on_engine=self._set_engine, override_how=OVERRIDE_HOW)
        with self._lock:
            if self._current is not None:
                self._current["campaign_id"] = result.get("campaign_id")
        return {"kind": "campaign", **result}, result["status"], result.get("reason")

    def _set_engine(self, engine: Engine) -> None:
        with self._lock:
            self._engine = engine
            stop = self._stop.is_set()
            estop, self._estop_pending = self._estop_pending, None
        if estop:  # pressed while the measurement was being set up: it never moves
            engine.estop(estop)
        elif stop:
            engine.abort("the control page was shut down")

    def _on_event(self, event: ProgressEvent) -> None:
        """Engine thread: keep the latest progress, forward it to the pages (cheap)."""
        with self._lock:
            self._progress = event
            if event.kind in ("paused", "resumed"):
                self.state = event.state
            if event.kind in ("fault", "abort", "estop"):
                self.state = "stopping"
                self._fault_reason = event.message
            if self._current is not None and event.run_id:
                self._current["run_id"] = event.run_id
            if event.kind == "run_started" and self._current is not None:
                camp = getattr(self._engine, "campaign_id", None)
                if camp:
                    self._current["campaign_id"] = camp
                self._current["measuring"] = self._measuring_now(event)
            if event.kind == "run_finished" and self._current is not None:
                self._current["finished"].append(finished_run(event.data))
                self._current["measuring"] = None
        tap = self._tap
        if event.kind == "run_finished" and tap is not None and tap.recorder is not None:
            self._twist_ref_from_run(tap.recorder)  # a run shorter than a status poll too
        self.hub.add_event({"type": "progress", **json_safe(event.to_dict())})

    def _measuring_now(self, event: ProgressEvent) -> dict[str, Any]:
        """The run just begun: its label, number of the plan's runs, input position (deg),
        amplitude (% of rated) and housing temperature (deg C) from its run.json ``test``."""
        tap = self._tap
        recorder = tap.recorder if tap is not None else None
        test = dict(recorder.meta.get("test") or {}) if recorder is not None else {}
        assert self._current is not None
        return {"run_id": event.run_id, "label": event.run_label,
                "number": len(self._current["finished"]) + 1,
                "n_runs": self._current.get("n_runs"),
                "input_angle_deg": test.get("input_angle_deg"),
                "amplitude_pct": test.get("amplitude_pct"),
                "temperature_C": test.get("temperature_C")}

    def _running_engine(self) -> Engine:
        engine = self._engine
        if engine is None or not self._busy():
            raise ControlError("no measurement is running")
        return engine

    def pause(self) -> str:
        self._running_engine().pause()
        return "pause requested: the rig holds its torque at the next checkpoint"

    def resume(self) -> str:
        self._running_engine().resume()
        with self._lock:
            if self.state == "paused":
                self.state = "running"
        return "resumed"

    def abort(self) -> str:
        self._running_engine().abort("aborted by the operator")
        return "aborted: the drive is off and the torque zero; the samples so far are kept"

    def estop(self) -> str:
        """Safe state now, whatever the state: the engine's E-stop if a measurement runs,
        else zero torque and the drive disabled directly. Never refused."""
        reason = "E-stop pressed on the control page"
        self._stop_lock_move(reason)
        with self._lock:
            engine = self._engine
            if engine is None and self._measuring:
                self._estop_pending = reason  # the engine being set up stops at once
        done = []
        if engine is not None or self._estop_pending:
            if engine is not None:
                engine.estop(reason)
            done.append("measurement stopped")
        session = self.session
        if session is not None:
            ok = session.devices.safe_state()
            done.append("drive disabled, torque zero" if ok else
                        "drive not reachable: its watchdog disables it")
            with self._lock:
                self._fault_reason = reason
                if not self._busy():
                    self.state = "idle"
                self._estop_latched = reason  # acknowledged by Reset faults
                self._lock_confirmed = False
        else:
            done.append("no rig connected")
        self.hub.add_event({"type": "state", "state": self.state, "estop": True})
        return "E-stop: " + "; ".join(done)

    def tare(self) -> float:
        """Tare the torque transducer (unit unloaded, no measurement running); N*m."""
        session = self._require_session()
        if self._busy():
            raise ControlError("cannot tare during a measurement")
        if self._lock_move is not None:
            raise ControlError("cannot tare while the input turns to its lock angle")
        transducer = session.devices.transducer
        if transducer is None:
            raise ControlError("the rig has no torque transducer to tare")
        with self._device_lock:
            try:
                offset = transducer.tare()
            except DeviceError as exc:
                raise ControlError(f"tare refused: {exc}") from exc
        return float(offset)

    def confirm_input_lock(self, req: InputLockRequest) -> dict[str, Any]:
        """Lock the input with the motor (if any, at ``angle_deg``) and record the operator's
        confirmation; ``confirm`` False withdraws it. Answers within :data:`LOCK_ANSWER_S`
        whatever the move's length (issue 33 item 7): a longer move goes on in
        :meth:`_follow_lock_move` (``moving`` True in the answer), its progress on the live
        stream (``input_lock`` events) and in the status; the lock is confirmed when it ends.
        A second lock while the input moves is refused (ControlError)."""
        session = self._require_session()
        if self._busy():
            raise ControlError("cannot change the input lock during a measurement")
        with self._lock:
            move = self._lock_move
        if move is not None:
            raise ControlError(f"the input is already moving to {move['target_deg']:.3f} deg: "
                               f"wait until it is locked (or press E-STOP to stop it)")
        if not req.confirm:
            with self._lock:
                self._lock_confirmed = False
            return {"ok": True, "message": "input lock confirmation withdrawn"}
        motor = session.devices.input_motor
        if motor is None:
            self._confirm_lock(session, req.angle_deg)
            return {"ok": True, "message": "input lock confirmed by the operator"}
        done = threading.Event()
        with self._device_lock:
            try:
                target = (float(req.angle_deg) if req.angle_deg is not None
                          else motor.state().angle_deg)
                with self._lock:
                    if self._lock_move is not None:  # another request got here first
                        raise ControlError(f"the input is already moving to "
                                           f"{self._lock_move['target_deg']:.3f} deg: wait "
                                           f"until it is locked (or press E-STOP to stop it)")
                    self._lock_confirmed = False  # the input moves: not locked meanwhile
                    self._lock_failed = None
                    self._lock_cancel = None
                    self._lock_move = {"target_deg": target, "angle_deg": None, "done": done,
                                       "result": None}
                motor.start_lock_at(target)
            except DeviceError as exc:
                with self._lock:
                    self._lock_move = None
                raise ControlError(f"the input did not lock: {exc}") from exc
        threading.Thread(target=self._follow_lock_move, args=(session, motor, target),
                         name="rig web input lock", daemon=True).start()
        self.hub.add_event({"type": "input_lock", "state": "moving", "target_deg": target,
                            "angle_deg": None})
        if done.wait(LOCK_ANSWER_S):  # a short move: its end is the answer
            failed, text = self._lock_move_result
            if failed:
                raise ControlError(text)
            return {"ok": True, "message": text}
        return {"ok": True, "moving": True, "target_deg": target,
                "message": f"the input is moving to {target:.3f} deg; it is confirmed once "
                           f"locked (progress on the page and the live stream)"}

    def _follow_lock_move(self, session: RigSession, motor: Any, target: float) -> None:
        """Input lock thread: follow the motor to ``target`` (deg) until it reports LOCKED
        there, sending its angle every :data:`LOCK_PROGRESS_PERIOD_S`; then confirm the
        lock. A fault, a timeout (the motor's ``move_timeout_s``), an E-stop or the page
        closing: the motor stops where it is, the drive goes to the safe state, the lock
        stays unconfirmed and the reason is sent (``failed``)."""
        config = getattr(motor, "config", None)
        timeout_s = float(getattr(config, "move_timeout_s", 30.0))
        tolerance = float(getattr(config, "lock_tolerance_deg", 0.01))
        deadline = time.monotonic() + timeout_s
        next_event = 0.0
        angle: float | None = None
        failure: str | None = None
        try:
            while True:
                with self._lock:
                    cancel = self._lock_cancel
                if cancel is None and self._stop.is_set():
                    cancel = "the control page was shut down"
                if cancel is not None:
                    failure = f"the input lock move was stopped: {cancel}"
                    break
                st = motor.state()
                angle = st.angle_deg
                if st.fault:
                    failure = (f"the input motor reports a fault at {angle:.3f} deg while "
                               f"turning to {target:.3f} deg")
                    break
                if st.locked and abs(angle - target) <= tolerance:
                    break
                if time.monotonic() > deadline:
                    failure = (f"the input did not lock at {target:.3f} deg within "
                               f"{timeout_s:g} s (it is at {angle:.3f} deg)")
                    break
                with self._lock:
                    if self._lock_move is not None:
                        self._lock_move["angle_deg"] = angle
                if time.monotonic() >= next_event:
                    next_event = time.monotonic() + LOCK_PROGRESS_PERIOD_S
                    self.hub.add_event({"type": "input_lock", "state": "moving",
                                        "target_deg": target, "angle_deg": angle})
                time.sleep(0.05)
        except DeviceError as exc:
            failure = f"the input did not lock: {exc}"
        except Exception as exc:  # a bug: the rig made safe all the same
            log.exception("input lock move")
            failure = f"the input did not lock: {type(exc).__name__}: {exc}"
        if failure is None:
            angle = self._confirm_lock(session, angle)
            text = f"input locked by the motor at {angle:.3f} deg"
        else:
            with contextlib.suppress(DeviceError):
                motor.stop()  # held where it is
            session.devices.safe_state()
            log.error("input lock failed: %s", failure)
            text = failure
        with self._lock:
            move, self._lock_move = self._lock_move, None
            self._lock_move_result = (failure is not None, text)
            self._lock_failed = failure
            if failure is not None:
                self._lock_confirmed = False
                self.message = f"input lock failed: {failure}"
        self.hub.add_event({"type": "input_lock", "state": "failed" if failure else "done",
                            "target_deg": target, "angle_deg": angle, "message": text})
        if move is not None:
            move["done"].set()

    def _confirm_lock(self, session: RigSession, angle: float | None) -> float | None:
        """The input is locked (at ``angle`` deg, None: by hand): the twist counts from the
        output angle now (zero torque), and the lock is confirmed. Returns ``angle``."""
        ref = None
        with self._device_lock, contextlib.suppress(DeviceError):
            ref = settled_output_arcmin(session.devices.encoder)
        with self._lock:
            self._lock_confirmed = True
            self._lock_angle = angle
            if ref is not None and math.isfinite(ref):
                self._twist_ref_arcmin = ref  # the twist counts from here (zero torque)
                self._twist_ref_input_deg = angle
        return angle

    def _stop_lock_move(self, reason: str) -> None:
        """An input lock move in progress stops now (E-stop, shutdown): the motor is told to
        stop where it is; the move's thread then ends it (safe state, ``failed``)."""
        with self._lock:
            moving = self._lock_move is not None
            if moving:
                self._lock_cancel = reason
            session = self.session
        motor = session.devices.input_motor if session is not None else None
        if moving and motor is not None:
            with contextlib.suppress(DeviceError):
                motor.stop()
