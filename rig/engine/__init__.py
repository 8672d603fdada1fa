"""The engine: executes a plan's steps against the rig, records runs into the store.

Threads (docs/campaigns.md, "Engine"):

- the caller's thread executes the steps (ramps, settles, dwells, moves);
- a torque thread reads the transducer stream and trips on any sample beyond the limit;
- a poll thread takes the encoder samples, merges the channels (:mod:`rig.engine.merge`),
  appends the rows of the open run to the store, checks the devices every 0.1 s (heartbeats,
  drive faults, the keepalive), reads the housing temperature (1 s) and the cross-check torque
  sensor (0.2 s), and trips when no merged sample has come for ``stale_timeout_s``.

Control from any thread: :meth:`Engine.pause` (honoured at the next checkpoint: the torque is
held, samples keep being recorded), :meth:`Engine.resume`, :meth:`Engine.abort` and
:meth:`Engine.estop`. A fault, an abort or an E-stop puts the rig in its safe state *at once*
from the thread that sees it (torque setpoint zero and drive disabled in one request; no
command is sent after it), the open run is kept and closed as "aborted" with the reason, and
:meth:`Engine.run` returns the outcomes. The end of every plan also leaves the rig safe.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drivers.errors import DeviceError, DeviceFault, DeviceTimeout
from rig.core.errors import RigError
from rig.engine.events import EventHub, ProgressEvent
from rig.engine.frozen import FrozenTwistWatch
from rig.engine.io import RigIO
from rig.engine.merge import ChannelMerger, ControlLog, ControlState, MergedRow
from rig.engine.record import OpenRun, RunOutcome
from rig.engine.safety import check_command, check_measured, preflight
from rig.plans import TE_KIND, Plan, run_label
from rig.plans.estimate import PlanEstimate, estimate
from rig.plans.steps import (
    BeginRun,
    Checkpoint,
    Dwell,
    EndRun,
    LockInput,
    Ramp,
    ReadTorqueZero,
    Sample,
    SetAmbient,
    Settle,
    Step,
    StepTwist,
    TurnInput,
    WaitTemperature,
    describe,
)
from rig.results.outcome import LIMIT_KEYS
from rig.store import Store, StoreDiskFull, StoreUnavailable

log = logging.getLogger(__name__)

ARCMIN_PER_DEG = 60.0
UNRECORDED_MAX_ROWS = 500_000
"""Rows kept of a run's preparation (pre-cycles, preload) before its recording begins: the
newest ~33 min at 250 Hz, kept in an aborted run if the plan stops before the recording."""
JUMP_GAP_S = 0.03
JUMP_MIN_DT_S = 5e-4
JUMP_GAP_TOLERANCE_DEG = 0.5
"""Two rows of a transmission error run further apart than ``JUMP_GAP_S`` (s: rows left out
unpaired, or a stalled PC) are a count jump only beyond this much more TE change (output
deg): the unit's own TE may have moved meanwhile, by far less."""
ZERO_WAIT_MAX_S = 5.0
"""How long (s) after its window the torque zero waits for the window's rows while rows still
come, however late (a PC that reads the devices behind; the stale-sample trip covers none)."""
STORE_RETRY_PERIOD_S = 1.0
"""While the store's database is away, the engine (paused, drive disabled) tries it this
often (s)."""
UNSTARTED_NOTE = ("stopped before its recording began: the samples are the preparation's "
                  "(torque zero, preload, pre-cycles), not a loop")


