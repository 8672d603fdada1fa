"""The whole simulated rig: one GearPlant behind every protocol face, on 127.0.0.1.

``SimulatedRig(plant_config, in_process=True)`` starts, around ONE
:class:`simulators.plant.GearPlant` (the "real world"):

- the output encoder (CANopen node 1) and, optionally, the input encoder (node 2), CiA 406
  :class:`EncoderNode` s on a private virtual CAN bus behind a :class:`SlcanAdapter` on TCP;
- one Modbus server (TCP, or RTU frames over TCP) with the torque sensor (unit 1), the
  loading drive (unit 2, commanding the plant's torque and enable), the input motor (unit 3,
  locking the plant's input angle) and the climate chamber (unit 4, the plant's ambient
  setpoint): :class:`simulators.rig_controls.RigModbusServer`;
- the serial torque transducer (torque and housing temperature) on a pty or a TCP port;

and writes the rig configuration (``rig.toml``) that connects to all of them.
``in_process=False`` runs the same as its own process (``rig sim``) and reads its first
output line; then there is no plant or backdoor to reach, only the addresses.

In process, tests reach the plant (``sim.plant``) and the backdoors (``sim.backdoors``:
``encoder``, ``input_encoder``, ``slcan``, ``modbus``, ``transducer``) for fault injection.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
from pathlib import Path
from typing import Any, Literal

from drivers.lifecycle import RunsWhileEntered
from rig.core.errors import RigError
from rig.hardware.config import dump_rig_toml, rig_config_from_mapping
from rig.hardware.simulated_tolerances import SIMULATED_HEARTBEAT_MS, SIMULATED_MISSED_PERIODS
from simulators.encoder_node import EncoderNode
from simulators.plant import GearPlant
from simulators.plant.config import PlantConfig, load_plant_config
from simulators.rig_controls import RigModbusServer
from simulators.slcan_adapter import SlcanAdapter
from simulators.transducer import TransducerSimulator

TransducerTransport = Literal["pty", "tcp"]
ModbusTransport = Literal["tcp", "rtu-tcp"]

TRANSDUCER_FULL_SCALE_NM = 20.0
"""Range of the simulated transducer (a TT-20, as the reference rig's), N*m."""
OUTPUT_NODE_ID, INPUT_NODE_ID = 1, 2
PORT_OFFSETS = {"modbus": 0, "slcan": 1, "transducer": 2}
"""With ``port_base``: Modbus on base, SLCAN on base + 1, transducer (tcp) on base + 2."""
START_TIMEOUT_S = 60.0
_channels = itertools.count()


class SimulatedRigError(RigError):
    """The simulated rig could not start (names what failed)."""


class SimulatedRig(RunsWhileEntered):
    """Start the simulated rig; use as a context manager (see the module docstring).

    ``plant_config``: a PlantConfig, a plant TOML path, or None (the default plant).
    ``seed`` replaces the plant's noise seed. ``port_base`` None: free ports (port 0).
    ``rig_config_path`` where to write the rig configuration (default: a temporary folder,
    removed on stop). ``sync_period_s`` (s) and ``stream_rate_Hz`` (Hz) go into that file.
    """

    def __init__(
        self,
        plant_config: PlantConfig | str | Path | None = None,
        *,
        in_process: bool = True,
        transducer: TransducerTransport = "pty",
        modbus: ModbusTransport = "tcp",
        port_base: int | None = None,
        seed: int | None = None,
        input_encoder: bool = True,
        rig_config_path: str | Path | None = None,
        sync_period_s: float = 0.002,
        stream_rate_Hz: float = 500.0,
        watchdog_s: float = 0.5,
        realtime_priority: int | None = None,
        device_priority: int | None = None,
    ) -> None:
        if transducer not in ("pty", "tcp"):
            raise ValueError(f"transducer must be 'pty' or 'tcp', got {transducer!r}")
        if modbus not in ("tcp", "rtu-tcp"):
            raise ValueError(f"modbus must be 'tcp' or 'rtu-tcp', got {modbus!r}")
        if port_base is not None and not 1024 <= port_base <= 65535 - len(PORT_OFFSETS):
            raise ValueError(f"port_base must be 1024..{65535 - len(PORT_OFFSETS)}, "
                             f"got {port_base}")
        self.plant_config_arg = plant_config
        self.in_process = in_process
        self.transducer_transport: TransducerTransport = transducer
        self.modbus_transport: ModbusTransport = modbus
        self.port_base = port_base
        self.seed = seed
        self.with_input_encoder = input_encoder
        self.sync_period_s = sync_period_s
        self.stream_rate_Hz = stream_rate_Hz
        self.watchdog_s = watchdog_s
        env_priority = os.environ.get(REALTIME_ENV, "").strip()
        self.realtime_priority = (realtime_priority if realtime_priority is not None
                                  else int(env_priority) if env_priority else None)
        """SCHED_FIFO for the simulated devices (they stand in for hardware, which a busy PC
        cannot starve) and ``[rig] realtime_priority`` of the rig configuration written;
        default from ``RIG_SIM_REALTIME_PRIORITY``; None: normal scheduling."""
        env_device = os.environ.get(DEVICE_PRIORITY_ENV, "").strip()
        self.device_priority = (device_priority if device_priority is not None
                                else int(env_device) if env_device else None)
        """SCHED_FIFO for the simulated devices only (the rig configuration written leaves the
        measuring program on the normal scheduler): a load test then measures our software
        on a busy PC against devices that, like hardware, have their own CPU. Default from
        ``RIG_SIM_DEVICE_PRIORITY``; ``realtime_priority`` wins when both are set."""
        self._rig_config_arg = Path(rig_config_path) if rig_config_path is not None else None
        self.rig_config_path: Path | None = None
        self.addresses: dict[str, Any] = {}
        self.plant: GearPlant | None = None
        self.encoder_nodes: dict[str, EncoderNode] = {}
        self.slcan_adapter: SlcanAdapter | None = None
        self.modbus_server: RigModbusServer | None = None
        self.transducer_sim: TransducerSimulator | None = None
        self.process: subprocess.Popen | None = None
        self._tempdir: Path | None = None
        self._stderr: Any = None
        self.stderr_final = ""
        self.exit_code: int | None = None
        self._started = False

    # -- lifecycle --------------------------------------------------------------------------
    def start(self) -> dict[str, Any]:
        """Start everything; return the addresses (also in ``self.addresses``)."""
        if self._started:
            raise RuntimeError("the simulated rig is already running")
        try:
            if self.in_process:
                self._start_in_process()
            else:
                self._start_process()
        except BaseException:
            self.stop()
            raise
        self._started = True
        return self.addresses

    def stop(self) -> int | None:
        """Stop everything (idempotent); out of process, return the exit code."""
        code = None
        if self.process is not None:
            code = _terminate(self.process)
            self.exit_code = code
            self.process = None
        if self._stderr is not None:
            self.stderr_final = self.stderr_text()
            self._stderr.close()
            self._stderr = None
        for face in ("transducer_sim", "modbus_server", "slcan_adapter"):
            server = getattr(self, face)
            if server is not None:
                server.stop()
                setattr(self, face, None)
        for node in self.encoder_nodes.values():
            node.stop()
        self.encoder_nodes = {}
        if self._tempdir is not None:
            shutil.rmtree(self._tempdir, ignore_errors=True)
            self._tempdir = None
        self._started = False
        return code

    @property
    def backdoors(self) -> dict[str, Any]:
        """Fault injection of every face (in process only)."""
        if not self.in_process:
            raise RuntimeError("backdoors are only reachable in process (in_process=True)")
        out: dict[str, Any] = {k: n.backdoor for k, n in self.encoder_nodes.items()}
        if self.slcan_adapter is not None:
            out["slcan"] = self.slcan_adapter.backdoor
        if self.modbus_server is not None:
            out["modbus"] = self.modbus_server.backdoor
        if self.transducer_sim is not None:
            out["transducer"] = self.transducer_sim.backdoor
        return out

    # -- in process -------------------------------------------------------------------------
    def _plant_config(self) -> PlantConfig:
        arg = self.plant_config_arg
        config = arg if isinstance(arg, PlantConfig) else load_plant_config(arg)
        if self.seed is not None:
            config = config.with_changes(noise={"seed": int(self.seed)})
        return config

    def _port(self, face: str) -> int:
        return 0 if self.port_base is None else self.port_base + PORT_OFFSETS[face]

    def _start_in_process(self) -> None:
        config = self._plant_config()
        plant = GearPlant(config)
        self.plant = plant
        channel = f"simrig-{os.getpid()}-{next(_channels)}"
        shafts = [("encoder", OUTPUT_NODE_ID, "output")]
        if self.with_input_encoder:
            shafts.append(("input_encoder", INPUT_NODE_ID, "input"))
        cpr = config.rig.encoder_counts_per_rev
        for key, node_id, shaft in shafts:
            node = EncoderNode(plant, node_id, shaft, channel, counts_per_rev=cpr,
                               heartbeat_ms=100)
            node.start()
            self.encoder_nodes[key] = node
        self.slcan_adapter = SlcanAdapter(channel=channel, port=self._port("slcan"))
        slcan = self.slcan_adapter.start()
        drive_limit = config.rig.drive_torque_limit_Nm
        self.modbus_server = RigModbusServer(
            plant, drive_limit, transport=self.modbus_transport, port=self._port("modbus"),
            watchdog_s=self.watchdog_s, ambient_C=config.housing.ambient_C,
            input_max_speed_rpm=config.rig.input_max_speed_rpm)
        modbus = self.modbus_server.start()
        self.transducer_sim = TransducerSimulator(
            plant, self.transducer_transport, port=self._port("transducer"),
            full_scale_Nm=TRANSDUCER_FULL_SCALE_NM)
        transducer = self.transducer_sim.start()
        modbus_key = "modbus_tcp" if self.modbus_transport == "tcp" else "modbus_rtu"
        self.addresses = {
            modbus_key: modbus,
            "encoder_slcan": slcan,
            "transducer": transducer,
            "encoder_nodes": {k: n.node_id for k, n in self.encoder_nodes.items()},
            "modbus_units": {"torque_sensor": self.modbus_server.sensor_id,
                             "drive": self.modbus_server.drive_id,
                             "input_motor": self.modbus_server.input_motor_id,
                             "climate": self.modbus_server.climate_id},
            "plant_config": config.source,
        }
        self.rig_config_path = self._write_rig_config(config)
        self.addresses["rig_config"] = str(self.rig_config_path)

    def rig_tables(self, config: PlantConfig) -> dict[str, dict[str, Any]]:
        """The rig configuration tables that connect to the running faces."""
        assert self.modbus_server is not None
        limit = min(config.rig.drive_torque_limit_Nm, TRANSDUCER_FULL_SCALE_NM)
        server = self.modbus_server
        if self.modbus_transport == "tcp":
            host, port = server.address.rsplit(":", 1)
            link: dict[str, Any] = {"transport": "tcp", "host": host, "port": int(port)}
        else:
            link = {"transport": "rtu", "serial_url": server.address}
        timeout = {"timeout_s": 1.0}
        tables: dict[str, dict[str, Any]] = {
            "rig": {"rig_id": "simulated", "torque_limit_Nm": limit, "sample_rate_Hz": 100.0,
                    "keepalive_period_s": 0.1, "master_timeout_s": 2.0,
                    **({} if self.realtime_priority is None
                       else {"realtime_priority": self.realtime_priority})},
            "can": {"interface": "slcan", "channel": self.addresses["encoder_slcan"],
                    "bitrate": 500000, "sync_period_s": self.sync_period_s,
                    "bus_options": {"sleep_after_open": 0}},
        }
        for key, node in self.encoder_nodes.items():
            # heartbeat 500 ms, missing after 3 periods (1.5 s), 400 SYNCs without a PDO: the
            # values the measuring path relaxes any simulated rig to, so that a loaded machine
            # (simulator, drivers, a database restart and a browser on 2 cores) is no fault
            tables[key] = {"name": key.replace("_", " "), "node_id": node.node_id,
                           "counts_per_rev": config.rig.encoder_counts_per_rev,
                           "heartbeat_ms": SIMULATED_HEARTBEAT_MS,
                           "heartbeat_timeout_periods": 3.0,
                           "missed_periods": SIMULATED_MISSED_PERIODS, "timeout_s": 2.0}
        tables["transducer"] = {"url": self.addresses["transducer"],
                                "full_scale_Nm": TRANSDUCER_FULL_SCALE_NM,
                                "stream_rate_Hz": self.stream_rate_Hz, **timeout}
        tables["torque_sensor"] = {**link, "device_id": server.sensor_id, **timeout}
        tables["drive"] = {**link, "device_id": server.drive_id, "torque_limit_Nm": limit,
                           "watchdog_s": self.watchdog_s, **timeout}
        tables["input_motor"] = {**link, "device_id": server.input_motor_id,
                                 "max_speed_rpm": config.rig.input_max_speed_rpm, **timeout}
        tables["climate"] = {**link, "device_id": server.climate_id, **timeout}
        return tables

    def _write_rig_config(self, config: PlantConfig) -> Path:
        tables = self.rig_tables(config)
        path = self._rig_config_arg
        if path is None:
            self._tempdir = Path(tempfile.mkdtemp(prefix="rig-sim-"))
            path = self._tempdir / "rig.toml"
        header = ("Written by `rig sim` for the simulated rig now running; see "
                  "docs/rig-config.md.\n"
                  f"Plant: {config.source}")
        text = dump_rig_toml(tables, header)
        rig_config_from_mapping(tables, str(path))  # what we write must load
        path.write_text(text, encoding="utf-8")
        return path

    # -- as its own process -----------------------------------------------------------------
    def command_line(self) -> list[str]:
        """The ``rig sim`` command this rig runs as (out of process)."""
        cmd = [sys.executable, "-c", "from rig.cli import main; main()", "sim",
               "--transducer", self.transducer_transport, "--modbus", self.modbus_transport,
               "--sync-period", repr(self.sync_period_s),
               "--stream-rate", repr(self.stream_rate_Hz), "--exit-with-parent"]
        arg = self.plant_config_arg
        if isinstance(arg, PlantConfig):
            raise ValueError("out of process the plant config must be a TOML path (or None)")
        if arg is not None:
            cmd += ["--config", str(arg)]
        if self.port_base is not None:
            cmd += ["--port-base", str(self.port_base)]
        if self.seed is not None:
            cmd += ["--seed", str(self.seed)]
        if not self.with_input_encoder:
            cmd.append("--no-input-encoder")
        if self._rig_config_arg is not None:
            cmd += ["--rig-config", str(self._rig_config_arg)]
        if self.realtime_priority is not None:
            cmd += ["--realtime-priority", str(self.realtime_priority)]
        elif self.device_priority is not None:
            cmd += ["--device-priority", str(self.device_priority)]
        return cmd

    def _start_process(self) -> None:
        # stderr to a file, not a pipe: a long-running child must never block on a full pipe
        self._stderr = tempfile.TemporaryFile(mode="w+", encoding="utf-8")  # noqa: SIM115
        proc = subprocess.Popen(self.command_line(), stdout=subprocess.PIPE,
                                stderr=self._stderr, text=True)
        self.process = proc
        ready, _, _ = select.select([proc.stdout], [], [], START_TIMEOUT_S)
        line = proc.stdout.readline() if ready else ""
        if not line:
            _terminate(proc)
            err = self.stderr_text()
            raise SimulatedRigError(f"rig sim printed no addresses within {START_TIMEOUT_S:g} s"
                                    f" (exit {proc.returncode}): {err.strip()}")
        try:
            self.addresses = json.loads(line)
        except json.JSONDecodeError as exc:
            raise SimulatedRigError(f"rig sim's first line is not JSON: {line!r}") from exc
        self.rig_config_path = Path(self.addresses["rig_config"])

    def stderr_text(self) -> str:
        """What the ``rig sim`` process wrote to stderr so far (out of process)."""
        if self._stderr is None:
            return self.stderr_final
        self._stderr.flush()
        self._stderr.seek(0)
        text = self._stderr.read()
        self._stderr.seek(0, os.SEEK_END)
        return text


def _terminate(proc: subprocess.Popen, timeout_s: float = 20.0) -> int:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=timeout_s)
    for stream in (proc.stdout, proc.stderr):
        if stream is not None:
            with contextlib.suppress(OSError):
                stream.close()
    return proc.returncode


