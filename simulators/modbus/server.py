"""The Modbus protocol face of the rig: torque sensor and loading drive on one pymodbus server.

Two ``pymodbus.simulator.SimDevice`` units share one server (as on one RS-485 line): the
torque sensor (unit 1) and the loading drive (unit 2), laid out by ``drivers/modbus/map.py``.
Every request runs the SimDevice ``action``, which refreshes the registers from the device
models (``simulators/modbus/devices.py``, fed by the plant) and hands writes to them, so a
running server always serves live values. Faults come from ``simulators/modbus/backdoor.py``.

Transports: ``"tcp"`` (Modbus TCP), ``"rtu-tcp"`` (RTU frames over a TCP socket; the master
opens ``socket://127.0.0.1:PORT``) and ``"rtu-serial"`` (RTU on a serial port or pty path).

Stand-alone: ``python -m simulators.modbus.server --transport tcp --port 0`` prints its
address as JSON on the first stdout line and serves until killed.
"""

from __future__ import annotations

import argparse
import asyncio
import concurrent.futures
import json
import signal
import sys
import threading
from functools import partial
from typing import Literal

from pymodbus.constants import ExcCodes
from pymodbus.framer import FramerType
from pymodbus.server import ModbusSerialServer, ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from drivers.lifecycle import RunsWhileEntered
from drivers.modbus.map import (
    DRIVE_DEVICE_ID,
    LOADING_DRIVE_MAP,
    SENSOR_DEVICE_ID,
    TORQUE_SENSOR_MAP,
    Register,
)
from simulators.modbus.backdoor import ModbusBackdoor
from simulators.modbus.devices import LoadingDriveModel, TorqueSensorModel
from simulators.plant.api import Plant

Transport = Literal["tcp", "rtu-tcp", "rtu-serial"]

_DATATYPES = {"uint16": DataType.UINT16, "uint32": DataType.UINT32,
              "float32": DataType.FLOAT32}
_READ_INPUT, _READ_HOLDING = 4, 3
_WRITES = {6, 16}
WATCHDOG_POLL_S = 0.005


def _simdata(register_map: dict[str, Register], table: str) -> list[SimData]:
    """SimData blocks for one table of a register map (read-only values marked so)."""
    out = []
    for reg in sorted(register_map.values(), key=lambda r: r.address):
        if reg.table != table:
            continue
        value: float | int = 0.0 if reg.datatype == "float32" else 0
        out.append(SimData(reg.address, values=value, datatype=_DATATYPES[reg.datatype],
                           readonly=reg.access == "r"))
    return out


def _sim_device(unit: int, register_map: dict[str, Register], action) -> SimDevice:
    # Coils and discrete inputs are not used: SimDevice still wants one block each (the action
    # answers their function codes with ILLEGAL FUNCTION).
    unused = [SimData(0, values=[False] * 16, datatype=DataType.BITS)]
    return SimDevice(
        id=unit,
        simdata=(unused, list(unused), _simdata(register_map, "holding"),
                 _simdata(register_map, "input")),
        action=action,
    )


