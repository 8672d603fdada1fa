"""Read every device of a rig for a while and report per device (``rig devices``).

Each device is read by its own thread for ``seconds`` (s), the way the engine reads it: the
encoders' SYNC-driven PDO queues, the transducer's stream, the torque sensor polled at
``rig.sample_rate_Hz``, the drive and the auxiliary units polled at 10 Hz. A device fault is
caught and counted for that device; it never stops the others.

Per device: ``samples``, ``rate_Hz`` (samples / s), ``expected_rate_Hz``, ``lost`` (samples
the device sent that did not come: stream sequence gaps; for the encoders SYNCs without a
PDO: SYNC stops at the end of the window and the PDOs still on their way are waited for,
but PDOs in flight when the window opens are counted, so a lag of n periods there can hide
up to n losses), ``late``
(intervals longer than 2.5 expected periods), ``last`` (the newest value and its unit) and
``errors`` (distinct messages, each with its count). A device is healthy when it opened,
gave samples and had no errors.
"""

from __future__ import annotations

import re
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

from drivers.errors import DeviceError, DeviceFault, DeviceTimeout
from rig.hardware.config import RigConfig
from rig.hardware.devices import RigDevices, open_rig

STATUS_POLL_HZ = 10.0
LATE_FACTOR = 2.5
MAX_DISTINCT_ERRORS = 5
TAIL_QUIET_S, TAIL_MAX_S = 0.3, 2.0
_NUMBER = re.compile(r"\d+(\.\d+)?")
_SYNC_LOCK = threading.Lock()


@dataclass
class DeviceReport:
    """What ``rig devices`` found for one device (rates in Hz, ``last`` in ``unit``)."""

    name: str
    device: str
    samples: int = 0
    rate_Hz: float = 0.0
    expected_rate_Hz: float | None = None
    lost: int = 0
    late: int = 0
    last: float | None = None
    unit: str = ""
    errors: dict[str, int] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)
    _shown: dict[str, str] = field(default_factory=dict, repr=False)

    @property
    def error_count(self) -> int:
        return sum(self.errors.values())

    @property
    def healthy(self) -> bool:
        return self.samples > 0 and not self.errors

    def note_error(self, exc: BaseException) -> None:
        """Count an error; messages that differ only in their numbers count as one (the
        first one is kept as it came)."""
        text = str(exc) if isinstance(exc, DeviceError) else f"{type(exc).__name__}: {exc}"
        key = _NUMBER.sub("#", text)
        shown = self._shown.get(key)
        if shown is None:
            if len(self.errors) >= MAX_DISTINCT_ERRORS:
                shown = "(more errors)"
            else:
                shown = self._shown[key] = text
        self.errors[shown] = self.errors.get(shown, 0) + 1

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        del out["_shown"]
        out["errors"] = [{"message": m, "count": n} for m, n in self.errors.items()]
        out["error_count"] = self.error_count
        out["healthy"] = self.healthy
        return out


class _Intervals:
    """Counts samples and intervals longer than LATE_FACTOR expected periods."""

    def __init__(self, report: DeviceReport, period_s: float | None) -> None:
        self.report = report
        self.period_s = period_s
        self.last_t: float | None = None

    def add(self, t_s: float, value: float) -> None:
        rep = self.report
        rep.samples += 1
        rep.last = value
        if self.last_t is not None and self.period_s and \
                t_s - self.last_t > LATE_FACTOR * self.period_s:
            rep.late += 1
        self.last_t = t_s


def _until(deadline: float, stop: threading.Event) -> bool:
    return time.monotonic() < deadline and not stop.is_set()


