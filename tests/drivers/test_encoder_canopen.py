"""The CiA 406 encoder driver against its simulator, over the real canopen/python-can stacks.

The encoder face is fed by ``RampPlant`` below: a small, honest test plant whose shaft
angles are set by the test (a ManualClock-free plant: the test moves the shaft), with a
real torque command path (clamped, zero while disabled).
"""

from __future__ import annotations

import math
import threading
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import canopen
import numpy as np
import pytest

from drivers.encoder_canopen import (
    DEFAULT_EDS,
    CanBusConfig,
    CanopenEncoder,
    EncoderConfig,
    EncoderNetwork,
    encoder_config_from_toml,
)
from drivers.errors import DeviceDisconnected, DeviceFault, DeviceProtocolError, DeviceTimeout
from simulators.encoder_node import EncoderNode, SweepPlant
from simulators.plant.api import PlantSnapshot
from simulators.slcan_adapter import SlcanAdapter

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

CPR = 8_388_608  # 0x6001 of the shipped EDS: 23 bit per revolution
RANGE = 2_147_483_648  # 0x6002: 256 revolutions


class RampPlant:
    """Test plant: the test sets the output angle (deg); input = ratio * output + lock."""

    def __init__(self, output_angle_deg: float = 0.0, ratio: float = 81.0) -> None:
        self.output_angle_deg = output_angle_deg
        self.ratio = ratio
        self.torque_limit_Nm = 20.0
        self._command = 0.0
        self._enabled = False
        self._lock_deg = 0.0
        self._guard = threading.Lock()

    def snapshot(self) -> PlantSnapshot:
        with self._guard:
            out = self.output_angle_deg
            torque = self._command if self._enabled else 0.0
            return PlantSnapshot(0.0, out, self._lock_deg + self.ratio * out, torque, torque,
                                 20.0, self._command, self._enabled)

    def command_torque(self, torque_Nm: float) -> None:
        with self._guard:
            self._command = max(-self.torque_limit_Nm, min(self.torque_limit_Nm, torque_Nm))

    def enable_drive(self, enabled: bool) -> None:
        with self._guard:
            self._enabled = enabled

    def lock_input_at(self, angle_deg: float) -> None:
        with self._guard:
            self._lock_deg = angle_deg


def wait_for(predicate, timeout_s: float = 5.0, what: str = "condition"):
    """Poll ``predicate`` until it returns a truthy value (generous timeout)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.005)
    raise AssertionError(f"timed out waiting for {what}")


def wait_for_error(encoder: CanopenEncoder, kind: type[Exception], timeout_s: float = 5.0):
    """Call ``read()`` until it raises ``kind``; return (exception, seconds waited)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        try:
            encoder.read()
        except kind as exc:
            return exc, time.monotonic() - t0
        time.sleep(0.005)
    raise AssertionError(f"{kind.__name__} not raised within {timeout_s} s")


@pytest.fixture
def channel() -> str:
    return f"enc-{uuid.uuid4().hex[:8]}"


@pytest.fixture
def plant() -> RampPlant:
    return RampPlant(output_angle_deg=1.25)


@pytest.fixture
def node(plant: RampPlant, channel: str) -> Iterator[EncoderNode]:
    face = EncoderNode(plant, node_id=5, channel=channel)
    face.start()
    yield face
    face.stop()


def make_config(channel: str, **kw) -> EncoderConfig:
    bus = kw.pop("bus", CanBusConfig(interface="virtual", channel=channel, sync_period_s=0.01))
    return EncoderConfig(node_id=kw.pop("node_id", 5), bus=bus, **kw)


@pytest.fixture
def encoder(node: EncoderNode, channel: str) -> Iterator[CanopenEncoder]:
    enc = CanopenEncoder(make_config(channel, heartbeat_ms=100, missed_periods=20))
    enc.start()
    yield enc
    enc.close()


def expected_counts(angle_deg: float, cpr: int = CPR, span: int = RANGE) -> int:
    """CiA 406 position value: floor(angle / 360 * cpr) modulo the total range."""
    return math.floor(angle_deg * cpr / 360.0) % span


