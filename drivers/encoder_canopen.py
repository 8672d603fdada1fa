"""Absolute rotary encoders on CANopen (CiA 406), on python-can + canopen.

Any python-can interface works by configuration (``socketcan``, ``slcan``, ``pcan``,
``virtual``, ...). Several encoders (output and input shaft) can share one
:class:`EncoderNetwork`, which owns the bus, the canopen ``Network`` and the SYNC producer.

Per encoder (:class:`CanopenEncoder`): the EDS is loaded (the shipped minimal CiA 406 one
or a vendor's), the device type (0x1000, profile 406 = 0x0196 in the low word), identity
(0x1018), resolution (0x6001, counts per revolution) and total range (0x6002) are read by
SDO, TPDO1 is configured to carry the position value 0x6004 on every n-th SYNC or on an
event timer, the heartbeat producer (0x1017) is set, and NMT starts the node. Every TPDO is
kept (a queue, no sample dropped unless the queue overflows, counted) and converted to
``angle_deg = (unwrapped_counts - zero_counts) / counts_per_rev * 360`` (deg).

Faults, each raised as a :mod:`drivers.errors` error that names the encoder:

- heartbeat missing for ``heartbeat_timeout_periods`` (default 2.5) producer periods, or
  the serial/TCP link gone: :class:`DeviceDisconnected`. While position PDOs still come,
  the heartbeat's absence is judged on the node's own time they span (PDOs since the last
  heartbeat x period): heartbeats and PDOs reach the program through one queue, and a PC
  that reads it late (a loaded CI machine, 0.5-2 s behind) delays both alike, which spread
  the heartbeats' arrivals 1.5 s apart from a healthy node;
- no position PDO for ``missed_periods`` SYNC/event periods: :class:`DeviceTimeout`;
- a garbled frame or a TPDO of the wrong length: :class:`DeviceProtocolError` (once);
- an EMCY, a node that left OPERATIONAL, an SDO abort: :class:`DeviceFault`;
- a position that has not changed for ``stuck_after_s`` (if set): :class:`DeviceFault`.
"""

from __future__ import annotations

import collections
import contextlib
import threading
import time
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, TypeVar

import can
import canopen
import serial
from canopen.emcy import EmcyError
from canopen.nmt import NMT_STATES
from canopen.sdo import SdoAbortedError, SdoCommunicationError
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from drivers.canbus.slcan_port import read_in_chunks
from drivers.errors import (
    DeviceDisconnected,
    DeviceError,
    DeviceFault,
    DeviceProtocolError,
    DeviceTimeout,
)
from drivers.lifecycle import StartedOnEnter

DEFAULT_EDS = Path(__file__).resolve().parent / "cia406_encoder.eds"
CIA406_PROFILE = 0x0196
POSITION_INDEX = 0x6004
SYNC_COB_ID = 0x80
T = TypeVar("T")


class CanBusConfig(BaseModel):
    """The CAN network: python-can interface and channel, bitrate (bit/s), SYNC period (s).

    ``sync_period_s`` makes this network the SYNC producer (None: SYNC comes from elsewhere,
    or no encoder uses it). ``bus_options`` are passed to ``can.Bus`` as they are (e.g.
    ``{"sleep_after_open": 0}`` for slcan).
    """

    model_config = ConfigDict(extra="forbid")

    interface: str = "virtual"
    channel: str = "rig-encoders"
    bitrate: int = Field(500_000, gt=0)
    sync_period_s: float | None = Field(0.001, gt=0, le=60.0)
    bus_options: dict[str, Any] = Field(default_factory=dict)


class EncoderConfig(BaseModel):
    """One CiA 406 encoder on the network (periods in s, heartbeat in ms, angles in deg)."""

    model_config = ConfigDict(extra="forbid")

    name: str = "output encoder"
    node_id: int = Field(1, ge=1, le=127)
    eds: Path = DEFAULT_EDS
    transmission: Literal["sync", "cyclic"] = "sync"
    sync_every: int = Field(1, ge=1, le=240, description="TPDO on every n-th SYNC")
    cyclic_period_s: float = Field(0.001, ge=0.001, le=65.535, description="event timer")
    heartbeat_ms: int = Field(100, ge=0, le=65535, description="0: no heartbeat check")
    heartbeat_timeout_periods: float = Field(2.5, gt=1.0, le=3.0)
    counts_per_rev: int | None = Field(None, gt=0, description="expected 0x6001")
    timeout_s: float = Field(1.0, gt=0, description="SDO replies and the first sample")
    missed_periods: int = Field(100, ge=2, description="no PDO for this many periods: timeout")
    stuck_after_s: float | None = Field(None, gt=0, description="unchanged position: fault")
    configure_node: bool = Field(True, description="write TPDO1 and 0x1017 by SDO at start")
    queue_size: int = Field(2_000_000, ge=1)
    bus: CanBusConfig = Field(default_factory=CanBusConfig)