class ModbusRigServer(RunsWhileEntered):
    """Serve the simulated torque sensor and loading drive of ``plant`` over Modbus.

    ``torque_limit_Nm`` (N*m) is the drive's own limit; ``full_scale_Nm`` (N*m) the sensor's
    range (default 1.5 x the limit); ``watchdog_s`` (s) the drive's initial watchdog time.
    Use :meth:`start`/:meth:`stop` (own thread and event loop) or, inside a running asyncio
    loop, :meth:`start_async`/:meth:`stop_async`.
    """

    def __init__(
        self,
        plant: Plant,
        torque_limit_Nm: float,
        *,
        transport: Transport = "tcp",
        host: str = "127.0.0.1",
        port: int = 0,
        serial_port: str | None = None,
        baudrate: int = 115200,
        sensor_id: int = SENSOR_DEVICE_ID,
        drive_id: int = DRIVE_DEVICE_ID,
        full_scale_Nm: float | None = None,
        watchdog_s: float = 0.5,
    ) -> None:
        if transport == "rtu-serial" and not serial_port:
            raise ValueError("transport 'rtu-serial' needs serial_port (a tty or pty path)")
        if transport not in ("tcp", "rtu-tcp", "rtu-serial"):
            raise ValueError(f"transport must be tcp, rtu-tcp or rtu-serial, got {transport!r}")
        self.plant = plant
        self.transport: Transport = transport
        self.host, self.port, self.serial_port, self.baudrate = host, port, serial_port, baudrate
        self.sensor_id, self.drive_id = sensor_id, drive_id
        self.sensor = TorqueSensorModel(plant, full_scale_Nm or 1.5 * torque_limit_Nm)
        self.drive = LoadingDriveModel(plant, torque_limit_Nm, watchdog_s)
        self.backdoor = ModbusBackdoor(rtu=transport != "tcp")
        self.address: str | None = None
        self._server: ModbusTcpServer | ModbusSerialServer | None = None
        self._watchdog_task: asyncio.Task | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None

    # -- the SimDevice action: protocol face <-> device models --------------------------
    async def _action(self, model, unit: int, func_code: int, start_address: int,
                      address: int, count: int, registers: list[int],
                      set_values) -> ExcCodes | None:
        if self.backdoor.delay_s > 0:
            await asyncio.sleep(self.backdoor.delay_s)
        if (code := self.backdoor.exception_for(unit)) is not None:
            return code
        if model is self.sensor:
            self.sensor.stuck = self.backdoor.sensor_stuck
        if func_code == _READ_INPUT:
            image = model.input_words()
        elif func_code == _READ_HOLDING:
            image = model.holding_words()
        elif func_code in _WRITES:
            # pymodbus calls the action twice for a write: with the values (apply them), then
            # without (to build the echo reply, which carries the values as written).
            if set_values is not None:
                return model.write_holding(address, list(set_values))
            return None
        else:
            return ExcCodes.ILLEGAL_FUNCTION
        registers[:len(image) - start_address] = image[start_address:]
        return None

    def _devices(self) -> list[SimDevice]:
        return [
            _sim_device(self.sensor_id, TORQUE_SENSOR_MAP,
                        partial(self._action, self.sensor, self.sensor_id)),
            _sim_device(self.drive_id, LOADING_DRIVE_MAP,
                        partial(self._action, self.drive, self.drive_id)),
        ]

    def _trace_packet(self, sending: bool, data: bytes) -> bytes:
        return self.backdoor.filter_reply(data) if sending else data

    # -- asyncio API --------------------------------------------------------------------
    async def start_async(self) -> str:
        """Start serving in the running loop; return the address a master connects to."""
        if self._server is not None:
            raise RuntimeError("the Modbus server is already running")
        self._loop = asyncio.get_running_loop()
        devices = self._devices()
        if self.transport == "tcp":
            server = ModbusTcpServer(devices, address=(self.host, self.port),
                                     trace_packet=self._trace_packet)
        else:
            where = (f"socket://{self.host}:{self.port}" if self.transport == "rtu-tcp"
                     else str(self.serial_port))
            server = ModbusSerialServer(devices, port=where, framer=FramerType.RTU,
                                        baudrate=self.baudrate,
                                        trace_packet=self._trace_packet)
        await server.serve_forever(background=True)
        self._server = server
        if self.transport == "rtu-serial":
            self.address = str(self.serial_port)
        else:
            port = server.transport.sockets[0].getsockname()[1]  # type: ignore[attr-defined]
            self.address = (f"{self.host}:{port}" if self.transport == "tcp"
                            else f"socket://{self.host}:{port}")
        self.backdoor.attach_disconnect(self._disconnect_threadsafe)
        self._watchdog_task = asyncio.create_task(self._watch())
        return self.address

    async def stop_async(self) -> None:
        """Stop serving and close every connection (idempotent)."""
        self.backdoor.attach_disconnect(None)
        if self._watchdog_task is not None:
            self._watchdog_task.cancel()
            self._watchdog_task = None
        if self._server is not None:
            server, self._server = self._server, None
            await server.shutdown()

    async def _watch(self) -> None:
        while True:
            self.drive.note_poll(WATCHDOG_POLL_S)
            await asyncio.sleep(WATCHDOG_POLL_S)

    def _drop_connections(self) -> None:
        server = self._server
        if server is None:
            return
        if self.transport == "rtu-serial":
            # On a serial line a pulled cable looks like silence to the master: there is no
            # connection to drop. The line stays silent until backdoor.clear().
            self.backdoor.silence(None)
            return
        for conn in list(server.active_connections.values()):
            conn.close()

    def _disconnect_threadsafe(self) -> None:
        loop = self._loop
        if loop is None:
            return
        if threading.current_thread() is self._thread or _running_loop() is loop:
            self._drop_connections()
            return
        done = concurrent.futures.Future()

        def run() -> None:
            try:
                self._drop_connections()
            finally:
                done.set_result(None)

        loop.call_soon_threadsafe(run)
        done.result(timeout=5.0)

    # -- thread API ---------------------------------------------------------------------
    def start(self) -> str:
        """Serve from a background thread with its own event loop; return the address."""
        if self._thread is not None:
            raise RuntimeError("the Modbus server is already running")
        started: concurrent.futures.Future[str] = concurrent.futures.Future()
        loop = asyncio.new_event_loop()

        def run() -> None:
            asyncio.set_event_loop(loop)
            try:
                started.set_result(loop.run_until_complete(self.start_async()))
            except BaseException as exc:  # hand the failure to start()'s caller
                started.set_exception(exc)
                loop.close()
                return
            loop.run_forever()
            loop.run_until_complete(self.stop_async())
            loop.close()

        self._thread = threading.Thread(target=run, name="modbus-rig-server", daemon=True)
        self._thread.start()
        try:
            return started.result(timeout=10.0)
        except BaseException:
            self._thread.join(timeout=5.0)
            self._thread = None
            raise

    def stop(self) -> None:
        """Stop the background server (idempotent)."""
        thread, self._thread = self._thread, None
        if thread is None or self._loop is None:
            return
        self._loop.call_soon_threadsafe(self._loop.stop)
        thread.join(timeout=10.0)