# -- normal operation -------------------------------------------------------------------------
def test_identity_resolution_and_device_type(encoder: CanopenEncoder) -> None:
    ident = encoder.identity()
    assert ident.device_type & 0xFFFF == 0x0196
    assert (ident.vendor_id, ident.product_code, ident.serial_number) == (0xB4C, 0x406, 1)
    assert ident.counts_per_rev == CPR and ident.total_range == RANGE
    assert ident.device_name == "Sim406"


def test_position_is_the_quantised_plant_angle(encoder: CanopenEncoder, plant: RampPlant) -> None:
    for angle in (1.25, 10.0 + 1e-5, 359.99999, 0.000043, -0.5, -123.456789):
        plant.output_angle_deg = angle
        reading = wait_for(
            lambda a=angle: (r := encoder.read()).counts == expected_counts(a) and r, what="count"
        )
        # the driver's angle is the count times 360/cpr: within one count of the plant angle
        assert reading.angle_deg == pytest.approx(math.floor(angle * CPR / 360) * 360 / CPR)
        assert 0 <= angle - reading.angle_deg < 360 / CPR + 1e-12


def test_every_sample_arrives_in_order(encoder: CanopenEncoder, node: EncoderNode) -> None:
    first = encoder.readings()
    time.sleep(0.3)
    rest = encoder.readings()
    seqs = [r.seq for r in first + rest]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    assert seqs[0] == 0
    # the node sent exactly what the driver got (no sample lost on the way)
    wait_for(lambda: node.tpdos_sent == encoder.health().samples, what="all PDOs received")
    assert all(t1 >= t0 for t0, t1 in zip(
        [r.t_s for r in first + rest], [r.t_s for r in (first + rest)[1:]], strict=False))


def test_callback_sees_every_sample(node: EncoderNode, channel: str) -> None:
    enc = CanopenEncoder(make_config(channel))
    seen: list[int] = []
    enc.add_callback(lambda r: seen.append(r.seq))
    with enc:
        wait_for(lambda: len(seen) >= 20, what="20 samples")
    assert seen[:20] == list(range(20))


def test_zero_and_preset(encoder: CanopenEncoder, plant: RampPlant) -> None:
    old = encoder.zero()
    assert old == pytest.approx(1.25, abs=1e-4)
    seq = encoder.read().seq  # the zero applies from the next sample on
    wait_for(lambda: encoder.read().seq > seq, what="a sample after zero()")
    assert encoder.read().angle_deg == pytest.approx(0.0, abs=1e-9)
    plant.output_angle_deg = 1.75
    wait_for(lambda: abs(encoder.read().angle_deg - 0.5) < 1e-4, what="0.5 deg after zero")
    encoder.preset(1000)
    wait_for(lambda: encoder.read().counts == 1000, what="preset position value 1000")


def test_unwraps_across_the_total_range(plant: RampPlant, channel: str) -> None:
    """A 10-turn encoder (0x6002 = 3600 counts) wraps at 3600 deg; the driver does not."""
    plant.output_angle_deg = 3590.0
    face = EncoderNode(plant, node_id=7, channel=channel, counts_per_rev=360, total_range=3600)
    face.start()
    try:
        with CanopenEncoder(make_config(channel, node_id=7, counts_per_rev=360)) as enc:
            assert enc.read().angle_deg == pytest.approx(-10.0)  # first sample: signed range
            for angle in (3595.0, 3600.0, 3605.0, 3700.0, 5300.0):
                plant.output_angle_deg = angle
                wait_for(lambda a=angle: enc.read().angle_deg == pytest.approx(a - 3600.0),
                         what=f"{angle} deg")
            assert enc.read().counts == 5300 % 3600
    finally:
        face.stop()


def test_cyclic_transmission_without_sync(node: EncoderNode, channel: str) -> None:
    bus = CanBusConfig(interface="virtual", channel=channel, sync_period_s=None)
    cfg = make_config(channel, bus=bus, transmission="cyclic", cyclic_period_s=0.005)
    with CanopenEncoder(cfg) as enc:
        wait_for(lambda: enc.health().samples >= 40, what="40 cyclic samples")
        samples = enc.readings()
        assert node.syncs_seen == 0
        span = samples[-1].t_s - samples[0].t_s
        assert span > 0
        assert enc.health().ok


