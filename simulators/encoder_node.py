"""The output (or input) shaft encoder as a CiA 406 CANopen node, fed by the plant.

Three parts, kept apart as in lewis: the device model is the plant (``Plant.snapshot()``),
the protocol face is :class:`EncoderNode` (a ``canopen.LocalNode`` on a python-can bus) and
the fault injection is :class:`EncoderBackdoor` (``node.backdoor``).

The node serves the CiA 406 objects of ``drivers/cia406_encoder.eds`` (or any EDS with
0x6001 and 0x6004): NMT slave, heartbeat producer (0x1017), SDO server, EMCY, and TPDO1
with the position value 0x6004, sent on every n-th SYNC (transmission type 1..240) or
every event-timer period (types 254/255, 0x1800 sub 5 in ms). canopen's LocalNode does not
send TPDOs by itself, so this module does (the recipe in docs/library-notes.md).

Position value (CiA 406, 0x6004, counts): ``floor(angle_deg / 360 * cpr) + preset_offset``
modulo the total measuring range 0x6002, with ``cpr`` the measuring units per revolution
(0x6001). That floor is the encoder quantisation; the angle is the plant snapshot's
``output_angle_deg`` (or ``input_angle_deg`` for the input-shaft encoder), in deg.

``python -m simulators.encoder_node`` serves encoders behind a simulated SLCAN adapter and
prints ``{"encoder_slcan": "socket://127.0.0.1:PORT", ...}`` as JSON on its first line.
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import threading
import time
from pathlib import Path
from typing import Literal

import can
import canopen

from drivers.lifecycle import RunsWhileEntered
from simulators.canbus.virtual import virtual_bus
from simulators.clock import Clock, MonotonicClock
from simulators.plant.api import Plant, PlantSnapshot

DEFAULT_EDS = Path(__file__).resolve().parent.parent / "drivers" / "cia406_encoder.eds"
POSITION_INDEX = 0x6004
SYNC_COB_ID = 0x80
_TPDO_CONFIG_INDICES = (0x1800, 0x1A00, 0x6001, 0x6002)

Shaft = Literal["output", "input"]


class EncoderBackdoor:
    """Fault injection for one :class:`EncoderNode` (thread-safe flags read by the face).

    - :meth:`silence`: no TPDOs (the node still answers SDO and sends heartbeats);
    - :meth:`delay`: every TPDO leaves ``delay_s`` late (a sluggish device);
    - :meth:`stick`: the position value freezes at its current count;
    - :meth:`wrong_dlc`: the next ``n`` TPDOs carry too few data bytes;
    - :meth:`lose_heartbeat`: the heartbeat producer stops (or resumes);
    - :meth:`emergency`: an EMCY with ``code`` is sent and logged in 0x1001/0x1003;
    - :meth:`jump`: the position value jumps by ``counts`` (a lost or extra count burst, a
      slipping disc) and goes on from there.
    """

    def __init__(self, node: EncoderNode) -> None:
        self._node = node
        self.silent = False
        self.delay_s = 0.0
        self.stuck_counts: int | None = None
        self.short_frames = 0

    def silence(self, on: bool = True) -> None:
        self.silent = on

    def delay(self, delay_s: float) -> None:
        if delay_s < 0:
            raise ValueError(f"delay_s must be >= 0, got {delay_s}")
        self.delay_s = float(delay_s)

    def stick(self, on: bool = True) -> None:
        self.stuck_counts = self._node.position_counts() if on else None

    def wrong_dlc(self, n_frames: int = 1) -> None:
        self.short_frames = int(n_frames)

    def lose_heartbeat(self, lost: bool = True) -> None:
        self._node.set_heartbeat_running(not lost)

    def emergency(self, code: int = 0x1000, register: int = 0x01) -> None:
        self._node.raise_emergency(code, register)

    def jump(self, counts: int) -> None:
        self._node._preset_offset += int(counts)


class EncoderNode(RunsWhileEntered):
    """A CiA 406 absolute encoder as a canopen ``LocalNode`` on a python-can bus.

    ``interface``/``channel`` pick the bus (default: the in-process virtual bus
    ``"rig-encoders"``; put an :class:`simulators.slcan_adapter.SlcanAdapter` on the same
    channel to reach it from another process). ``counts_per_rev`` and ``total_range``
    override 0x6001/0x6002 of the EDS; ``heartbeat_ms`` sets 0x1017 at boot.
    """

    def __init__(
        self,
        plant: Plant,
        node_id: int = 1,
        shaft: Shaft = "output",
        channel: str = "rig-encoders",
        interface: str = "virtual",
        eds: str | Path = DEFAULT_EDS,
        counts_per_rev: int | None = None,
        total_range: int | None = None,
        heartbeat_ms: int | None = None,
        clock: Clock | None = None,
    ) -> None:
        if not 1 <= node_id <= 127:
            raise ValueError(f"node_id must be 1..127, got {node_id}")
        if shaft not in ("output", "input"):
            raise ValueError(f"shaft must be 'output' or 'input', got {shaft!r}")
        self.plant = plant
        self.node_id = node_id
        self.shaft: Shaft = shaft
        self.channel = channel
        self.interface = interface
        self.eds = Path(eds)
        self._clock = clock or MonotonicClock()
        self._od = canopen.import_od(str(self.eds), node_id)
        for index in (0x6001, POSITION_INDEX):
            if index not in self._od:
                raise ValueError(f"{self.eds}: a CiA 406 encoder EDS needs object 0x{index:04X}")
        self._overrides = {0x6001: counts_per_rev, 0x6002: total_range, 0x1017: heartbeat_ms}
        self.backdoor = EncoderBackdoor(self)
        self.network: canopen.Network | None = None
        self.local: canopen.LocalNode | None = None
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._cyclic_thread: threading.Thread | None = None
        self._config_dirty = True
        self._cpr = 1
        self._range = 1 << 32
        self._trans_type = 1
        self._event_timer_ms = 0
        self._cob_id = 0x180 + node_id
        self._sync_count = 0
        self._preset_offset = 0
        self._errors: list[int] = []
        self.syncs_seen = 0
        self.tpdos_sent = 0

    # -- lifecycle -------------------------------------------------------------------------
    def start(self) -> str:
        """Boot the node (boot-up message, PRE-OPERATIONAL) and return the bus description."""
        network = canopen.Network()
        network.NOTIFIER_CYCLE = 0.1  # stop() joins the receive thread within 0.1 s
        local = network.create_node(self.node_id, self._od)
        for index, value in self._overrides.items():
            if value is not None:
                # straight into the store: no write callbacks before the bus is up
                local.data_store.setdefault(index, {})[0] = self._od[index].encode_raw(int(value))
        local.add_read_callback(self._on_sdo_read)
        local.add_write_callback(self._on_sdo_write)
        network.subscribe(SYNC_COB_ID, self._on_sync)
        if self.interface == "virtual":  # python-can's, with a cheaper copy per receiver
            network.bus = virtual_bus(self.channel)
        network.connect(interface=self.interface, channel=self.channel)
        self.network, self.local = network, local
        self._stop.clear()
        local.nmt.send_command(0x81)  # reset node: boot-up message
        local.nmt.send_command(0x80)  # to PRE-OPERATIONAL: heartbeat from 0x1017 starts
        self._cyclic_thread = threading.Thread(
            target=self._cyclic_loop, name=f"encoder node {self.node_id} event timer", daemon=True
        )
        self._cyclic_thread.start()
        return f"{self.interface}:{self.channel} node {self.node_id}"

    def stop(self) -> None:
        """Stop heartbeats and TPDOs and leave the bus."""
        self._stop.set()
        if self._cyclic_thread is not None:
            self._cyclic_thread.join(timeout=2.0)
            self._cyclic_thread = None
        if self.local is not None:
            self.local.nmt.stop_heartbeat()
        if self.network is not None:
            self.network.disconnect()
        self.network = self.local = None

    # -- the device model ------------------------------------------------------------------
    def angle_deg(self, snapshot: PlantSnapshot) -> float:
        """The shaft angle this encoder sees, deg (absolute, unwrapped)."""
        if self.shaft == "output":
            return snapshot.output_angle_deg
        return snapshot.input_angle_deg

    def position_counts(self, at_monotonic_s: float | None = None) -> int:
        """Position value 0x6004: quantised angle + preset offset, modulo 0x6002; now, or
        at host ``time.monotonic()`` time ``at_monotonic_s`` (s) when the plant can tell
        (``snapshot_at_monotonic``)."""
        stuck = self.backdoor.stuck_counts
        if stuck is not None:
            return stuck
        self._refresh_config()
        at = getattr(self.plant, "snapshot_at_monotonic", None)
        snap = (self.plant.snapshot() if at is None or at_monotonic_s is None
                else at(at_monotonic_s))
        raw = math.floor(self.angle_deg(snap) * self._cpr / 360.0)
        return (raw + self._preset_offset) % self._range

    @property
    def nmt_state(self) -> str:
        return self.local.nmt.state if self.local is not None else "OFF"

    # -- backdoor hooks --------------------------------------------------------------------
    def set_heartbeat_running(self, running: bool) -> None:
        if self.local is None:
            return
        if running:
            self.local.nmt.start_heartbeat(int(self.local.sdo[0x1017].raw))
        else:
            self.local.nmt.stop_heartbeat()

    def raise_emergency(self, code: int, register: int) -> None:
        """Send EMCY ``code`` and log it in 0x1001 and 0x1003 (newest first)."""
        if self.local is None:
            return
        with self._lock:
            self._errors.insert(0, code & 0xFFFF)
            self.local.set_data(0x1001, 0, bytes([register & 0xFF]))
        self.local.emcy.send(code, register)

    # -- protocol face ---------------------------------------------------------------------
    def _on_sdo_read(self, index: int, subindex: int, od: object) -> int | None:
        if index == POSITION_INDEX:
            return self.position_counts()
        if index == 0x1003 and 0x1003 in self._od:
            with self._lock:
                if subindex == 0:
                    return len(self._errors)
                if subindex <= len(self._errors):
                    return self._errors[subindex - 1]
        return None

    def _on_sdo_write(self, index: int, subindex: int, od: object, data: bytes) -> None:
        if index in _TPDO_CONFIG_INDICES:
            self._config_dirty = True
        elif index == 0x6003:
            preset = int.from_bytes(data, "little")
            self.backdoor.stuck_counts = None
            with self._lock:
                self._preset_offset = 0
                self._preset_offset = preset - self.position_counts()
        elif index == 0x1003 and subindex == 0 and int.from_bytes(data, "little") == 0:
            with self._lock:  # CiA 301: writing 0 to 0x1003 sub 0 clears the error history
                self._errors.clear()

    def _refresh_config(self) -> None:
        if not self._config_dirty or self.local is None:
            return
        with self._lock:
            self._config_dirty = False
            sdo = self.local.sdo
            self._cpr = max(1, int(sdo[0x6001].raw))
            if 0x6002 in self._od:
                self._range = max(1, int(sdo[0x6002].raw))
            tpdo = self.local.tpdo[1]
            tpdo.read(from_od=False)  # the LocalNode's own SDO view: data store, then EDS
            self._cob_id = tpdo.cob_id
            self._trans_type = int(tpdo.trans_type or 0)
            self._event_timer_ms = int(sdo[0x1800][5].raw) if 5 in self._od[0x1800] else 0

    def _operational(self) -> bool:
        return self.local is not None and self.local.nmt.state == "OPERATIONAL"

    def _on_sync(self, can_id: int, data: bytearray, timestamp: float) -> None:
        """A SYNC: the position is sampled when it reached the node, as a hardware encoder
        latches it on the SYNC (CiA 301 synchronous TPDO) however late this thread runs:
        ``timestamp`` (s, ``time.time()`` scale) is the frame's arrival on the bus (the SLCAN
        adapter gives the kernel's receive time of its bytes)."""
        self.syncs_seen += 1
        self._refresh_config()
        if not 1 <= self._trans_type <= 240 or not self._operational():
            return
        self._sync_count += 1
        if self._sync_count % self._trans_type == 0:
            self._send_position(_sync_monotonic(timestamp))

    def _cyclic_loop(self) -> None:
        deadline = time.monotonic()
        while not self._stop.is_set():
            self._refresh_config()
            period_s = self._event_timer_ms / 1000.0
            if self._trans_type < 254 or period_s <= 0 or not self._operational():
                deadline = time.monotonic()
                self._stop.wait(0.01)
                continue
            self._send_position()
            deadline += period_s
            pause = deadline - time.monotonic()
            if pause > 0:
                self._stop.wait(pause)
            elif pause < -10 * period_s:  # fell far behind (machine stalled): do not burst
                deadline = time.monotonic()

    def _send_position(self, sampled_at_monotonic_s: float | None = None) -> None:
        """Sample (at ``sampled_at_monotonic_s``, host monotonic s; None: now) and send the
        position TPDO; the backdoor's delay holds the frame back after sampling."""
        backdoor = self.backdoor
        if backdoor.silent or self.local is None or self.network is None:
            return
        counts = self.position_counts(sampled_at_monotonic_s)
        if backdoor.delay_s > 0:
            time.sleep(backdoor.delay_s)
        with self._lock:
            tpdo = self.local.tpdo[1]
            position = next((v for v in tpdo.map if v.index == POSITION_INDEX), None)
            if position is None or not tpdo.enabled:
                return
            position.raw = counts
            payload = bytes(tpdo.data)
            if backdoor.short_frames > 0:
                backdoor.short_frames -= 1
                payload = payload[: max(0, len(payload) - 2)]
        try:
            self.network.send_message(self._cob_id, payload)
        except (can.CanError, RuntimeError):
            return  # the bus went away under us (stop() racing a SYNC): nothing to send to
        self.tpdos_sent += 1