def _running_loop() -> asyncio.AbstractEventLoop | None:
    try:
        return asyncio.get_running_loop()
    except RuntimeError:
        return None


def _make_plant(kind: str, config_path: str | None = None) -> Plant:
    if kind == "gear":
        from simulators.plant import GearPlant  # the rig's plant (imported only when asked)
        from simulators.plant.config import load_plant_config

        return GearPlant(load_plant_config(config_path))
    from simulators.modbus.plant_backdoor import SineTestPlant

    return SineTestPlant()


def main(argv: list[str] | None = None) -> int:
    """Serve until SIGTERM/SIGINT; print ``{"modbus_...": address, ...}`` first."""
    parser = argparse.ArgumentParser(prog="python -m simulators.modbus.server",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--transport", choices=["tcp", "rtu-tcp", "rtu-serial"], default="tcp")
    parser.add_argument("--port", type=int, default=0, help="TCP port (0 = any free port)")
    parser.add_argument("--serial-port", help="tty/pty path for rtu-serial")
    parser.add_argument("--torque-limit", type=float, default=20.0, help="drive limit, N*m")
    parser.add_argument("--full-scale", type=float, default=None, help="sensor range, N*m")
    parser.add_argument("--watchdog", type=float, default=0.5, help="drive watchdog, s")
    parser.add_argument("--plant", choices=["sine", "gear"], default="sine",
                        help="sine: closed-form test plant; gear: simulators.plant.GearPlant")
    parser.add_argument("--plant-config", help="plant TOML for --plant gear (default: built-in)")
    args = parser.parse_args(argv)
    server = ModbusRigServer(_make_plant(args.plant, args.plant_config), args.torque_limit,
                             transport=args.transport, port=args.port,
                             serial_port=args.serial_port, full_scale_Nm=args.full_scale,
                             watchdog_s=args.watchdog)
    address = server.start()
    key = {"tcp": "modbus_tcp", "rtu-tcp": "modbus_rtu", "rtu-serial": "modbus_rtu"}
    print(json.dumps({key[args.transport]: address, "sensor_id": server.sensor_id,
                      "drive_id": server.drive_id}), flush=True)
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    stop.wait()
    server.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