def test_sync_every_third(node: EncoderNode, channel: str) -> None:
    with CanopenEncoder(make_config(channel, sync_every=3)) as enc:
        wait_for(lambda: enc.network.syncs_sent >= 60, what="60 SYNCs")
        enc.network.stop_sync()
        time.sleep(0.1)
        assert enc.health().samples == node.syncs_seen // 3


def test_two_encoders_on_one_network(plant: RampPlant, channel: str) -> None:
    faces = [EncoderNode(plant, 5, "output", channel), EncoderNode(plant, 6, "input", channel)]
    for face in faces:
        face.start()
    network = EncoderNetwork(CanBusConfig(interface="virtual", channel=channel, sync_period_s=0.01))
    out = CanopenEncoder(EncoderConfig(name="output encoder", node_id=5), network)
    inp = CanopenEncoder(EncoderConfig(name="input encoder", node_id=6), network)
    try:
        out.start()
        inp.start()
        plant.output_angle_deg = 0.5
        wait_for(lambda: out.read().counts == expected_counts(0.5), what="output at 0.5")
        wait_for(lambda: inp.read().counts == expected_counts(81 * 0.5), what="input at 40.5")
        assert inp.read().angle_deg == pytest.approx(40.5, abs=1e-4)
        assert "node 6" in inp.device and "input encoder" in inp.device
    finally:
        out.close()
        inp.close()
        network.close()
        for face in faces:
            face.stop()


def test_over_slcan_socket_in_process(node: EncoderNode, plant: RampPlant, channel: str) -> None:
    with SlcanAdapter(channel=channel) as adapter:
        bus = CanBusConfig(interface="slcan", channel=adapter.address, sync_period_s=0.01,
                           bus_options={"sleep_after_open": 0})
        with CanopenEncoder(make_config(channel, bus=bus)) as enc:
            plant.output_angle_deg = -2.0
            wait_for(lambda: enc.read().counts == expected_counts(-2.0), what="-2 deg over slcan")
            assert enc.identity().counts_per_rev == CPR
            assert enc.errors().error_register == 0


# -- faults from the backdoor -----------------------------------------------------------------
def test_heartbeat_loss_is_a_disconnect_within_three_periods(
    encoder: CanopenEncoder, node: EncoderNode
) -> None:
    encoder.read()
    assert encoder.health().heartbeat_age_s is not None
    node.backdoor.lose_heartbeat()
    exc, waited = wait_for_error(encoder, DeviceDisconnected)
    assert "heartbeat every 100 ms" in str(exc) and "node 5" in str(exc)
    assert waited < 3 * 0.100 + 0.25  # 2.5 periods by design; slack for a loaded machine
    node.backdoor.lose_heartbeat(False)
    wait_for(lambda: encoder.health().ok, what="recovery after the heartbeat returns")


def test_a_pc_reading_the_bus_late_is_no_heartbeat_loss(node: EncoderNode,
                                                         channel: str) -> None:
    """A PC that reads the bus slower than it fills (40 frames/s against 100 PDOs and 10
    heartbeats a second) gets every frame late and in order, heartbeats 0.28 s apart by its
    clock: more than 2.5 periods of 100 ms, and a loaded CI machine tripped healthy runs on
    that. While PDOs come, the heartbeat is judged on the node's time they span; a heartbeat
    really lost is still found."""
    with SlcanAdapter(channel=channel) as adapter:
        bus = CanBusConfig(interface="slcan", channel=adapter.address, sync_period_s=0.01,
                           bus_options={"sleep_after_open": 0})
        with CanopenEncoder(make_config(channel, bus=bus, heartbeat_ms=100,
                                        missed_periods=20)) as enc:
            enc.read()
            adapter.backdoor.throttle(40.0)
            arrivals: list[float] = []
            t_end = time.monotonic() + 2.0
            last = enc.health().heartbeat_age_s
            while time.monotonic() < t_end:
                enc.read()  # raises a heartbeat fault if one is judged lost
                age = enc.health().heartbeat_age_s
                if age is not None and last is not None and age < last:
                    arrivals.append(time.monotonic())
                last = age
                time.sleep(0.005)
            gaps = np.diff(arrivals)
            assert gaps.size >= 3 and np.median(gaps) > 0.25, gaps  # late by the PC's clock
            node.backdoor.lose_heartbeat()
            exc, _ = wait_for_error(enc, DeviceDisconnected, timeout_s=10.0)
            assert "heartbeat every 100 ms" in str(exc)
            adapter.backdoor.throttle(None)