def _watch_encoder(devices: RigDevices, name: str, rep: DeviceReport, deadline: float,
                   stop: threading.Event) -> None:
    enc = devices.get(name)
    period = enc.period_s
    rep.expected_rate_Hz = None if period is None else 1.0 / period
    rep.unit = "deg"
    counter = _Intervals(rep, period)
    network = devices.network
    try:
        enc.readings()  # drop what queued before the window
    except DeviceError as exc:
        rep.note_error(exc)
    syncs0, t0 = network.syncs_sent, time.monotonic()
    while _until(deadline, stop):
        try:
            for r in enc.readings():
                counter.add(r.t_s, r.angle_deg)
        except DeviceError as exc:
            rep.note_error(exc)
            time.sleep(0.05)
        time.sleep(0.01)
    with _SYNC_LOCK:  # no more SYNCs: every PDO still on its way answers a counted one
        network.stop_sync()
    syncs1, t1 = network.syncs_sent, time.monotonic()
    _drain_tail(enc, counter, rep)
    if enc.config.transmission == "sync" and network.config.sync_period_s is not None:
        expected = (syncs1 - syncs0) // enc.config.sync_every
    else:
        expected = int((t1 - t0) / period) if period else rep.samples
    rep.lost = max(0, expected - rep.samples)
    health = enc.health()
    rep.info = {"nmt_state": health.nmt_state, "protocol_errors": health.protocol_errors}


def _drain_tail(enc: Any, counter: _Intervals, rep: DeviceReport) -> None:
    """Take the PDOs still in flight after SYNC stopped (until none for TAIL_QUIET_S)."""
    end = time.monotonic() + TAIL_MAX_S
    quiet_since = time.monotonic()
    while time.monotonic() < end and time.monotonic() - quiet_since < TAIL_QUIET_S:
        try:
            batch = enc.readings()
        except DeviceTimeout:
            batch = []  # expected: SYNC has stopped, so PDOs do too
        except DeviceError as exc:
            rep.note_error(exc)
            return
        for r in batch:
            counter.add(r.t_s, r.angle_deg)
        if batch:
            quiet_since = time.monotonic()
        time.sleep(0.01)


def _watch_transducer(devices: RigDevices, rep: DeviceReport, deadline: float,
                      stop: threading.Event) -> None:
    tt = devices.transducer
    rate = tt.config.stream_rate_Hz
    rep.expected_rate_Hz, rep.unit = rate, "N*m"
    counter = _Intervals(rep, 1.0 / rate)
    try:
        tt.start_stream(rate)
    except DeviceError as exc:
        rep.note_error(exc)
        return
    while _until(deadline, stop):
        try:
            r = tt.next_reading()
            counter.add(r.t_s, r.torque_Nm)
        except DeviceError as exc:
            rep.note_error(exc)
            time.sleep(0.05)
    try:
        tt.stop_stream()
        while True:  # samples that came before the device's OK to STOP
            r = tt.next_reading()
            counter.add(r.t_s, r.torque_Nm)
    except RuntimeError:
        pass  # no stream and nothing pending: done
    except DeviceError as exc:
        rep.note_error(exc)
    stats = tt.stats
    rep.lost = stats.lost
    rep.info = {"bad_lines": stats.bad_lines}
    try:
        rep.info["temperature_C"] = tt.temperature_C()
    except DeviceError as exc:
        rep.note_error(exc)


def _poll(read: Callable[[], tuple[float, float]], rep: DeviceReport, rate_Hz: float,
          deadline: float, stop: threading.Event) -> None:
    period = 1.0 / rate_Hz
    rep.expected_rate_Hz = rate_Hz
    counter = _Intervals(rep, period)
    next_t = time.monotonic()
    while _until(deadline, stop):
        try:
            t_s, value = read()
            counter.add(t_s, value)
        except DeviceError as exc:
            rep.note_error(exc)
        next_t += period
        pause = next_t - time.monotonic()
        if pause > 0:
            stop.wait(pause)
        else:
            next_t = time.monotonic()


def _drive_reading(devices: RigDevices, rep: DeviceReport) -> Callable[[], tuple[float, float]]:
    def read() -> tuple[float, float]:
        st = devices.drive.status()
        rep.info = {"enabled": st.enabled, "fault_code": int(st.fault_code),
                    "torque_limit_Nm": devices.drive.torque_limit_Nm}
        if st.faulted:
            raise DeviceFault(devices.drive.name, "no latched fault",
                              f"fault code {int(st.fault_code)} {st.fault_code.name}")
        return st.t_s, st.actual_torque_Nm

    return read