REALTIME_ENV = "RIG_SIM_REALTIME_PRIORITY"
DEVICE_PRIORITY_ENV = "RIG_SIM_DEVICE_PRIORITY"


def _write_stats(sim: SimulatedRig, path: Path) -> None:
    """The simulated devices' own figures (the drive's watchdog) as JSON, replaced atomically:
    what a load test reads from outside (``RIG_SIM_STATS``)."""
    server = getattr(sim, "modbus_server", None)
    if server is None:
        return
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(server.drive.stats()), encoding="utf-8")
    os.replace(tmp, path)


def serve_until_signalled(sim: SimulatedRig, poll_s: float = 0.2,
                          parent_pid: int | None = None) -> int:
    """Run ``sim`` (started) until SIGTERM/SIGINT, or until the process ``parent_pid`` is no
    longer this one's parent (it died: an orphaned simulator would load the PC for ever);
    then stop cleanly and return 0.

    Started by a parent (``parent_pid``), SIGINT is ignored: the simulated devices stand in
    for hardware, which a Ctrl-C in the terminal (it reaches the whole process group) does
    not switch off; the parent brings the rig to its safe state, then stops them (SIGTERM)."""
    done = threading.Event()
    signals = (signal.SIGTERM,) if parent_pid is not None else (signal.SIGTERM, signal.SIGINT)
    previous = {sig: signal.signal(sig, lambda *_: done.set()) for sig in signals}
    if parent_pid is not None:
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, signal.SIG_IGN)
    stats_path = os.environ.get("RIG_SIM_STATS")
    try:
        while not done.wait(poll_s):
            if parent_pid is not None and os.getppid() != parent_pid:
                break
            if stats_path:
                _write_stats(sim, Path(stats_path))
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        sim.stop()
    return 0