def test_silence_is_a_timeout(encoder: CanopenEncoder, node: EncoderNode) -> None:
    node.backdoor.silence()
    exc, waited = wait_for_error(encoder, DeviceTimeout)
    assert "position PDO every 10 ms" in str(exc)
    assert waited < 20 * 0.010 + 0.5
    assert not encoder.health().ok
    node.backdoor.silence(False)
    wait_for(lambda: encoder.health().ok, what="recovery after silence")


def test_delay_longer_than_the_limit_is_a_timeout(
    encoder: CanopenEncoder, node: EncoderNode
) -> None:
    node.backdoor.delay(0.4)
    exc, _ = wait_for_error(encoder, DeviceTimeout)
    assert "none for" in exc.got
    node.backdoor.delay(0.0)


def test_wrong_dlc_is_a_protocol_error_once(encoder: CanopenEncoder, node: EncoderNode) -> None:
    node.backdoor.wrong_dlc(1)
    exc, _ = wait_for_error(encoder, DeviceProtocolError)
    assert "with 2 bytes" in exc.got and "0x185" in exc.got
    seq = encoder.read().seq  # reported once, then samples go on
    wait_for(lambda: encoder.read().seq > seq + 3, what="samples after the bad frame")
    assert encoder.health().protocol_errors == 1


def test_stuck_value_is_seen_by_health(plant: RampPlant, node: EncoderNode, channel: str) -> None:
    moving = SweepPlant(amplitude_deg=1.0, period_s=2.0)
    node.plant = moving
    with CanopenEncoder(make_config(channel, stuck_after_s=0.3)) as enc:
        wait_for(lambda: (h := enc.health()).unchanged_s is not None and h.unchanged_s < 0.1,
                 what="a moving position")
        node.backdoor.stick()
        exc, waited = wait_for_error(enc, DeviceFault)
        assert "unchanged" not in exc.expected and "counts for" in exc.got
        assert enc.health().unchanged_s > 0.3
        node.backdoor.stick(False)
        wait_for(lambda: enc.health().ok, what="moving again")


def test_emergency_is_a_fault_with_error_fields(encoder: CanopenEncoder, node: EncoderNode) -> None:
    node.backdoor.emergency(0x7300, 0x01)
    exc, _ = wait_for_error(encoder, DeviceFault)
    assert "EMCY" in exc.got and "7300" in exc.got
    errors = encoder.errors()
    assert errors.error_register == 0x01
    assert errors.error_codes == (0x7300,)
    assert errors.active_emergencies


def test_node_leaving_operational_is_a_fault(encoder: CanopenEncoder, node: EncoderNode) -> None:
    node.local.nmt.state = "PRE-OPERATIONAL"  # the device drops out by itself
    exc, _ = wait_for_error(encoder, DeviceFault)
    assert exc.expected == "NMT state OPERATIONAL" and "PRE-OPERATIONAL" in exc.got


def test_slcan_faults(node: EncoderNode, channel: str) -> None:
    with SlcanAdapter(channel=channel) as adapter:
        bus = CanBusConfig(interface="slcan", channel=adapter.address, sync_period_s=0.01,
                           bus_options={"sleep_after_open": 0})
        with CanopenEncoder(make_config(channel, bus=bus, heartbeat_ms=200)) as enc:
            adapter.backdoor.garble(1, "bad_hex")
            exc, _ = wait_for_error(enc, DeviceProtocolError)
            assert "garbled frame" in exc.got
            adapter.backdoor.garble(1, "wrong_dlc")
            exc, _ = wait_for_error(enc, DeviceProtocolError)
            assert "with 3 bytes" in exc.got or "garbled" in exc.got
            seq = enc.read().seq
            wait_for(lambda: enc.read().seq > seq + 3, what="samples after garbage")
            adapter.backdoor.unplug()
            exc, waited = wait_for_error(enc, DeviceDisconnected)
            assert "heartbeat" in exc.expected and waited < 3 * 0.2 + 0.25
            adapter.backdoor.unplug(False)
            wait_for(lambda: enc.health().ok, what="plugged in again")
            adapter.backdoor.disconnect()
            exc, waited = wait_for_error(enc, DeviceDisconnected)
            assert "CAN link" in exc.expected
            with pytest.raises(DeviceDisconnected):  # queued samples first, then the fault
                while enc.readings():
                    pass