class EngineStopped(RigError):
    """The plan stopped before its end (fault, abort or E-stop); ``reason`` says why."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


@dataclass
class EngineOptions:
    """Tuning of the engine (s, N*m). ``torque_limit_Nm`` (None: the rig's) may only lower
    the rig's limit; ``measured_trip_margin_Nm`` is added to it for the measured-torque trip
    (0: trip on any sample beyond the limit)."""

    torque_limit_Nm: float | None = None
    measured_trip_margin_Nm: float = 0.0
    stale_timeout_s: float = 1.0
    poll_period_s: float = 0.005
    check_period_s: float = 0.1
    temperature_period_s: float = 1.0
    crosscheck_period_s: float = 0.2
    crosscheck_window_s: float = 0.05
    crosscheck_still_s: float = 0.2
    crosscheck_limit_share: float | None = 0.1
    """The cross-check torque sensor may read at most this share of the run's rated torque
    beside the transducer's readings of the same instant (±``crosscheck_window_s``): beyond
    it one channel is late, mis-scaled or broken, and the run is stopped (None: recorded
    only)."""
    recent_s: float = 5.0
    drain_timeout_s: float = 1.0
    profile: str | None = None
    extra_meta: dict[str, Any] = field(default_factory=dict)
    run_meta: Callable[[dict[str, Any]], dict[str, Any]] | None = None
    """Extra run.json keys of one run from its ``test`` (e.g. the simulated plant's truth
    under ``generator``, rig/measurement/service.py); None: none."""
    limits: dict[str, Any] | None = None
    """The limits of the runs (rig/results/outcome.py keys): run.json ``limits``, and ``outcome``
    against them."""


class Engine:
    """Runs plans on one rig into one store (see the module docstring).

    ``meta``: run.json keys every run carries (``unit``, ``operator``, ``rig_id``,
    ``calibration`` ...); ``campaign_id``: a running campaign of the store the runs join.
    """

    def __init__(self, io: RigIO, store: Store, *, meta: dict[str, Any] | None = None,
                 campaign_id: str | None = None, options: EngineOptions | None = None) -> None:
        self.io = io
        self.store = store
        self.meta = dict(meta or {})
        self.campaign_id = campaign_id
        self.options = options or EngineOptions()
        limit = io.torque_limit_Nm
        if self.options.torque_limit_Nm is not None:
            limit = min(limit, self.options.torque_limit_Nm)
        self._torque_limit_Nm = float(limit)
        self.trip_Nm = self.torque_limit_Nm + self.options.measured_trip_margin_Nm
        self.hub = EventHub()
        self.state = "idle"
        self.outcomes: list[RunOutcome] = []
        self._lock = threading.Lock()  # merger, recent rows, open run
        self._cmd_lock = threading.Lock()  # commands vs the safe state
        self._wake = threading.Event()
        self._resume = threading.Event()
        self._stop_threads = threading.Event()
        self._pause_requested = False
        self._stopping: str | None = None
        self._merger = ChannelMerger()
        self._dropped_at_begin = 0
        self._frozen: FrozenTwistWatch | None = None
        self._recent: deque[MergedRow] = deque()
        self._torque_arrivals: deque[tuple[float, float]] = deque(maxlen=4000)
        self._open: OpenRun | None = None
        self._setpoint = 0.0
        self._sample_window = 0
        self._direction = 0
        self._step_index = 0
        self._control = ControlLog()
        """The setpoint, step and sample window over time: a row gets those of the instant it
        was measured (rig.engine.merge.ControlLog)."""
        self._temperature: float | None = None
        self._crosscheck_max_diff = 0.0
        self._cross_pending: deque[tuple[float, float, float]] = deque(maxlen=200)
        self._cross_limit_Nm: float | None = None
        self._last_row_mono = time.monotonic()
        self._zero_before: float | None = None
        self._plan: Plan | None = None
        self._estimate = PlanEstimate()
        self._t_start = time.monotonic()
        self._threads: list[threading.Thread] = []
        self._steps: list[Step] = []
        self._moved = False
        """The drive was enabled or torque commanded since the plan began or its last run
        ended: a stop before the next run's recording then leaves a record of it."""
        self._unrecorded: deque[tuple[MergedRow, float, int]] = deque(
            maxlen=UNRECORDED_MAX_ROWS)
        """Rows merged while the drive is enabled and no run is recording (the preparation
        of the next run: preload, pre-cycles), with the setpoint and step in force."""

    # ------------------------------------------------------------------ control (any thread)


    @property
    def torque_limit_Nm(self) -> float:
        """The most this engine commands (N*m), fixed when it was made (read-only)."""
        return self._torque_limit_Nm
    def subscribe(self, callback) -> Any:
        """Call ``callback(ProgressEvent)`` for every event; returns an unsubscribe function."""
        return self.hub.subscribe(callback)

    def pause(self) -> None:
        """Pause at the next checkpoint (the torque is held there)."""
        self._pause_requested = True
        self._resume.clear()

    def resume(self) -> None:
        self._pause_requested = False
        self._resume.set()
        self._wake.set()

    def abort(self, reason: str = "aborted by the operator") -> None:
        """Stop now: safe state at once, the open run kept and marked aborted."""
        self._trip(reason, kind="abort")

    def estop(self, reason: str = "E-stop pressed") -> None:
        """Emergency stop: safe state at once from the calling thread."""
        self._trip(f"E-stop: {reason}" if not reason.startswith("E-stop") else reason,
                   kind="estop")

    @property
    def stopping_reason(self) -> str | None:
        return self._stopping

    def _trip(self, reason: str, kind: str = "fault") -> None:
        with self._cmd_lock:
            first = self._stopping is None
            if first:
                self._stopping = reason
            try:
                self.io.safe_state()
            except DeviceError as exc:  # the drive's watchdog takes it to the same state
                log.error("safe state not confirmed (%s); the drive watchdog takes over", exc)
        self._wake.set()
        self._resume.set()
        if first:
            log.warning("engine stopping: %s", reason)
            self._publish(kind, message=reason)

    # ------------------------------------------------------------------ events

    def _publish(self, kind: str, message: str = "", data: dict[str, Any] | None = None,
                 run: Any = None) -> None:
        """Publish a progress event; ``run_label``/``run_id`` are those of ``run`` (the run
        just finished, no longer open) if given, else of the open run."""
        open_run = run if run is not None else self._open
        n = self._estimate.n_steps
        done = min(self._step_index, n)
        self.hub.publish(ProgressEvent(
            kind=kind, state=self.state, step=done, n_steps=n,
            elapsed_s=time.monotonic() - self._t_start,
            remaining_s=self._estimate.remaining_s(done),
            description=message if kind == "step" else "",
            run_label=None if open_run is None else open_run.label,
            run_id=None if open_run is None else open_run.recorder.run_id,
            message=message, data=data or {},
        ))

    # ------------------------------------------------------------------ running a plan

    def preview(self, plan: Plan) -> tuple[list[str], PlanEstimate]:
        """The plan's steps as text and its duration estimate (nothing moves)."""
        steps = list(plan.steps())
        return plan.listing(), estimate(steps)

    def run(self, plan: Plan) -> list[RunOutcome]:
        """Execute ``plan``; return the outcome of every run begun (completed or aborted).

        Raises PlanRejected before anything moves if the plan does not fit the rig. A device
        fault, abort or E-stop does not raise: the state becomes "aborted" and the reason is
        in :attr:`stopping_reason` and the last outcome.
        """
        steps = list(plan.steps())
        preflight(steps, self.torque_limit_Nm, has_input_motor=self.io.has_input_motor,
                  has_climate=self.io.has_climate,
                  has_input_encoder=self.io.has_input_encoder)
        self._merger.wait_input = any(isinstance(st, TurnInput) for st in steps)
        self._plan = plan
        self._steps = steps
        self._step_index = 0
        self._moved = False
        self._unrecorded.clear()
        self._estimate = estimate(steps)
        self._t_start = time.monotonic()
        self.outcomes = []
        self.state = "running"
        self._publish("start", message=f"plan {plan.name}: {len(steps)} steps, about "
                      f"{self._estimate.total_s:.0f} s")
        try:
            self.io.start_acquisition()
            self._start_threads()
            self._wait_first_rows()
            with self._cmd_lock:
                self._check_stopping()
                self.io.set_torque(0.0)
                self._moved = True  # from here a stop leaves a run record (issue 21 item 6)
                self.io.enable_drive()
            for i, step in enumerate(steps):
                self._step_index = i
                self._note_control()
                self._check_stopping()
                self._publish("step", message=describe(step))
                self._execute(step)
            self._step_index = len(steps)
            self.state = "completed"
        except EngineStopped:
            self.state = "aborted"
        except (DeviceError, StoreDiskFull) as exc:
            self._trip(str(exc))
            self.state = "aborted"
        except BaseException as exc:  # KeyboardInterrupt, a bug: the rig goes safe first
            self._trip(f"{type(exc).__name__}: {exc}")
            self.state = "aborted"
            self._finish_open(f"{type(exc).__name__}: {exc}")
            self._shutdown()
            raise
        finally:
            if self.state != "aborted":
                self._safe_end()
        if self.state == "aborted":
            self._finish_open(self._stopping or "stopped")
        self._shutdown()
        self._publish("finished", message=f"plan {plan.name} {self.state}"
                      + (f": {self._stopping}" if self._stopping else ""))
        return list(self.outcomes)

    def _safe_end(self) -> None:
        """Normal end: torque to zero and the drive disabled (the safe state)."""
        with self._cmd_lock:
            try:
                self.io.safe_state()
            except DeviceError as exc:
                log.error("safe state at the end not confirmed: %s", exc)

    def _shutdown(self) -> None:
        self._stop_threads.set()
        for thread in self._threads:
            thread.join(timeout=5.0)
        self._threads = []
        self.io.stop_acquisition()

    def _finish_open(self, reason: str) -> None:
        with self._lock:
            open_run, self._open = self._open, None
        if open_run is None:
            open_run = self._record_unstarted(reason)
        if open_run is not None:
            open_run.samples_dropped = self._dropped_total() - self._dropped_at_begin
            self.outcomes.append(open_run.finish_aborted(reason))
            self._publish("run_finished", message=f"run {open_run.label} aborted: {reason}",
                          data=self.outcomes[-1].to_dict(), run=open_run)

    def _next_begin(self) -> BeginRun | None:
        """The BeginRun step the plan was preparing when it stopped (None: no run ahead)."""
        for step in self._steps[self._step_index:]:
            if isinstance(step, BeginRun):
                return step
        return None

    def _record_unstarted(self, reason: str) -> OpenRun | None:
        """A stop after the drive moved but before the run's recording began: open the run
        it was preparing in the store with the preparation's rows (pre-cycles, preload;
        possibly none), so that every start that moved the drive leaves an aborted run with
        its reason, samples and audit record (issue 21 item 6). None when the drive never
        moved or no run was ahead; the record is best effort (a store error is logged)."""
        step = self._next_begin() if self._moved else None
        if step is None:
            return None
        with self._lock:
            rows = list(self._unrecorded)
            self._unrecorded.clear()
        try:
            open_run = self._open_run(step, step.label, dict(step.test),
                                      t0=rows[0][0].t_mono_s if rows else time.monotonic())
            for row, setpoint, index in rows:
                open_run.append([row], setpoint, index, 0)
            open_run.note(UNSTARTED_NOTE)
        except Exception:  # the rig is safe already; the record is what failed
            log.exception("the aborted run of a stop before its recording was not stored")
            return None
        self._dropped_at_begin = self._dropped_total()
        return open_run

    # ------------------------------------------------------------------ threads

    def _start_threads(self) -> None:
        self._stop_threads.clear()
        self._last_row_mono = time.monotonic()
        for target, name in ((self._torque_loop, "rig-torque"), (self._poll_loop, "rig-poll")):
            thread = threading.Thread(target=self._guarded, args=(target, name), name=name,
                                      daemon=True)
            thread.start()
            self._threads.append(thread)

    def _guarded(self, loop: Any, name: str) -> None:
        """Run an acquisition thread's loop; an unexpected error (a bug, not a device fault)
        stops the run at once with its name, instead of leaving the run without that thread
        until the stale-sample trip (the traceback goes to the log)."""
        try:
            loop()
        except StoreDiskFull as exc:  # the samples written so far are kept whole
            if not self._stop_threads.is_set():
                self._trip(str(exc))
        except Exception as exc:
            log.exception("unexpected error in the %s thread", name)
            if not self._stop_threads.is_set():
                self._trip(f"internal error in the {name} thread: {type(exc).__name__}: {exc} "
                           "(the traceback is in the log)")

    def _torque_loop(self) -> None:
        while not self._stop_threads.is_set():
            try:
                samples = self.io.take_torque(0.5)
            except DeviceError as exc:
                if not self._stop_threads.is_set():
                    self._trip(str(exc))
                return
            for t, torque in samples:
                reason = check_measured(torque, self.trip_Nm, "torque transducer")
                if reason is not None:
                    self._trip(reason)
                with self._lock:
                    self._merger.add_torque(t, torque)
                    self._torque_arrivals.append((t, torque))

    def _poll_loop(self) -> None:
        opt = self.options
        next_check = next_temp = next_cross = time.monotonic()
        while not self._stop_threads.is_set():
            now = time.monotonic()
            try:
                out = self.io.take_output()
                inp = self.io.take_input()
                self._merge(out, inp)
                if now >= next_check:
                    next_check = now + opt.check_period_s
                    self.io.alive()
                    self.io.check()
                    if now - self._last_row_mono > opt.stale_timeout_s and self._stopping is None:
                        raise DeviceTimeout(
                            "acquisition", f"merged samples (encoder + torque stream) within "
                            f"{opt.stale_timeout_s:g} s",
                            f"none for {now - self._last_row_mono:.2f} s "
                            f"({self._merger.pending} encoder samples waiting for torque)")
                if now >= next_temp:
                    next_temp = now + opt.temperature_period_s
                    temp = self.io.read_temperature()
                    if temp is not None:
                        self._temperature = temp
                        with self._lock:
                            self._merger.set_temperature(temp)
                if now >= next_cross:
                    next_cross = now + opt.crosscheck_period_s
                    self._crosscheck()
            except DeviceError as exc:
                if not self._stop_threads.is_set():
                    self._trip(str(exc))
                return
            self._stop_threads.wait(opt.poll_period_s)

    def _crosscheck(self) -> None:
        t0 = time.monotonic()
        torque = self.io.read_crosscheck_torque()
        if torque is None:
            return
        t1 = time.monotonic()
        reason = check_measured(torque, self.trip_Nm, "cross-check torque sensor")
        if reason is not None:
            self._trip(reason)
        with self._lock:
            self._cross_pending.append((t0, t1, torque))

    def _compare_crosscheck(self) -> str | None:
        """Compare each pending cross-check reading with the torque transducer's readings taken
        while the cross-check sensor was read, both on this PC's clock: the transducer's by its
        device clock mapped onto the host's (rig.engine.steady_clock; a line that a busy PC
        read late keeps the time it was measured: with arrival times, lines read 0.2 s late
        under load looked like a disagreement and stopped healthy runs), the Modbus read by the
        host time around it. Compared only when the transducer's torque has stood still for
        ``crosscheck_still_s`` before the read, so a ramp cannot look like a disagreement; a
        transducer stream that is behind by more than that shows as one. Returns a trip
        reason beyond the limit.
        Called holding ``_lock``."""
        w = self.options.crosscheck_window_s
        pending = self._cross_pending
        arrivals = self._torque_arrivals
        if self._open is None:
            pending.clear()
            return None
        if not pending or not arrivals:
            return None
        t_end = arrivals[-1][0]
        reason = None
        while pending and pending[0][1] + w <= t_end:
            t0, t1, value = pending.popleft()
            near = [v for t, v in arrivals if t0 - w <= t <= t1 + w]
            before = [v for t, v in arrivals
                      if t0 - self.options.crosscheck_still_s <= t <= t1 + w]
            limit = self._cross_limit_Nm
            if not near or (limit is not None and max(before) - min(before) > 0.25 * limit):
                continue
            diff = max(0.0, min(near) - value, value - max(near))
            self._open.note_crosscheck(diff)
            if limit is not None and diff > limit and reason is None:
                reason = (f"torque channels: expected the cross-check torque sensor within "
                          f"{limit:.3g} N*m of the torque transducer at the same instant, got "
                          f"{value:+.3g} N*m beside {min(near):+.3g}..{max(near):+.3g} N*m "
                          f"(one channel late, mis-scaled or broken: check both sensors)")
        return reason

    def _merge(self, out: list[tuple[float, float]], inp: list[tuple[float, float]]) -> None:
        with self._lock:
            for t, a in inp:
                self._merger.add_input(t, a)
            for t, a in out:
                self._merger.add_output(t, a)
            rows = self._merger.pop_rows()
            if not rows:
                return
            self._last_row_mono = time.monotonic()
            recent = self._recent
            recent.extend(rows)
            horizon = rows[-1].t_mono_s - self.options.recent_s
            while recent and recent[0].t_mono_s < horizon:
                recent.popleft()
            if self._open is not None:
                for group, state in self._by_control_state(rows):
                    self._open.append(group, state.setpoint_Nm, state.step,
                                      state.sample_window, state.direction)
            elif self._moved:
                for group, state in self._by_control_state(rows):
                    self._unrecorded.extend((r, state.setpoint_Nm, state.step) for r in group)
            mismatch = self._compare_crosscheck()
            watch = self._frozen if self._open is not None else None
            frozen = None if watch is None else watch.update(
                (r.t_mono_s, r.torque_Nm, r.output_angle_deg) for r in rows)
        if frozen is not None:
            self._trip(frozen)
        if mismatch is not None:
            self._trip(mismatch)

    def _note_control(self) -> None:
        """Log the control state in force from now (setpoint, step, sample window)."""
        self._control.set(time.monotonic(), ControlState(
            self._setpoint, self._step_index + 1, self._sample_window, self._direction))

    def _by_control_state(self, rows: list[MergedRow]
                          ) -> list[tuple[list[MergedRow], ControlState]]:
        """``rows`` in runs of one control state: the state when each row was measured."""
        now = ControlState(self._setpoint, self._step_index + 1, self._sample_window,
                           self._direction)
        out: list[tuple[list[MergedRow], ControlState]] = []
        for row in rows:
            state = self._control.at(row.t_mono_s) or now
            if out and out[-1][1] == state:
                out[-1][0].append(row)
            else:
                out.append(([row], state))
        return out

    def _wait_first_rows(self) -> None:
        deadline = time.monotonic() + max(2.0, self.options.stale_timeout_s)
        while True:
            self._check_stopping()
            with self._lock:
                if self._recent:
                    return
            if time.monotonic() > deadline:
                raise DeviceTimeout("acquisition", "the first merged samples (encoder + torque "
                                    "stream) within 2 s of the start", "none")
            self._wake.wait(0.01)

    # ------------------------------------------------------------------ step helpers

    def _check_stopping(self) -> None:
        if self._stopping is not None:
            raise EngineStopped(self._stopping)

    def _sleep_until(self, t_mono: float) -> None:
        while True:
            self._check_stopping()
            left = t_mono - time.monotonic()
            if left <= 0:
                return
            self._wake.wait(min(left, 0.05))
            self._wake.clear()

    def _command(self, torque_Nm: float) -> None:
        value = check_command(torque_Nm, self.torque_limit_Nm)
        with self._cmd_lock:
            self._check_stopping()
            self.io.set_torque(value)
            self._setpoint = value
            self._note_control()
            if value != 0.0:
                self._moved = True

    def _recent_rows(self, window_s: float) -> list[MergedRow]:
        with self._lock:
            if not self._recent:
                return []
            t_end = self._recent[-1].t_mono_s
            return [r for r in self._recent if r.t_mono_s >= t_end - window_s]

    def _latest_angle_deg(self) -> float:
        rows = self._recent_rows(0.02)
        if not rows:
            raise DeviceTimeout("acquisition", "a recent output encoder sample", "none")
        return float(np.mean([r.output_angle_deg for r in rows]))

    # ------------------------------------------------------------------ steps

    def _execute(self, step: Step) -> None:
        match step:
            case Ramp():
                self._ramp(step.target_Nm, step.rate_Nm_per_s, step.update_s)
            case Settle():
                self._settle(step)
            case Dwell(seconds=s):
                self._sleep_until(time.monotonic() + s)
            case Sample(window_s=w):
                self._sample_window = 1
                self._note_control()
                try:
                    self._sleep_until(time.monotonic() + w)
                finally:
                    self._sample_window = 0
                    self._note_control()
            case StepTwist():
                self._step_twist(step)
            case ReadTorqueZero():
                self._torque_zero(step)
            case Checkpoint():
                self._checkpoint(step)
            case BeginRun():
                self._begin_run(step)
            case EndRun():
                self._end_run()
            case LockInput():
                self._lock_input(step)
            case TurnInput():
                self._turn_input(step)
            case SetAmbient(temperature_C=c):
                self.io.set_ambient(c)
            case WaitTemperature():
                self._wait_temperature(step)
            case _:
                raise TypeError(f"the engine cannot execute {step!r}")

    def _ramp(self, target: float, rate: float | None, update_s: float) -> None:
        start = self._setpoint
        if rate is None or start == target:
            self._command(target)
            return
        duration = abs(target - start) / rate
        n = max(1, math.ceil(duration / update_s))
        t0 = time.monotonic()
        for k in range(1, n + 1):
            self._sleep_until(t0 + duration * k / n)
            self._command(start + (target - start) * k / n if k < n else target)

    def _settle(self, step: Settle) -> bool:
        """Wait for the twist rate to fall below the threshold; False on timeout (noted)."""
        t0 = time.monotonic()
        min_wait = max(step.min_s, step.hold_s)
        while True:
            self._sleep_until(time.monotonic() + 0.02)
            elapsed = time.monotonic() - t0
            if elapsed >= min_wait:
                rows = self._recent_rows(step.hold_s)
                if len(rows) >= 3:
                    t = np.array([r.t_mono_s for r in rows])
                    a = np.array([r.output_angle_deg for r in rows]) * ARCMIN_PER_DEG
                    slope = abs(float(np.polyfit(t - t[0], a, 1)[0]))
                    if slope < step.max_rate_arcmin_per_s:
                        return True
            if elapsed >= step.timeout_s:
                if self._open is not None:
                    self._open.note(f"settle timed out after {step.timeout_s:g} s at "
                                    f"{self._setpoint:+.4g} N*m")
                return False

    def _step_twist(self, step: StepTwist) -> None:
        direction = 1.0 if step.limit_Nm > self._setpoint else -1.0
        while self._setpoint != step.limit_Nm:
            ref = self._latest_angle_deg()
            next_t = time.monotonic()
            target = self._setpoint
            while True:
                next_t += step.update_s
                self._sleep_until(next_t)
                slow = step.zero_rate_Nm_per_s is not None and abs(target) < step.zero_band_Nm
                rate = step.zero_rate_Nm_per_s if slow else step.rate_Nm_per_s
                target += direction * rate * step.update_s
                if direction * (target - step.limit_Nm) >= 0:
                    self._command(step.limit_Nm)
                    break
                self._command(target)
                moved = direction * (self._latest_angle_deg() - ref) * ARCMIN_PER_DEG
                if moved >= step.delta_arcmin:
                    break
            self._settle(step.settle)
            if step.dwell_s > 0:
                self._sleep_until(time.monotonic() + step.dwell_s)
            if step.sample_s > 0:
                self._execute(Sample(step.sample_s))

    def _torque_zero(self, step: ReadTorqueZero) -> None:
        """Ramp to zero and average the torque; a run open now stops recording (its loop
        is over: the run then ends where it began, as the loop analysis expects)."""
        self._stop_recording()
        self._ramp(0.0, step.rate_Nm_per_s, 0.02)
        self._sleep_until(time.monotonic() + step.settle_s)
        t0 = time.monotonic()
        t_end = t0 + step.window_s
        self._sleep_until(t_end)
        # The window's rows may reach us late when the PC is busy (the receiving thread
        # waits for the CPU; a loaded CI machine had them 0.5-2 s behind): wait for them
        # while rows still come (the stale-sample trip's tolerance since the last one), at
        # most ZERO_WAIT_MAX_S.
        stale_s = self.options.stale_timeout_s
        deadline = t_end + max(stale_s, ZERO_WAIT_MAX_S)
        while True:
            rows = [r for r in self._recent_rows(step.window_s + deadline - t0)
                    if r.t_mono_s >= t0]
            now = time.monotonic()
            if (rows and rows[-1].t_mono_s >= t_end) or now >= deadline or (
                    now >= t_end + stale_s and now - self._last_row_mono > stale_s):
                break
            self._sleep_until(min(deadline, now + 0.01))
        # at zero command the torque is steady: rows stamped just after the window (late
        # delivery) are as good as the window's own
        rows = [r for r in rows if r.t_mono_s <= t_end] or rows
        if not rows:
            raise DeviceTimeout("acquisition", f"torque samples over {step.window_s:g} s "
                                "for the torque zero", "none")
        zero = float(np.mean([r.torque_Nm for r in rows]))
        if step.when == "before" and self._open is None:
            self._zero_before = zero
        elif self._open is not None:
            self._open.torque_zero[step.when] = zero

    def _checkpoint(self, step: Checkpoint) -> None:
        if not self._pause_requested:
            return
        self.state = "paused"
        self._publish("paused", message=f"paused at {step.label}")
        if self._open is not None:
            self._open.note(f"paused at {step.label}")
        while self._pause_requested:
            self._check_stopping()
            self._resume.wait(0.05)
        self._check_stopping()
        self.state = "running"
        self._publish("resumed", message=f"resumed at {step.label}")

    def _lock_input(self, step: LockInput) -> None:
        self._ramp(0.0, None, 0.02)
        self._sleep_until(time.monotonic() + 0.05)
        self.io.lock_input(step.angle_deg, step.timeout_s)
        self._check_stopping()

    def _turn_input(self, step: TurnInput) -> None:
        """One direction of a transmission error run (see :class:`TurnInput`): brake torque,
        turn, record from the end of the lead-in for the output revolutions, stop. Raises a
        DeviceFault on a stall, a frozen output encoder, an overspeed or a count jump (the
        engine then trips: zero torque, input stopped, the run kept and aborted)."""
        self._ramp(step.brake_command_Nm, step.brake_rate_Nm_per_s, 0.02)
        rows = self._recent_rows(0.1)
        if not rows:
            raise DeviceTimeout("acquisition", "recent encoder samples before turning", "none")
        last = rows[-1]
        in_start = last.input_angle_deg
        in_rate = 6.0 * step.speed_rpm * step.direction  # deg/s, signed
        out_rate = in_rate / step.ratio
        lead_in = step.lead_in_output_deg * abs(step.ratio)  # deg of input
        # deg of output, and a margin: the rows merged before the direction was set (at
        # most a check period and a poll late) are not marked; the recorded span stays >= goal
        goal = 360.0 * step.output_revolutions + abs(out_rate) * 0.1 + 0.5
        t_start = time.monotonic()
        deadline = t_start + step.timeout_factor * step.expected_s + 2.0
        spin_up_until = last.t_mono_s + 0.3
        out_begin: float | None = None
        window: deque[MergedRow] = deque()
        with self._cmd_lock:
            self._check_stopping()
            self.io.turn_input(step.direction * step.speed_rpm)
        try:
            while True:
                self._sleep_until(time.monotonic() + 0.02)
                new = [r for r in self._recent_rows(1.0) if r.t_mono_s > last.t_mono_s]
                for row in new:
                    self._check_jump(last, row, in_rate, out_rate, step)
                    last = row
                    window.append(row)
                    while window and window[0].t_mono_s < row.t_mono_s - step.stall_s:
                        window.popleft()
                if new and new[-1].t_mono_s > spin_up_until + step.stall_s:
                    self._check_speed(window, in_rate, out_rate, step)
                if out_begin is None and abs(last.input_angle_deg - in_start) >= lead_in:
                    out_begin = last.output_angle_deg
                    self._direction = step.direction
                    self._note_control()
                if out_begin is not None and abs(last.output_angle_deg - out_begin) >= goal:
                    break
                if time.monotonic() > deadline:
                    raise DeviceTimeout(
                        "input motor", f"{step.output_revolutions:g} output revolutions "
                        f"within {deadline - t_start:.1f} s",
                        f"{abs(last.output_angle_deg - (out_begin or 0.0)) / 360.0:.3f}")
        finally:
            self._direction = 0
            self._note_control()
        with self._cmd_lock:
            self._check_stopping()
            self.io.stop_input()
        self._sleep_until(time.monotonic() + 0.2)

    @staticmethod
    def _check_jump(prev: MergedRow, row: MergedRow, in_rate: float, out_rate: float,
                    step: TurnInput) -> None:
        """A count jump of either encoder between two rows: the transmission error
        ``output - input / ratio`` changing by more than ``jump_tolerance_deg`` (output deg)
        from one sample to the next (the unit's TE changes by arcsec per sample; a jump of
        either encoder is the whole jump). The encoder named is the one whose change is
        further from the motion expected at the set speed."""
        dt = row.t_mono_s - prev.t_mono_s
        if dt < JUMP_MIN_DT_S:  # two samples given (nearly) one SYNC's time: not judged
            return
        d_out = row.output_angle_deg - prev.output_angle_deg
        d_in = row.input_angle_deg - prev.input_angle_deg
        d_te = d_out - d_in / step.ratio
        # the tolerance, plus 1.5 samples of output motion: a sample the PC paired with its
        # neighbour's SYNC (a loaded PC) is not a jump; across a gap in the rows (left out,
        # or a stalled PC) the unit's own TE may have moved: only a gross change counts
        tolerance = step.jump_tolerance_deg + 1.5 * abs(out_rate) * min(dt, JUMP_GAP_S)
        if dt > JUMP_GAP_S:
            tolerance += JUMP_GAP_TOLERANCE_DEG
        if not abs(d_te) > tolerance:
            return
        off_out = abs(d_out - out_rate * dt)
        off_in = abs(d_in - in_rate * dt) / abs(step.ratio)
        name, change = (("output encoder", d_out) if off_out >= off_in
                        else ("input encoder", d_in))
        raise DeviceFault(name, f"the output to follow the input within "
                          f"{tolerance:.3g} deg between two samples "
                          f"{dt * 1000:.1f} ms apart", f"a change of {d_te:+.4g} deg of the "
                          f"transmission error ({name} {change:+.4g} deg): an encoder count "
                          "jump")

    @staticmethod
    def _check_speed(window: deque[MergedRow], in_rate: float, out_rate: float,
                     step: TurnInput) -> None:
        """Stall (the input, or the output encoder frozen) or overspeed over the window."""
        first, last = window[0], window[-1]
        span = last.t_mono_s - first.t_mono_s
        if span < 0.5 * step.stall_s:
            return
        moved_in = abs(last.input_angle_deg - first.input_angle_deg)
        moved_out = abs(last.output_angle_deg - first.output_angle_deg)
        want_in, want_out = abs(in_rate) * span, abs(out_rate) * span
        rpm = moved_in / span / 6.0
        if len(window) >= 5:  # the least-squares speed: one misplaced time does not count
            t = np.array([r.t_mono_s for r in window])
            a = np.array([r.input_angle_deg for r in window])
            rpm = abs(float(np.polyfit(t - t[0], a, 1)[0])) / 6.0
        if moved_in < step.stall_share * want_in:
            raise DeviceFault("input motor", f"the input turning at {step.speed_rpm:g} rpm",
                              f"{rpm:.3g} rpm over {span:.2f} s (input encoder): a stall")
        if moved_out < step.stall_share * want_out:
            raise DeviceFault("output encoder", f"the output turning at "
                              f"{step.speed_rpm / abs(step.ratio):.3g} rpm",
                              f"{moved_out / span / 6.0:.3g} rpm over {span:.2f} s while the "
                              "input turns: a frozen output encoder or a broken unit")
        if rpm > step.overspeed_factor * step.speed_rpm:
            raise DeviceFault("input motor", f"at most {step.overspeed_factor:g} x "
                              f"{step.speed_rpm:g} rpm", f"{rpm:.4g} rpm over {span:.2f} s "
                              "(input encoder): an overspeed")

    def _wait_temperature(self, step: WaitTemperature) -> None:
        deadline = time.monotonic() + step.timeout_s
        while True:
            temp = self._temperature
            if temp is not None and abs(temp - step.temperature_C) <= step.tolerance_C:
                return
            if time.monotonic() > deadline:
                raise DeviceTimeout("climate chamber", f"housing at {step.temperature_C:g} +- "
                                    f"{step.tolerance_C:g} C within {step.timeout_s:g} s",
                                    f"{temp} C")
            self._sleep_until(time.monotonic() + 0.1)

    def _begin_run(self, step: BeginRun) -> None:
        if self._open is not None:
            raise RigError(f"plan error: run {step.label} begun inside run {self._open.label}")
        test = dict(step.test)
        label = step.label
        if step.label_from_input:
            angle = self._measured_input_angle()
            if angle is not None:
                test["input_angle_deg"] = angle
                label = relabel_position(label, angle)
        while True:
            try:
                open_run = self._open_run(step, label, dict(test), t0=None)
                break
            except StoreUnavailable as exc:
                message = (f"store: PostgreSQL unreachable ({str(exc).split(': ', 1)[-1]}); "
                           f"run {label} not begun, the campaign waits for it")
                log.warning("%s", message)
                self._wait_for_store(message, run_id=None)
        self._dropped_at_begin = self._dropped_total()
        with self._lock:
            self._open = open_run
            self._unrecorded.clear()
        self._zero_before = None
        self._publish("run_started",
                      message=f"run {step.label} ({open_run.recorder.run_id}) started")

    def _open_run(self, step: BeginRun, label: str, test: dict[str, Any],
                  t0: float | None) -> OpenRun:
        """Begin ``step``'s run in the store (run.json, samples.csv, index, audit) and arm
        its watches; ``t0``: the monotonic time of t_s = 0 (None: now)."""
        if self._zero_before is not None:
            test["torque_zero_before_Nm"] = self._zero_before
        if self._temperature is not None:
            test.setdefault("temperature_C", self._temperature)
        meta = {**self.meta, **self.options.extra_meta, "label": label, "test": test,
                "sensors": self.io.sensors_meta(),
                "plan": self._plan.meta() if self._plan else {"name": "ad hoc"},
                "acquisition": acquisition_meta(self.io),
                "limits": limits_dict(self.options.limits)}
        if self.options.run_meta is not None:
            try:
                meta.update(self.options.run_meta(dict(test)))
            except Exception as exc:  # the truth is a record, never a reason to stop a run
                log.warning("run meta of %s not recorded: %s", label, exc)
        columns = ["t_s", "torque_Nm", "output_angle_deg"]
        if self.io.has_input_encoder:
            columns.append("input_angle_deg")
        if self.io.has_climate:
            columns.append("temperature_C")
        columns += ["torque_command_Nm", "step", "sample_window"]
        if test.get("kind") == TE_KIND:
            columns.append("direction")
        recorder = self.store.begin_run(meta, columns, campaign_id=self.campaign_id)
        open_run = OpenRun(recorder, label, time.monotonic() if t0 is None else t0,
                           profile=self.options.profile,
                           limits=limits_dict(self.options.limits))
        self._dropped_at_begin = self._dropped_total()
        # a transmission error run turns the output under a constant torque: its own watches
        # (TurnInput: stall, frozen output, overspeed, count jumps) replace the frozen twist's
        self._frozen = None if test.get("kind") == TE_KIND else frozen_watch(meta, test,
                                                                             open_run.t0)
        share, rated = self.options.crosscheck_limit_share, test.get("rated_torque_Nm")
        self._cross_limit_Nm = (share * float(rated) if share is not None
                                and isinstance(rated, int | float) and rated > 0 else None)
        return open_run

    def _measured_input_angle(self) -> float | None:
        """The input angle now (deg, modulo 360, 0.01 deg), from the input encoder's merged
        rows; None without an input encoder."""
        if not self.io.has_input_encoder:
            return None
        values = [r.input_angle_deg for r in self._recent_rows(0.2)
                  if math.isfinite(r.input_angle_deg)]
        if not values:
            return None
        return round(float(np.median(values)) % 360.0, 2) % 360.0

    def _dropped_total(self) -> int:
        """Encoder samples lost so far: full driver queues plus merge drops (count)."""
        counter = getattr(self.io, "samples_dropped", None)
        return ((0 if counter is None else int(counter())) + self._merger.dropped_before_torque
                + self._merger.unpaired)

    def _stop_recording(self) -> None:
        """Wait until the rows up to now are in the open run, then stop appending rows."""
        open_run = self._open
        if open_run is None or not open_run.recording:
            return
        t_end = time.monotonic()
        deadline = t_end + self.options.drain_timeout_s
        while open_run.last_t_mono < t_end and time.monotonic() < deadline:
            self._sleep_until(time.monotonic() + 0.005)
        with self._lock:
            open_run.recording = False

    def _end_run(self) -> None:
        open_run = self._open
        if open_run is None:
            raise RigError("plan error: end of a run that was not begun")
        self._stop_recording()
        with self._lock:
            self._open = None
            self._unrecorded.clear()
            self._moved = False  # this run is the record of the torque applied so far
        open_run.samples_dropped = self._dropped_total() - self._dropped_at_begin
        outcome = open_run.finish_completed()
        self.outcomes.append(outcome)
        self._publish("run_finished", message=f"run {open_run.label} completed",
                      data=outcome.to_dict(), run=open_run)
        if not getattr(open_run.recorder, "indexed", True):
            self._wait_for_store(
                f"store: PostgreSQL unreachable; run {outcome.run_id} kept locally, will be "
                "indexed when it returns (paused, drive disabled)", run_id=outcome.run_id)

    def _wait_for_store(self, message: str, run_id: str | None) -> None:
        """The store's database is away (issue 21 item 7): pause in the safe state (zero
        torque, drive disabled) instead of holding the drive or aborting, try the database
        every :data:`STORE_RETRY_PERIOD_S`, index the runs kept locally (``run_id`` among
        them) when it is back, then enable the drive again, bring back the torque the plan
        was holding (at the rate of its last ramp, then its last settle) and go on. An abort
        or E-stop meanwhile stops the plan as usual."""
        restore = self._setpoint
        with self._cmd_lock:
            self._check_stopping()
            self.io.safe_state()
            self._setpoint = 0.0
            self._note_control()
        self.state = "paused"
        self._publish("paused", message=message)
        while True:
            self._sleep_until(time.monotonic() + STORE_RETRY_PERIOD_S)
            if not self.store.reachable():
                continue
            self.store.index_pending()
            if run_id is None or run_id not in self.store.pending_runs():
                break
        with self._cmd_lock:
            self._check_stopping()
            self.io.set_torque(0.0)
            self.io.enable_drive()
        self.state = "running"
        self._publish("resumed", message="store reachable again: resumed"
                      + (f" (run {run_id} indexed)" if run_id else ""))
        if restore != 0.0:
            done = self._steps[:self._step_index]
            ramp = next((st for st in reversed(done) if isinstance(st, Ramp)
                         and st.rate_Nm_per_s is not None), None)
            self._ramp(restore, ramp.rate_Nm_per_s if ramp else 1.0, 0.02)
            settle = next((st for st in reversed(done) if isinstance(st, Settle)), None)
            if settle is not None:
                self._settle(settle)


def frozen_watch(meta: dict[str, Any], test: dict[str, Any], t0_mono_s: float = 0.0
                 ) -> FrozenTwistWatch | None:
    """The frozen-twist watch of a run (rig/engine/frozen.py), from its sensors, rated torque
    and the unit's nominal model; None when the run says too little to judge. ``t0_mono_s``:
    the run's start (s, monotonic clock), for the times in its message."""
    from rig.results.analyse import nominal_model_for_unit

    counts = (meta.get("sensors") or {}).get("encoder_counts_per_rev")
    rated = test.get("rated_torque_Nm")
    if not isinstance(counts, int | float) or not isinstance(rated, int | float) or \
            counts <= 0 or rated <= 0:
        return None
    model, _ = nominal_model_for_unit(meta.get("unit") or {}, float(rated))
    stiffness = getattr(model, "stiffness_Nm_per_arcmin", None)
    play = getattr(model, "play_arcmin", None)
    good = [v if isinstance(v, int | float) and math.isfinite(v) and v > 0 else None
            for v in (stiffness, play)]
    device = (meta.get("sensors") or {}).get("output_encoder") or "encoder"
    return FrozenTwistWatch(float(counts), float(rated), good[0], good[1], str(device),
                            t0_mono_s)


def limits_dict(limits: dict[str, Any] | None) -> dict[str, Any]:
    """Every limit key (rig/results/outcome.py), None where not checked."""
    return {key: (limits or {}).get(key) for key in LIMIT_KEYS}


def relabel_position(label: str, angle_deg: float) -> str:
    """``label`` with its ``posNNN`` part naming ``angle_deg`` (rounded to 0.1 deg)."""
    parts = label.split("-")
    for i, part in enumerate(parts):
        if part.startswith("pos"):
            value = round(angle_deg, 1)
            parts[i] = run_label(value if value != 360.0 else 0.0, 0, 0).split("-")[0]
            break
    return "-".join(parts)


def acquisition_meta(io: RigIO) -> dict[str, Any]:
    """How the channels of a run were aligned (kept in run.json ``acquisition``)."""
    return {
        "time_base": "t_s: host monotonic time since the run began",
        "master_clock": "output encoder (one row per position PDO)",
        "torque": "transducer stream, linearly interpolated at each encoder time",
        "input_angle_deg": "input encoder, interpolated (held when older)"
        if io.has_input_encoder else "not recorded",
        "temperature_C": "housing temperature, latest value (polled every ~1 s)"
        if io.has_climate else "not recorded",
        "torque_command_Nm": "setpoint in force when the row was measured",
        "step": "1-based index of the plan step being executed",
        "sample_window": "1 inside a Sample step (settled measurement point)",
        "cross_check": "Modbus torque sensor, polled, compared (result.crosscheck_max_diff_Nm)",
    }