SYNC_STAMP_MAX_AGE_S = 2.0
"""A SYNC's bus time older than this (s), or in the future, is not believed (a clock step):
the position is then sampled when the node gets to it."""


def _sync_monotonic(timestamp: float) -> float | None:
    """Host ``time.monotonic()`` time (s) of a frame stamped ``timestamp`` (s,
    ``time.time()`` scale); None when the stamp is missing or not believable."""
    if not timestamp or not math.isfinite(timestamp):
        return None
    now_wall, now_mono = time.time(), time.monotonic()
    age = now_wall - timestamp
    if not 0.0 <= age <= SYNC_STAMP_MAX_AGE_S:
        return None
    return now_mono - age


class SweepPlant:
    """A kinematic stand-in plant for running the encoder face on its own (deg, N*m, s).

    Output angle ``= amplitude_deg * sin(2 pi t / period_s) + torque / stiffness``, input
    angle ``= ratio * output``; the torque command path is real (clamped to
    ``torque_limit_Nm``, zero while the drive is disabled). Not a gear model: the rig's
    ``GearPlant`` replaces it in ``rig sim``.
    """

    def __init__(
        self,
        clock: Clock | None = None,
        amplitude_deg: float = 0.05,
        period_s: float = 4.0,
        ratio: float = 81.0,
        stiffness_Nm_per_deg: float = 2000.0,
        torque_limit_Nm: float = 20.0,
    ) -> None:
        self._clock = clock or MonotonicClock()
        self._amplitude_deg = amplitude_deg
        self._period_s = period_s
        self._ratio = ratio
        self._stiffness = stiffness_Nm_per_deg
        self._limit = torque_limit_Nm
        self._command = 0.0
        self._enabled = False
        self._input_lock_deg = 0.0
        self._lock = threading.Lock()

    def snapshot(self) -> PlantSnapshot:
        return self._snapshot(self._clock.now_s())

    def snapshot_at_monotonic(self, t_mono_s: float) -> PlantSnapshot:
        """The view at host monotonic time ``t_mono_s`` (s), never after now (a clock that
        is not the host's: now). The sweep is a closed form: any past instant is exact."""
        now = self._clock.now_s()
        at_monotonic = getattr(self._clock, "at_monotonic", None)
        return self._snapshot(now if at_monotonic is None else min(now,
                                                                   at_monotonic(t_mono_s)))

    def _snapshot(self, t: float) -> PlantSnapshot:
        with self._lock:
            torque = self._command if self._enabled else 0.0
            out = self._amplitude_deg * math.sin(2 * math.pi * t / self._period_s)
            out += torque / self._stiffness
            return PlantSnapshot(
                t_s=t,
                output_angle_deg=out,
                input_angle_deg=self._input_lock_deg + self._ratio * out,
                torque_Nm=torque,
                true_torque_Nm=torque,
                temperature_C=20.0,
                torque_command_Nm=self._command,
                drive_enabled=self._enabled,
            )

    def command_torque(self, torque_Nm: float) -> None:
        with self._lock:
            self._command = max(-self._limit, min(self._limit, float(torque_Nm)))

    def enable_drive(self, enabled: bool) -> None:
        with self._lock:
            self._enabled = bool(enabled)

    def lock_input_at(self, angle_deg: float) -> None:
        with self._lock:
            self._input_lock_deg = float(angle_deg)