# -- configuration and EDS --------------------------------------------------------------------
def test_wrong_resolution_is_refused(node: EncoderNode, channel: str) -> None:
    enc = CanopenEncoder(make_config(channel, counts_per_rev=4096))
    with pytest.raises(DeviceProtocolError, match="4096 counts/rev"):
        enc.start()


def test_absent_node_is_a_timeout(node: EncoderNode, channel: str) -> None:
    enc = CanopenEncoder(make_config(channel, node_id=9, timeout_s=0.2))
    with pytest.raises(DeviceTimeout, match="node 9.*SDO reply"):
        enc.start()


def test_not_an_encoder_is_refused(plant: RampPlant, channel: str, tmp_path: Path) -> None:
    eds = tmp_path / "drive.eds"
    cia402 = DEFAULT_EDS.read_text().replace("=0x00020196", "=0x00020192")  # a drive, not 406
    eds.write_text(cia402)
    face = EncoderNode(plant, node_id=5, channel=channel, eds=eds)
    face.start()
    try:
        with pytest.raises(DeviceProtocolError, match="0x00020192"):
            CanopenEncoder(make_config(channel)).start()
    finally:
        face.stop()


def rich_od() -> canopen.ObjectDictionary:
    """The shipped OD plus what a full vendor device carries: 4 TPDOs, an RPDO, CiA 406
    status objects 0x6500-0x650B and 200 manufacturer objects."""
    od = canopen.import_od(str(DEFAULT_EDS), 5)
    for n in (1, 2, 3):
        com = canopen.objectdictionary.ODRecord(f"TPDO{n + 1} communication parameter", 0x1800 + n)
        for sub, name, dtype, default in (
            (0, "Highest sub-index supported", 0x05, 5),
            (1, "COB-ID", 0x07, 0x80000180 + 0x100 * n),
            (2, "Transmission type", 0x05, 254),
            (3, "Inhibit time", 0x06, 0),
            (5, "Event timer", 0x06, 0),
        ):
            var = canopen.objectdictionary.ODVariable(name, 0x1800 + n, sub)
            var.data_type, var.access_type, var.default = dtype, "rw", default
            com.add_member(var)
        od.add_object(com)
        mapping = canopen.objectdictionary.ODRecord(f"TPDO{n + 1} mapping parameter", 0x1A00 + n)
        for sub in range(9):
            var = canopen.objectdictionary.ODVariable(f"Mapped object {sub}", 0x1A00 + n, sub)
            var.data_type = 0x05 if sub == 0 else 0x07
            var.access_type, var.default = "rw", 0
            mapping.add_member(var)
        od.add_object(mapping)
    for index, name, dtype in (
        (0x6500, "Operating status", 0x06), (0x6501, "Singleturn resolution", 0x07),
        (0x6502, "Number of distinguishable revolutions", 0x06), (0x6503, "Alarms", 0x06),
        (0x6504, "Supported alarms", 0x06), (0x6505, "Warnings", 0x06),
        (0x6506, "Supported warnings", 0x06), (0x6507, "Profile and software version", 0x07),
        (0x6508, "Operating time", 0x07), (0x6509, "Offset value", 0x04),
        (0x650B, "Serial number", 0x07),
    ):
        var = canopen.objectdictionary.ODVariable(name, index)
        var.data_type, var.access_type, var.default = dtype, "ro", 0
        od.add_object(var)
    for i in range(200):
        var = canopen.objectdictionary.ODVariable(f"Vendor parameter {i}", 0x2000 + i)
        var.data_type, var.access_type, var.default = 0x07, "rw", i
        od.add_object(var)
    return od