def encoder_config_from_toml(path: str | Path, table: str = "encoder") -> EncoderConfig:
    """Read ``[table]`` of a TOML file; errors name the file and the key."""
    path = Path(path)
    try:
        with path.open("rb") as fh:
            data = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: {exc}") from exc
    node: Any = data
    for key in table.split("."):
        if not isinstance(node, dict) or key not in node:
            raise ValueError(f"{path}: no table [{table}]")
        node = node[key]
    try:
        return EncoderConfig.model_validate(node)
    except ValidationError as exc:
        problems = "; ".join(
            f"{table}.{'.'.join(str(p) for p in err['loc'])}: {err['msg']}" for err in exc.errors()
        )
        raise ValueError(f"{path}: {problems}") from exc


@dataclass(frozen=True)
class EncoderReading:
    """One position sample: receive time ``t_s`` (s, python-can's time.time() scale),
    ``angle_deg`` (unwrapped, minus the zero), raw position value ``counts`` (0x6004) and
    ``seq`` (0, 1, 2, ... per received PDO of this encoder)."""

    t_s: float
    angle_deg: float
    counts: int
    seq: int


@dataclass(frozen=True)
class EncoderIdentity:
    """Identity object 0x1018, device type 0x1000, name 0x1008 and the resolution."""

    vendor_id: int
    product_code: int
    revision: int
    serial_number: int
    device_type: int
    device_name: str | None
    counts_per_rev: int
    total_range: int


@dataclass(frozen=True)
class EncoderErrors:
    """Error register 0x1001, pre-defined error field 0x1003 (newest first) and EMCYs."""

    error_register: int
    error_codes: tuple[int, ...]
    active_emergencies: tuple[str, ...]


@dataclass(frozen=True)
class EncoderHealth:
    """What the driver knows of the link and the samples (ages in s, None: never seen)."""

    state: str
    ok: bool
    nmt_state: str
    samples: int
    sample_age_s: float | None
    heartbeat_age_s: float | None
    unchanged_s: float | None
    protocol_errors: int
    dropped: int
    syncs_sent: int
    last_error: str | None


class _BusErrorListener(can.Listener):
    """Sees the exceptions of the Notifier's receive thread (python-can's ``on_error``).

    A broken link (serial or TCP gone) is remembered as fatal; a garbled line (the slcan
    parser raising ValueError/IndexError) is counted and reception goes on.
    """

    def __init__(self, network: EncoderNetwork) -> None:
        self._network = network

    def on_message_received(self, msg: can.Message) -> None:
        return None

    def on_error(self, exc: Exception) -> None:
        notifier = self._network.canopen.notifier
        cause = exc.__cause__ if isinstance(exc, can.CanOperationError) else exc
        if isinstance(cause, UnicodeError):  # slcan: a non-ASCII byte on the line
            exc = cause
            # python-can 4.6.1 slcan keeps the undecodable bytes in its line buffer, so every
            # later line would fail too: drop that partial line (the only state it holds)
            buffer = getattr(self._network.canopen.bus, "_buffer", None)
            if isinstance(buffer, bytearray):
                buffer.clear()
        elif isinstance(exc, can.CanOperationError | OSError | serial.SerialException):
            self._network.link_error = exc
            time.sleep(0.05)  # the receive thread retries at once: back off while it is down
            return
        self._network.note_protocol_error(f"{type(exc).__name__}: {exc}")
        if notifier is not None:
            notifier.exception = None  # handled: canopen must not re-raise it on every send


