"""Open every driver of a rig configuration as one bundle: :func:`open_rig` -> RigDevices.

The measuring engine uses the bundle; nothing else in the application opens drivers. What
it holds (None where the configuration has no such device, or it failed to open with
``tolerate_faults=True``):

- ``encoder``, ``input_encoder``: :class:`drivers.encoder_canopen.CanopenEncoder` on one
  shared :class:`EncoderNetwork` (the SYNC producer);
- ``transducer``: :class:`drivers.transducer.serial.SerialTorqueTransducer` (opened);
- ``torque_sensor``, ``drive``: the Modbus drivers; ``input_motor``, ``climate``: the
  :mod:`drivers.rig_controls` ones. Modbus devices at the same address share one
  :class:`ModbusLink` (one RS-485 line or TCP connection, requests serialised).

Drive keepalive: the drive's watchdog trips when the master writes nothing for
``drive.watchdog_s``. The keepalive is written every ``rig.keepalive_period_s`` while the
engine shows it is alive: the engine calls :meth:`RigDevices.alive` at least every
``rig.master_timeout_s``; if it stops (a hung program), the keepalive stops and the drive
falls to its safe state by itself. On Modbus TCP (and ``rig.hardware.keepalive_process``, the
default) a small process of its own writes it over its own connection
(:mod:`rig.hardware.keepalive_process`), so nothing in this process can hold it up; a thread of the
bundle writes it whenever that process has not been acknowledged for 1.5 periods (not yet
started, died, or an RS-485 line with one master, where the thread is the only writer).
``safe_state()`` (zero torque, disabled) never raises; ``close()`` stops the thread, puts the
drive safe and closes everything.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from drivers.encoder_canopen import CanopenEncoder, EncoderNetwork
from drivers.errors import DeviceError
from drivers.loading_drive import LoadingDrive
from drivers.modbus.link import ModbusLink, ModbusLinkConfig
from drivers.modbus.map import LOADING_DRIVE_MAP
from drivers.modbus.torque_sensor import ModbusTorqueSensor
from drivers.rig_controls import ClimateChamber, InputMotor
from drivers.transducer.serial import SerialTorqueTransducer
from rig.hardware.config import RigConfig, link_key
from rig.hardware.keepalive_process import KeepaliveProcess, KeepaliveTarget

log = logging.getLogger(__name__)

KEEPALIVE_REGISTER = LOADING_DRIVE_MAP["keepalive"].address


class RigDevices:
    """The opened drivers of one rig (see the module docstring). Use :func:`open_rig`."""

    def __init__(self, config: RigConfig) -> None:
        self.config = config
        self.network: EncoderNetwork | None = None
        self.encoder: CanopenEncoder | None = None
        self.input_encoder: CanopenEncoder | None = None
        self.transducer: SerialTorqueTransducer | None = None
        self.torque_sensor: ModbusTorqueSensor | None = None
        self.drive: LoadingDrive | None = None
        self.input_motor: InputMotor | None = None
        self.climate: ClimateChamber | None = None
        self.links: dict[tuple, ModbusLink] = {}
        self.open_errors: dict[str, str] = {}
        self._thread_errors = 0
        self._thread_error: str | None = None
        self._thread_withheld = False
        self._alive_mono = time.monotonic()
        self._stop = threading.Event()
        self._keepalive_thread: threading.Thread | None = None
        self._keepalive_process: KeepaliveProcess | None = None
        self._thread_sent = 0
        self._closed = False

    # -- for the engine ---------------------------------------------------------------------
    @property
    def torque_limit_Nm(self) -> float:
        """The most torque (N*m) to command: configuration and the drive's own limit."""
        limit = self.config.torque_limit_Nm
        if self.drive is not None:
            limit = min(limit, self.drive.torque_limit_Nm)
        return limit

    def alive(self) -> None:
        """Tell the keepalive the measuring program is alive (call it often)."""
        self._alive_mono = time.monotonic()
        process = self._keepalive_process
        if process is not None:
            process.alive()

    @property
    def keepalives_sent(self) -> int:
        """Keepalives written (process and thread)."""
        process = self._keepalive_process
        return self._thread_sent + (process.sent if process is not None else 0)

    @property
    def keepalive_errors(self) -> int:
        process = self._keepalive_process
        return self._thread_errors + (process.errors if process is not None else 0)

    @property
    def last_keepalive_error(self) -> str | None:
        process = self._keepalive_process
        return (process.last_error if process is not None else None) or self._thread_error

    @property
    def keepalive_withheld(self) -> bool:
        """True while the measuring program is silent and the keepalive is withheld."""
        process = self._keepalive_process
        return self._thread_withheld or (process is not None and process.withheld)

    @property
    def keepalive_process_running(self) -> bool:
        """True while the keepalive's own process runs (see the module doc)."""
        process = self._keepalive_process
        return process is not None and process.running

    def get(self, name: str) -> Any:
        """The driver called ``name`` (a key of ``RigConfig.device_names()``), or None."""
        if name not in self.config.device_names():
            raise KeyError(f"{self.config.source}: no device {name!r} in this configuration")
        return getattr(self, name)

    def safe_state(self) -> bool:
        """Drive to zero torque and disabled (one request). Never raises; False if the drive
        could not be reached (its watchdog then brings it to the same state)."""
        drive = self.drive
        if drive is None:
            return self.config.drive is None
        try:
            drive.safe_state()
            return True
        except DeviceError as exc:
            log.error("safe state not confirmed: %s", exc)
        except Exception:  # safe_state must never raise past logging
            log.exception("safe state not confirmed: unexpected error")
        return False

    def close(self) -> None:
        """Stop the keepalive, put the drive safe, close every driver (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self.stop_keepalive()
        self.safe_state()
        closers: list[tuple[str, Callable[[], None] | None]] = [
            ("drive", self.drive and (lambda: self.drive.close(safe=False))),
            ("transducer", self.transducer and self.transducer.close),
            ("torque_sensor", self.torque_sensor and self.torque_sensor.close),
            ("input_motor", self.input_motor and self.input_motor.close),
            ("climate", self.climate and self.climate.close),
            ("input_encoder", self.input_encoder and self.input_encoder.close),
            ("encoder", self.encoder and self.encoder.close),
            ("CAN bus", self.network and self.network.close),
        ]
        closers += [(f"Modbus link {k}", link.close) for k, link in self.links.items()]
        for name, close in closers:
            if close is None:
                continue
            try:
                close()
            except Exception:  # closing the rest matters more than one close failing
                log.exception("closing %s failed", name)

    def __enter__(self) -> RigDevices:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- keepalive --------------------------------------------------------------------------
    def start_keepalive(self) -> None:
        """Start the drive keepalive: its process where it can have one, and the thread
        (done by :func:`open_rig`; idempotent)."""
        if self.drive is None or self._keepalive_thread is not None:
            return
        self._stop.clear()
        self.alive()
        self._start_keepalive_process()
        self._keepalive_thread = threading.Thread(target=self._keepalive_loop,
                                                  name="rig drive keepalive", daemon=True)
        self._keepalive_thread.start()

    def _start_keepalive_process(self) -> None:
        cfg, rig = self.config.drive, self.config.rig
        if not rig.keepalive_process or cfg is None or cfg.transport != "tcp":
            return
        process = KeepaliveProcess(KeepaliveTarget(
            host=cfg.host, port=cfg.port, unit=cfg.device_id, address=KEEPALIVE_REGISTER,
            timeout_s=cfg.timeout_s, period_s=rig.keepalive_period_s,
            master_timeout_s=rig.master_timeout_s))
        try:
            process.start()
        except OSError as exc:  # the thread alone then feeds the drive
            log.warning("drive keepalive process did not start (%s): the thread feeds the "
                        "drive", exc)
            process.stop()
            return
        self._keepalive_process = process

    def stop_keepalive(self) -> None:
        """Stop the keepalive (process and thread) and wait for them."""
        self._stop.set()
        thread, self._keepalive_thread = self._keepalive_thread, None
        if thread is not None:
            thread.join(timeout=5.0 + 2 * self.config.drive.timeout_s)
        process, self._keepalive_process = self._keepalive_process, None
        if process is not None:
            process.stop()
            # its figures stay readable after the stop (the thread's counts hold them)
            self._thread_sent += process.sent
            self._thread_errors += process.errors

    @property
    def keepalive_running(self) -> bool:
        thread = self._keepalive_thread
        return thread is not None and thread.is_alive()

    def _keepalive_loop(self) -> None:
        period = self.config.rig.keepalive_period_s
        master_timeout = self.config.rig.master_timeout_s
        while not self._stop.wait(period):
            drive = self.drive
            if drive is None:
                return
            silent_s = time.monotonic() - self._alive_mono
            if master_timeout is not None and silent_s > master_timeout:
                if not self._thread_withheld:
                    log.error("measuring program silent for %.1f s: drive keepalive withheld "
                              "(the drive watchdog will disable it)", silent_s)
                self._thread_withheld = True
                continue
            self._thread_withheld = False
            process = self._keepalive_process
            if process is not None and process.fed_within(1.5 * period):
                continue  # the keepalive process feeds the drive
            try:
                drive.keepalive()
                self._thread_sent += 1
            except DeviceError as exc:
                self._thread_errors += 1
                if str(exc) != self._thread_error:
                    log.warning("drive keepalive failed: %s", exc)
                self._thread_error = str(exc)


def _link(devices: RigDevices, cfg: ModbusLinkConfig) -> ModbusLink:
    key = link_key(cfg)
    if key not in devices.links:
        common = ModbusLinkConfig.model_validate(
            {k: getattr(cfg, k) for k in ModbusLinkConfig.model_fields})
        devices.links[key] = ModbusLink(common)
    return devices.links[key]


def _open_encoders(devices: RigDevices, tolerate: bool) -> None:
    config = devices.config
    network = EncoderNetwork(config.can)
    devices.network = network
    for name in ("encoder", "input_encoder"):
        enc_cfg = getattr(config, name)
        if enc_cfg is None:
            continue
        encoder = CanopenEncoder(enc_cfg, network)
        _guarded(devices, name, tolerate, lambda e=encoder: e.start())
        if name not in devices.open_errors:
            setattr(devices, name, encoder)


def _guarded(devices: RigDevices, name: str, tolerate: bool, action: Callable[[], Any]) -> Any:
    try:
        return action()
    except (DeviceError, ValueError, OSError) as exc:
        if not tolerate:
            raise
        devices.open_errors[name] = f"{type(exc).__name__}: {exc}"
        log.warning("%s did not open: %s", name, exc)
        return None


def open_rig(config: RigConfig, *, tolerate_faults: bool = False) -> RigDevices:
    """Open every device of ``config`` and start the drive keepalive.

    ``tolerate_faults=False`` (the engine): the first device that fails closes what was
    opened and its error is raised. ``True`` (diagnostics): failed devices stay None and
    their errors are in ``open_errors``.
    """
    devices = RigDevices(config)
    try:
        _open_encoders(devices, tolerate_faults)
        tt = SerialTorqueTransducer(config.transducer)
        if _guarded(devices, "transducer", tolerate_faults, tt.open) is not None:
            devices.transducer = tt
        sensor = ModbusTorqueSensor(config.torque_sensor,
                                    link=_link(devices, config.torque_sensor))
        devices.torque_sensor = sensor  # kept even if the probe fails: it may recover
        _guarded(devices, "torque_sensor", tolerate_faults, sensor.read)
        devices.drive = _guarded(devices, "drive", tolerate_faults,
                                 lambda: LoadingDrive(config.drive,
                                                      link=_link(devices, config.drive)))
        if config.input_motor is not None:
            motor = InputMotor(config.input_motor, link=_link(devices, config.input_motor))
            devices.input_motor = motor
            _guarded(devices, "input_motor", tolerate_faults, motor.state)
        if config.climate is not None:
            climate = ClimateChamber(config.climate, link=_link(devices, config.climate))
            devices.climate = climate
            _guarded(devices, "climate", tolerate_faults, climate.state)
        devices.start_keepalive()
    except BaseException:
        with contextlib.suppress(Exception):
            devices.close()
        raise
    return devices
