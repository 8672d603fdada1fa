"""One Modbus master connection (TCP or RTU) shared by the Modbus drivers.

Wraps the synchronous pymodbus client behind a lock and turns every failure into the
project's errors (``drivers/errors.py``), each naming the device and the transport address:

- no (valid) reply within the timeout -> :class:`DeviceTimeout`;
- an exception response -> :class:`DeviceFault` naming the exception code;
- connection refused or lost -> :class:`DeviceDisconnected`;
- a reply of the wrong shape -> :class:`DeviceProtocolError`.

After a timeout the link is closed, so a late reply can never be taken for the answer to
the next request; the next request reconnects.
"""

from __future__ import annotations

import struct
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.constants import ExcCodes
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException
from pymodbus.framer import FramerType

from drivers.errors import (
    DeviceDisconnected,
    DeviceError,
    DeviceFault,
    DeviceProtocolError,
    DeviceTimeout,
)


class ModbusLinkConfig(BaseModel):
    """Where a Modbus device is and how long to wait for it (a TOML table maps onto this).

    ``transport = "tcp"`` uses ``host``/``port``; ``transport = "rtu"`` uses ``serial_url``
    (a tty such as ``/dev/ttyUSB0``, a pty, or a pyserial URL such as
    ``socket://127.0.0.1:15021``) and ``baudrate``. ``timeout_s`` (s) bounds each request.
    """

    model_config = ConfigDict(extra="forbid")

    transport: Literal["tcp", "rtu"] = "tcp"
    host: str = "127.0.0.1"
    port: int = Field(default=502, ge=1, le=65535)
    serial_url: str | None = None
    baudrate: int = Field(default=115200, gt=0)
    device_id: int = Field(default=1, ge=1, le=247)
    timeout_s: float = Field(default=0.5, gt=0, le=60)
    retries: int = Field(default=0, ge=0, le=10)

    @model_validator(mode="after")
    def _rtu_needs_port(self) -> ModbusLinkConfig:
        if self.transport == "rtu" and not self.serial_url:
            raise ValueError("transport 'rtu' needs serial_url (tty path or socket:// URL)")
        return self

    def where(self) -> str:
        """The transport address in words, e.g. ``tcp 127.0.0.1:502``."""
        if self.transport == "tcp":
            return f"tcp {self.host}:{self.port}"
        return f"rtu {self.serial_url}"


@dataclass(frozen=True)
class ModbusHealth:
    """What a Modbus driver knows about its device's health (never raises to produce)."""

    device: str
    ok: bool
    detail: str
    requests: int
    errors: int
    last_latency_s: float | None


class ModbusLink:
    """A locked, synchronous Modbus master on one TCP connection or serial line."""

    def __init__(self, config: ModbusLinkConfig) -> None:
        self.config = config
        self._lock = threading.RLock()
        self.requests = 0
        self.errors = 0
        self.last_latency_s: float | None = None
        self._client: ModbusTcpClient | ModbusSerialClient
        if config.transport == "tcp":
            self._client = ModbusTcpClient(config.host, port=config.port,
                                           timeout=config.timeout_s, retries=config.retries)
        else:
            self._client = ModbusSerialClient(str(config.serial_url), framer=FramerType.RTU,
                                              baudrate=config.baudrate,
                                              timeout=config.timeout_s,
                                              retries=config.retries)

    def where(self) -> str:
        return self.config.where()

    def _connect(self, device: str) -> None:
        if self._client.connected:
            return
        try:
            ok = self._client.connect()
        except (OSError, ModbusException) as exc:
            raise DeviceDisconnected(device, f"a connection on {self.where()}",
                                     f"{type(exc).__name__}: {exc}") from exc
        if not ok:
            raise DeviceDisconnected(device, f"a connection on {self.where()}",
                                     "connection refused or port not available")

    def _call(self, device: str, what: str, unit: int, call: Callable[[], Any]) -> Any:
        """Run one request under the lock; map every failure to a DeviceError."""
        with self._lock:
            self.requests += 1
            try:
                self._connect(device)
                t0 = time.monotonic()
                try:
                    reply = call()
                except ModbusIOException as exc:
                    self._client.close()  # drop late replies with the connection
                    raise DeviceTimeout(
                        device,
                        f"a reply from unit {unit} to {what} within {self.config.timeout_s} s "
                        f"on {self.where()}",
                        "no valid reply") from exc
                except (ConnectionException, OSError) as exc:  # reset, broken pipe, port gone
                    self._client.close()
                    raise DeviceDisconnected(device, f"an open connection for {what} on "
                                             f"{self.where()}", f"connection lost ({exc})"
                                             ) from exc
                except (ModbusException, ValueError, struct.error) as exc:
                    self._client.close()
                    raise DeviceProtocolError(device, f"a valid reply to {what}",
                                              f"{type(exc).__name__}: {exc}") from exc
                self.last_latency_s = time.monotonic() - t0
                if reply.isError():
                    code = getattr(reply, "exception_code", None)
                    try:
                        name = ExcCodes(code).name
                    except ValueError:
                        name = "unknown"
                    raise DeviceFault(device, f"a normal reply from unit {unit} to {what}",
                                      f"Modbus exception code {code} ({name})")
                return reply
            except DeviceError:
                self.errors += 1
                raise

    def read_input(self, device: str, unit: int, address: int, count: int) -> list[int]:
        """Read ``count`` input registers (function code 4) from ``address``."""
        what = f"read input registers {address}..{address + count - 1} (FC4)"
        reply = self._call(device, what, unit, lambda: self._client.read_input_registers(
            address, count=count, device_id=unit))
        return self._registers(device, what, reply, count)

    def read_holding(self, device: str, unit: int, address: int, count: int) -> list[int]:
        """Read ``count`` holding registers (function code 3) from ``address``."""
        what = f"read holding registers {address}..{address + count - 1} (FC3)"
        reply = self._call(device, what, unit, lambda: self._client.read_holding_registers(
            address, count=count, device_id=unit))
        return self._registers(device, what, reply, count)

    def write(self, device: str, unit: int, address: int, words: Sequence[int]) -> None:
        """Write holding registers: one word with FC6, more with FC16."""
        words = [int(w) for w in words]
        if len(words) == 1:
            what = f"write holding register {address} = {words[0]} (FC6)"
            self._call(device, what, unit, lambda: self._client.write_register(
                address, words[0], device_id=unit))
        else:
            what = f"write holding registers {address}..{address + len(words) - 1} (FC16)"
            self._call(device, what, unit, lambda: self._client.write_registers(
                address, words, device_id=unit))

    @staticmethod
    def _registers(device: str, what: str, reply: Any, count: int) -> list[int]:
        regs = list(getattr(reply, "registers", []) or [])
        if len(regs) != count:
            raise DeviceProtocolError(device, f"{count} registers in the reply to {what}",
                                      f"{len(regs)}")
        return regs

    def close(self) -> None:
        with self._lock:
            self._client.close()


class ReportsModbusHealth:
    """:meth:`health` of a Modbus device with ``name`` and ``link``: one read by its
    ``_health_check()`` (ok, detail), a DeviceError being (False, its text)."""

    name: str
    link: ModbusLink
    _health_check: Callable[[], tuple[bool, str]]
    """Each device's one read (sensor, drive, input motor, climate chamber define it)."""

    def health(self) -> ModbusHealth:
        """Read once and say whether the device answers sensibly; never raises."""
        try:
            ok, detail = self._health_check()
        except DeviceError as exc:
            ok, detail = False, str(exc)
        return ModbusHealth(self.name, ok, detail, self.link.requests, self.link.errors,
                            self.link.last_latency_s)