class SyncProducer:
    """The SYNC producer (COB-ID 0x80, CiA 301): one SYNC every ``period_s`` on its own thread.

    Unlike python-can's cyclic task it never catches up: after the PC was busy (this thread
    got no CPU for several periods) it sends the next SYNC at once and goes on from there,
    leaving the missed ones out. A catch-up burst (python-can sends every missed message back
    to back) makes the encoders sample many times at one instant, faster than the bus carries
    their answers; PDOs are lost and the SYNC each answer belongs to is misjudged, so the
    output and input encoders' samples were paired wrongly or not at all (rows lost, false
    count jumps on a loaded PC). ``before_send()`` is called just before each SYNC (its time
    is logged then: an earlier bound of the instant the encoders sample); ``on_error(exc)``
    on a send error, returning False stops the producer."""

    def __init__(self, bus: can.BusABC, lock: threading.RLock | threading.Lock,
                 period_s: float, before_send: Callable[[], None],
                 on_error: Callable[[Exception], bool]) -> None:
        self.period_s = float(period_s)
        self.skipped = 0
        """SYNCs left out because this thread came too late for them (count)."""
        self._bus, self._lock = bus, lock
        self._before_send, self._on_error = before_send, on_error
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="can-sync", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        msg = can.Message(arbitration_id=SYNC_COB_ID, is_extended_id=False, data=b"")
        due = time.perf_counter()
        while not self._stop.is_set():
            try:
                self._before_send()
                with self._lock:
                    self._bus.send(msg)
            except Exception as exc:  # the link: its owner decides (on_error)
                if not self._on_error(exc):
                    return
            due += self.period_s
            now = time.perf_counter()
            if now - due > self.period_s:  # late by more than a period: no burst
                missed = int((now - due) / self.period_s)
                self.skipped += missed
                due += missed * self.period_s
            delay = due - time.perf_counter()
            if delay > 0:
                self._stop.wait(delay)

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=1.0)


class EncoderNetwork:
    """One CAN bus shared by N encoders: python-can bus, canopen ``Network``, SYNC producer."""

    def __init__(self, config: CanBusConfig | None = None) -> None:
        self.config = config or CanBusConfig()
        self.canopen = canopen.Network()
        self.canopen.NOTIFIER_CYCLE = 0.1  # receive thread wakes at least every 0.1 s
        self.canopen.listeners.append(_BusErrorListener(self))
        self.link_error: Exception | None = None
        self.syncs_sent = 0
        # (SYNC number, host time.monotonic() s just before it was sent): the moments the
        # encoders sampled, for stamping their PDOs (rig.engine.steady_clock.SyncClock)
        # (2048: 8 s at the simulated rig's 4 ms, 2 s at 1 ms; the engine copies it each poll)
        self.sync_log: collections.deque[tuple[int, float]] = collections.deque(maxlen=2048)
        self.protocol_error_count = 0
        self.last_protocol_error = ""
        self._sync_task: SyncProducer | None = None
        self._connected = False

    @property
    def description(self) -> str:
        return f"{self.config.interface} {self.config.channel}"

    def connect(self) -> None:
        """Open the bus (idempotent). Raises :class:`DeviceDisconnected` if it cannot."""
        if self._connected:
            return
        cfg = self.config
        try:
            self.canopen.connect(
                interface=cfg.interface, channel=cfg.channel, bitrate=cfg.bitrate,
                **cfg.bus_options,
            )
        except (can.CanError, OSError, ValueError) as exc:
            raise DeviceDisconnected(
                f"CAN bus {self.description}", "the bus to open", f"{type(exc).__name__}: {exc}"
            ) from exc
        if cfg.interface == "slcan":
            read_in_chunks(self.canopen.bus)
        self._connected = True

    def start_sync(self) -> None:
        """Start the SYNC producer (COB-ID 0x80) if configured and not yet running."""
        period = self.config.sync_period_s
        if period is None or self._sync_task is not None:
            return
        self._sync_task = SyncProducer(self.canopen.bus, self.canopen.send_lock, period,
                                       before_send=self._count_sync,
                                       on_error=self._on_sync_error)

    def stop_sync(self) -> None:
        if self._sync_task is not None:
            self._sync_task.stop()
            self._sync_task = None

    def _count_sync(self) -> None:
        self.syncs_sent += 1
        self.sync_log.append((self.syncs_sent, time.monotonic()))

    def _on_sync_error(self, exc: Exception) -> bool:
        self.link_error = exc
        return False  # stop the SYNC producer: the link is gone

    def note_protocol_error(self, text: str) -> None:
        """Count a garbled line seen by the receive thread (every encoder reports it once)."""
        self.last_protocol_error = text
        self.protocol_error_count += 1

    def close(self) -> None:
        """Stop SYNC and close the bus (idempotent, never raises for a dead link)."""
        self.stop_sync()
        if not self._connected:
            return
        self._connected = False
        try:
            self.canopen.disconnect()
        except Exception:  # the link may already be gone; closing must still succeed
            bus = self.canopen.bus
            self.canopen.bus = None
            if bus is not None:
                with contextlib.suppress(Exception):  # a dead port may refuse the close command
                    bus.shutdown()