VENDOR_EXTRA = """
[Comments]
Lines=2
Line1=Vendor style: manufacturer objects, compact arrays, strings and a domain
Line2=Generated for the backlash-rig tests

[ManufacturerObjects]
SupportedObjects=4
1=0x2000
2=0x2001
3=0x2100
4=0x2200

[2000]
ParameterName=Customer name
ObjectType=0x7
DataType=0x0009
AccessType=rw
DefaultValue=ACME gears
PDOMapping=0
ObjFlags=0x0

[2001]
ParameterName=Firmware image
ObjectType=0x2
DataType=0x000F
AccessType=rw
PDOMapping=0

[2100]
ParameterName=Linearisation table
ObjectType=0x8
DataType=0x0008
AccessType=rw
CompactSubObj=16
PDOMapping=0

[2200]
ParameterName=Filter settings
ObjectType=0x9
SubNumber=3

[2200sub0]
ParameterName=Highest sub-index supported
ObjectType=0x7
DataType=0x0005
AccessType=ro
DefaultValue=2
PDOMapping=0

[2200sub1]
ParameterName=Cut-off frequency
ObjectType=0x7
DataType=0x0006
AccessType=rw
LowLimit=10
HighLimit=5000
DefaultValue=1000
PDOMapping=0

[2200sub2]
ParameterName=Filter order
ObjectType=0x7
DataType=0x0005
AccessType=rw
LowLimit=1
HighLimit=4
DefaultValue=2
PDOMapping=0
"""


def vendor_eds_text() -> str:
    text = DEFAULT_EDS.read_text()
    head, _, tail = text.partition("[ManufacturerObjects]\nSupportedObjects=0\n")
    head = head.replace("[Comments]\nLines=0\n", "")
    return head + tail + VENDOR_EXTRA


@pytest.mark.parametrize("kind", ["exported-rich", "vendor-style"])
def test_vendor_eds_with_more_objects_loads(
    kind: str, plant: RampPlant, channel: str, tmp_path: Path
) -> None:
    eds = tmp_path / f"{kind}.eds"
    if kind == "exported-rich":
        canopen.export_od(rich_od(), str(eds), doc_type="eds")
    else:
        eds.write_text(vendor_eds_text())
    od = canopen.import_od(str(eds), 5)
    assert len(od) > len(canopen.import_od(str(DEFAULT_EDS), 5))
    face = EncoderNode(plant, node_id=5, channel=channel, eds=eds)
    face.start()
    try:
        with CanopenEncoder(make_config(channel, eds=eds)) as enc:
            plant.output_angle_deg = 3.0
            wait_for(lambda: enc.read().counts == expected_counts(3.0), what="3 deg")
            assert enc.identity().counts_per_rev == CPR
            if kind == "vendor-style":
                node = enc.network.canopen[5]
                assert node.sdo[0x2200][1].raw == 1000
                assert node.sdo[0x2000].raw == "ACME gears"
    finally:
        face.stop()


def test_config_from_toml_and_its_errors(tmp_path: Path) -> None:
    good = tmp_path / "rig.toml"
    good.write_text(
        '[devices.encoder]\nname = "output encoder"\nnode_id = 5\nheartbeat_ms = 50\n'
        '[devices.encoder.bus]\ninterface = "slcan"\nchannel = "socket://127.0.0.1:15030"\n'
        'sync_period_s = 0.001\nbus_options = { sleep_after_open = 0 }\n'
    )
    cfg = encoder_config_from_toml(good, "devices.encoder")
    assert cfg.node_id == 5 and cfg.bus.interface == "slcan" and cfg.heartbeat_ms == 50
    bad = tmp_path / "bad.toml"
    bad.write_text("[encoder]\nnode_id = 300\nheartbeat = 5\n")
    with pytest.raises(ValueError, match=r"bad\.toml.*encoder\.node_id.*encoder\.heartbeat"):
        encoder_config_from_toml(bad)
    with pytest.raises(ValueError, match=r"bad\.toml: no table \[rig\]"):
        encoder_config_from_toml(bad, "rig")


def test_bad_interface_is_a_disconnect(channel: str) -> None:
    bus = CanBusConfig(interface="slcan", channel="socket://127.0.0.1:1",
                       bus_options={"sleep_after_open": 0})
    with pytest.raises(DeviceDisconnected, match="CAN bus slcan"):
        CanopenEncoder(make_config(channel, bus=bus)).start()