def main(argv: list[str] | None = None) -> int:
    """Serve encoder nodes behind an SLCAN adapter on 127.0.0.1 until killed."""
    from simulators.slcan_adapter import SlcanAdapter

    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("--node-id", type=int, default=1, help="output-shaft encoder node id")
    parser.add_argument("--input-node-id", type=int, default=0, help="input encoder (0: none)")
    parser.add_argument("--port", type=int, default=0, help="SLCAN TCP port (0: a free one)")
    parser.add_argument("--heartbeat-ms", type=int, default=0, help="0x1017 at boot")
    parser.add_argument("--channel", default="rig-encoders-main", help="internal virtual bus")
    args = parser.parse_args(argv)

    plant = SweepPlant()
    heartbeat_ms = args.heartbeat_ms or None
    nodes = [EncoderNode(plant, args.node_id, "output", args.channel, heartbeat_ms=heartbeat_ms)]
    if args.input_node_id:
        nodes.append(
            EncoderNode(plant, args.input_node_id, "input", args.channel, heartbeat_ms=heartbeat_ms)
        )
    for node in nodes:
        node.start()
    adapter = SlcanAdapter(channel=args.channel, port=args.port)
    address = adapter.start()
    info = {"encoder_slcan": address, "nodes": {n.shaft: n.node_id for n in nodes}}
    print(json.dumps(info), flush=True)
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    try:
        while not done.wait(0.5):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        adapter.stop()
        for node in nodes:
            node.stop()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