class CanopenEncoder(StartedOnEnter):
    """A CiA 406 absolute encoder: ``start()``, ``read()``, ``readings()``, ``zero()``,
    ``health()``, ``identity()``, ``errors()``, ``close()``.

    Without ``network`` the encoder opens (and later closes) its own from ``config.bus``;
    pass a shared :class:`EncoderNetwork` for several encoders on one bus.
    """

    def __init__(self, config: EncoderConfig, network: EncoderNetwork | None = None) -> None:
        self.config = config
        self._own_network = network is None
        self.network = network or EncoderNetwork(config.bus)
        bus = self.network.config
        self.device = f"{config.name} (CANopen node {config.node_id} on {bus.interface} " \
            f"{bus.channel})"
        self._node: canopen.RemoteNode | None = None
        self._identity: EncoderIdentity | None = None
        self._cpr = 1
        self._range = 1 << 32
        self._pdo_bytes = 4
        self._position_var: Any = None
        self._queue: collections.deque[EncoderReading] = collections.deque(
            maxlen=config.queue_size
        )
        self._callbacks: list[Callable[[EncoderReading], None]] = []
        self._latest: EncoderReading | None = None
        self._first_sample = threading.Event()
        self._seq = -1
        self._last_counts: int | None = None
        self._unwrapped = 0
        self._zero_counts = 0
        self._sample_mono: float | None = None
        self._changed_mono: float | None = None
        self._heartbeat_mono: float | None = None
        self._heartbeat_state: int | None = None
        self._pdos_since_heartbeat = 0
        self._started_mono: float | None = None
        self._protocol_errors = 0
        self._protocol_reported = 0
        self._last_protocol_error = ""
        self._bus_reported = network.protocol_error_count if network is not None else 0
        self._dropped = 0
        self._closed = False
        self._started = False

    # -- lifecycle -------------------------------------------------------------------------
    @property
    def period_s(self) -> float | None:
        """The expected time between position PDOs (s), None if SYNC comes from elsewhere."""
        if self.config.transmission == "cyclic":
            return self.config.cyclic_period_s
        sync = self.network.config.sync_period_s
        return None if sync is None else sync * self.config.sync_every

    def start(self) -> EncoderIdentity:
        """Connect, check and configure the node, start it and wait for the first sample.

        On any error the driver is closed again and the error raised.
        """
        try:
            return self._start()
        except BaseException:
            self.close()
            raise

    def _start(self) -> EncoderIdentity:
        cfg = self.config
        self.network.connect()
        try:
            node = self.network.canopen.add_node(cfg.node_id, str(cfg.eds))
        except (OSError, KeyError, ValueError) as exc:
            raise ValueError(f"{cfg.eds}: cannot load EDS: {exc}") from exc
        self._node = node
        node.sdo.RESPONSE_TIMEOUT = cfg.timeout_s
        od = node.object_dictionary
        for index in (0x6001, POSITION_INDEX):
            if index not in od:
                raise ValueError(f"{cfg.eds}: a CiA 406 encoder EDS needs object 0x{index:04X}")
        node.nmt.add_heartbeat_callback(self._on_heartbeat)
        node.emcy.add_callback(self._on_emcy)
        self._identity = self._sdo("identity 0x1000/0x1018/0x6001", self._read_identity)
        if cfg.counts_per_rev is not None and cfg.counts_per_rev != self._cpr:
            raise DeviceProtocolError(
                self.device, f"{cfg.counts_per_rev} counts/rev (0x6001)", f"{self._cpr}"
            )
        if cfg.configure_node:
            node.nmt.state = "PRE-OPERATIONAL"
            self._sdo("TPDO1 configuration 0x1800/0x1A00", self._configure_tpdo)
            self._sdo("heartbeat time 0x1017", lambda: self._write(0x1017, cfg.heartbeat_ms))
        else:
            self._sdo("TPDO1 configuration 0x1800/0x1A00", node.tpdo[1].read)
        tpdo = node.tpdo[1]
        self._position_var = next((v for v in tpdo.map if v.index == POSITION_INDEX), None)
        if self._position_var is None:
            raise DeviceProtocolError(self.device, "0x6004 mapped in TPDO1", "another mapping")
        self._pdo_bytes = (tpdo.length + 7) // 8
        tpdo.add_callback(self._on_pdo)
        self._started_mono = time.monotonic()
        self._started = True
        self._closed = False
        self._sdo("NMT start", lambda: setattr(node.nmt, "state", "OPERATIONAL"))
        if cfg.transmission == "sync":
            self.network.start_sync()
        if not self._first_sample.wait(cfg.timeout_s + 10 * (self.period_s or 0.0)):
            self.check()
            raise DeviceTimeout(self.device, f"a position PDO within {cfg.timeout_s} s", "none")
        return self._identity

    def close(self) -> None:
        """Stop the node's PDOs (PRE-OPERATIONAL, best effort) and release the bus."""
        if self._closed:
            return
        self._closed = True
        node = self._node
        if node is not None and self.network.link_error is None and self._started:
            with contextlib.suppress(Exception):  # closing must succeed on a broken link
                node.nmt.state = "PRE-OPERATIONAL"
        if node is not None and node.id in self.network.canopen:
            del self.network.canopen[node.id]
        if self._own_network:
            self.network.close()

    # -- samples ---------------------------------------------------------------------------
    def read(self) -> EncoderReading:
        """The newest sample; raises the current fault (see :meth:`check`) instead."""
        self.check()
        if self._latest is None:
            raise DeviceTimeout(self.device, "a position PDO", "none yet")
        return self._latest

    @property
    def dropped(self) -> int:
        """Samples lost to a full queue since the driver opened (never reset)."""
        return self._dropped

    def readings(self, max_n: int | None = None) -> list[EncoderReading]:
        """Take every queued sample, oldest first (at most ``max_n``).

        Samples are never lost to a fault: the fault is raised only once the queue is empty.
        """
        out: list[EncoderReading] = []
        queue = self._queue
        while queue and (max_n is None or len(out) < max_n):
            out.append(queue.popleft())
        if not out:
            self.check()
        return out

    def add_callback(self, callback: Callable[[EncoderReading], None]) -> None:
        """Call ``callback(reading)`` for every sample, on the CAN receive thread."""
        self._callbacks.append(callback)

    def zero(self) -> float:
        """Make the current position read 0 deg from the next sample on (software zero).

        Returns the angle (deg) of the newest sample before the zero.
        """
        latest = self.read()
        self._zero_counts = self._unwrapped
        return latest.angle_deg

    def preset(self, counts: int) -> None:
        """Write the CiA 406 preset value 0x6003: the device then reports ``counts`` here."""
        node = self._require_node()
        if 0x6003 not in node.object_dictionary:
            raise DeviceProtocolError(self.device, "object 0x6003 (preset value)", "no 0x6003")
        self._sdo("preset value 0x6003", lambda: self._write(0x6003, int(counts)))

    # -- information -----------------------------------------------------------------------
    def identity(self) -> EncoderIdentity:
        if self._identity is None:
            self._require_node()
            self._identity = self._sdo("identity", self._read_identity)
        return self._identity

    def errors(self) -> EncoderErrors:
        """Read 0x1001 and (if the EDS has it) 0x1003 by SDO."""
        node = self._require_node()

        def read() -> EncoderErrors:
            register = int(node.sdo[0x1001].raw)
            codes: list[int] = []
            if 0x1003 in node.object_dictionary:
                field = node.sdo[0x1003]
                count = int(field[0].raw)
                codes = [int(field[i].raw) for i in range(1, count + 1) if i in field]
            active = tuple(str(e) for e in node.emcy.active)
            return EncoderErrors(register, tuple(codes), active)

        return self._sdo("error register 0x1001/0x1003", read)

    def health(self) -> EncoderHealth:
        """State of the link and samples, without raising or consuming a fault."""
        now = time.monotonic()
        fault = self._fault(consume=False)
        hb_state = self._heartbeat_state
        return EncoderHealth(
            state="ok" if fault is None else type(fault).__name__,
            ok=fault is None,
            nmt_state="UNKNOWN" if hb_state is None else NMT_STATES.get(hb_state, str(hb_state)),
            samples=self._seq + 1,
            sample_age_s=None if self._sample_mono is None else now - self._sample_mono,
            heartbeat_age_s=None if self._heartbeat_mono is None else now - self._heartbeat_mono,
            unchanged_s=None if self._changed_mono is None else now - self._changed_mono,
            protocol_errors=self._protocol_errors + self.network.protocol_error_count,
            dropped=self._dropped,
            syncs_sent=self.network.syncs_sent,
            last_error=None if fault is None else str(fault),
        )

    def check(self) -> None:
        """Raise the current fault, if any (order: link, heartbeat, NMT, EMCY, frames, age).

        A protocol error (garbled frame) is raised once; the others while they last.
        """
        fault = self._fault(consume=True)
        if fault is not None:
            raise fault

    def _fault(self, consume: bool) -> DeviceError | None:
        cfg = self.config
        if self._closed:
            return DeviceDisconnected(self.device, "an open driver", "closed")
        if not self._started:
            return DeviceDisconnected(self.device, "a started driver", "start() not called")
        now = time.monotonic()
        link = self.network.link_error
        if link is not None:
            return DeviceDisconnected(
                self.device, "an open CAN link", f"{type(link).__name__}: {link}"
            )
        if cfg.heartbeat_ms > 0:
            since = self._heartbeat_mono or self._started_mono or now
            limit = cfg.heartbeat_timeout_periods * cfg.heartbeat_ms / 1000.0
            late = now - since > limit
            period = self.period_s
            if late and period is not None and self._sample_mono is not None \
                    and now - self._sample_mono <= limit:
                late = self._pdos_since_heartbeat * period > limit  # PDOs still come
            if late:
                return DeviceDisconnected(
                    self.device,
                    f"a heartbeat every {cfg.heartbeat_ms} ms",
                    f"none for {now - since:.3f} s",
                )
        state = self._heartbeat_state
        if state is not None and state != 5:
            name = NMT_STATES.get(state, str(state))
            what = "a boot-up message (the node restarted)" if state == 0 else f"state {name}"
            return DeviceFault(self.device, "NMT state OPERATIONAL", what)
        node = self._node
        if node is not None and node.emcy.active:
            return DeviceFault(self.device, "no emergency", f"EMCY {node.emcy.active[-1]}")
        bus_errors = self.network.protocol_error_count
        if self._protocol_errors > self._protocol_reported or bus_errors > self._bus_reported:
            if bus_errors > self._bus_reported:
                got = f"garbled frame ({self.network.last_protocol_error})"
            else:
                got = self._last_protocol_error
            if consume:
                self._protocol_reported, self._bus_reported = self._protocol_errors, bus_errors
            return DeviceProtocolError(self.device, "well-formed position PDOs", got)
        period = self.period_s
        if period is not None and self._sample_mono is not None:
            age = now - self._sample_mono
            if age > cfg.missed_periods * period:
                return DeviceTimeout(
                    self.device,
                    f"a position PDO every {period * 1000:.3g} ms",
                    f"none for {age:.3f} s ({age / period:.0f} periods)",
                )
        if cfg.stuck_after_s is not None and self._changed_mono is not None:
            unchanged = now - self._changed_mono
            if unchanged > cfg.stuck_after_s:
                return DeviceFault(
                    self.device,
                    f"a changing position within {cfg.stuck_after_s} s",
                    f"{self._last_counts} counts for {unchanged:.2f} s",
                )
        return None

    # -- internals -------------------------------------------------------------------------
    def _require_node(self) -> canopen.RemoteNode:
        if self._node is None:
            raise DeviceDisconnected(self.device, "a started driver", "start() not called")
        return self._node

    def _write(self, index: int, value: int) -> None:
        self._require_node().sdo[index].raw = value

    def _sdo(self, what: str, action: Callable[[], T]) -> T:
        """Run SDO work and turn canopen/python-can errors into device errors."""
        try:
            return action()
        except SdoCommunicationError as exc:
            link = self.network.link_error
            if link is not None:
                raise DeviceDisconnected(self.device, f"SDO reply to {what}", f"{link}") from exc
            raise DeviceTimeout(self.device, f"SDO reply to {what}", f"{exc}") from exc
        except SdoAbortedError as exc:
            raise DeviceFault(self.device, f"SDO {what}", f"abort {exc}") from exc
        except (can.CanError, OSError, serial.SerialException) as exc:
            raise DeviceDisconnected(self.device, f"SDO {what}", f"{exc}") from exc
        except (ValueError, IndexError) as exc:  # a garbled line re-raised by canopen
            raise DeviceProtocolError(self.device, f"SDO {what}", f"{exc}") from exc

    def _read_identity(self) -> EncoderIdentity:
        node = self._require_node()
        od = node.object_dictionary
        device_type = int(node.sdo[0x1000].raw)
        if device_type & 0xFFFF != CIA406_PROFILE:
            raise DeviceProtocolError(
                self.device, "a CiA 406 encoder (0x1000 low word 0x0196)", f"0x{device_type:08X}"
            )
        ident = node.sdo[0x1018]
        values = [int(ident[i].raw) if i in od[0x1018] else 0 for i in (1, 2, 3, 4)]
        name = str(node.sdo[0x1008].raw) if 0x1008 in od else None
        self._cpr = int(node.sdo[0x6001].raw)
        if self._cpr <= 0:
            raise DeviceProtocolError(self.device, "0x6001 > 0 counts/rev", f"{self._cpr}")
        self._range = int(node.sdo[0x6002].raw) if 0x6002 in od else 1 << 32
        if self._range <= 0:
            self._range = 1 << 32
        return EncoderIdentity(*values, device_type, name, self._cpr, self._range)

    def _configure_tpdo(self) -> None:
        cfg = self.config
        tpdo = self._require_node().tpdo[1]
        tpdo.read()
        tpdo.clear()
        tpdo.add_variable(POSITION_INDEX)
        if cfg.transmission == "sync":
            tpdo.trans_type = cfg.sync_every
            tpdo.event_timer = None
        else:
            tpdo.trans_type = 254
            tpdo.event_timer = round(cfg.cyclic_period_s * 1000)
        tpdo.inhibit_time = None
        tpdo.enabled = True
        tpdo.save()

    def _on_heartbeat(self, state: int) -> None:
        self._heartbeat_mono = time.monotonic()
        self._pdos_since_heartbeat = 0
        if self._started:
            self._heartbeat_state = state

    def _on_emcy(self, entry: EmcyError) -> None:
        return None  # canopen keeps node.emcy.active; check() reports it

    def _on_pdo(self, pdo_map: Any) -> None:
        data = pdo_map.data
        if len(data) != self._pdo_bytes:
            self._last_protocol_error = (
                f"TPDO 0x{pdo_map.cob_id:03X} with {len(data)} bytes ({bytes(data).hex()}), "
                f"expected {self._pdo_bytes}"
            )
            self._protocol_errors += 1
            return
        counts = int(self._position_var.raw)
        now = time.monotonic()
        span = self._range
        if self._last_counts is None:
            self._unwrapped = counts if counts < span // 2 else counts - span
            self._changed_mono = now
        else:
            delta = (counts - self._last_counts) % span
            if delta > span // 2:
                delta -= span
            self._unwrapped += delta
            if delta:
                self._changed_mono = now
        self._last_counts = counts
        self._seq += 1
        self._pdos_since_heartbeat += 1
        angle = (self._unwrapped - self._zero_counts) / self._cpr * 360.0
        reading = EncoderReading(float(pdo_map.timestamp), angle, counts, self._seq)
        if len(self._queue) == self._queue.maxlen:
            self._dropped += 1
        self._queue.append(reading)
        self._latest = reading
        self._sample_mono = now
        self._first_sample.set()
        for callback in self._callbacks:
            callback(reading)