def _motor_reading(devices: RigDevices, rep: DeviceReport) -> Callable[[], tuple[float, float]]:
    def read() -> tuple[float, float]:
        st = devices.input_motor.state()
        rep.info = {"locked": st.locked, "moving": st.moving}
        if st.fault:
            raise DeviceFault(devices.input_motor.name, "no fault", "status FAULT")
        return st.t_s, st.angle_deg

    return read


def _climate_reading(devices: RigDevices, rep: DeviceReport
                     ) -> Callable[[], tuple[float, float]]:
    def read() -> tuple[float, float]:
        st = devices.climate.state()
        rep.info = {"setpoint_C": st.setpoint_C}
        return st.t_s, st.housing_C

    return read


def _sensor_reading(devices: RigDevices) -> Callable[[], tuple[float, float]]:
    def read() -> tuple[float, float]:
        r = devices.torque_sensor.read()
        return r.t_s, r.torque_Nm

    return read


def _describe(devices: RigDevices, name: str) -> str:
    driver = getattr(devices, name)
    for attr in ("device", "name"):
        text = getattr(driver, attr, None)
        if isinstance(text, str):
            return text
    cfg = getattr(devices.config, name)
    where = cfg.where() if hasattr(cfg, "where") else getattr(cfg, "url", "")
    return f"{name.replace('_', ' ')} ({where})" if where else name


def check_devices(config: RigConfig, seconds: float,
                  progress: Callable[[float], None] | None = None) -> list[DeviceReport]:
    """Open the rig (faults tolerated), read every device for ``seconds`` (s), report."""
    if not seconds > 0:
        raise ValueError(f"seconds must be > 0, got {seconds!r}")
    reports = {n: DeviceReport(n, n) for n in config.device_names()}
    stop = threading.Event()
    with open_rig(config, tolerate_faults=True) as devices:
        for name, rep in reports.items():
            rep.device = _describe(devices, name)
            if name in devices.open_errors:
                rep.errors[f"did not open: {devices.open_errors[name]}"] = 1
        deadline = time.monotonic() + seconds
        jobs: dict[str, Callable[[], None]] = {}
        for name in ("encoder", "input_encoder"):
            if getattr(devices, name) is not None:
                jobs[name] = lambda n=name: _watch_encoder(devices, n, reports[n], deadline,
                                                           stop)
        if devices.transducer is not None:
            jobs["transducer"] = lambda: _watch_transducer(devices, reports["transducer"],
                                                           deadline, stop)
        polled = {
            "torque_sensor": (lambda: _sensor_reading(devices), config.rig.sample_rate_Hz,
                              "N*m"),
            "drive": (lambda: _drive_reading(devices, reports["drive"]), STATUS_POLL_HZ, "N*m"),
            "input_motor": (lambda: _motor_reading(devices, reports["input_motor"]),
                            STATUS_POLL_HZ, "deg"),
            "climate": (lambda: _climate_reading(devices, reports["climate"]),
                        STATUS_POLL_HZ, "degC"),
        }
        for name, (make, rate, unit) in polled.items():
            if getattr(devices, name) is not None:
                reports[name].unit = unit
                jobs[name] = lambda m=make, r=rate, n=name: _poll(m(), reports[n], r,
                                                                  deadline, stop)
        threads = [threading.Thread(target=_run_job, args=(job, reports[n]),
                                    name=f"rig devices {n}", daemon=True)
                   for n, job in jobs.items()]
        for thread in threads:
            thread.start()
        t0 = time.monotonic()
        while any(t.is_alive() for t in threads):
            devices.alive()
            if progress is not None:
                progress(min(seconds, time.monotonic() - t0))
            time.sleep(0.05)
    for rep in reports.values():
        rep.rate_Hz = rep.samples / seconds
        if rep.samples == 0 and not rep.errors:
            rep.errors["no samples"] = 1
    return list(reports.values())


def _run_job(job: Callable[[], None], rep: DeviceReport) -> None:
    try:
        job()
    except Exception as exc:  # one device's surprise must not stop the others
        rep.note_error(exc)
