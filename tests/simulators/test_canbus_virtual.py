"""simulators.canbus.virtual: the simulated rig's virtual CAN bus copies each frame per
receiver like python-can's VirtualBus (same fields, its own data), shares its channel with
plain virtual buses, and does it without ``deepcopy``."""

from __future__ import annotations

import uuid

import can
from can.interfaces.virtual import VirtualBus

from simulators.canbus.virtual import CopyingVirtualBus, virtual_bus


def test_every_receiver_gets_its_own_copy_with_the_fields_python_can_gives() -> None:
    channel = f"copy-{uuid.uuid4().hex[:8]}"
    ours = virtual_bus(channel, preserve_timestamps=True)
    plain_sender = VirtualBus(channel=channel, preserve_timestamps=True)
    receivers = [VirtualBus(channel=channel), CopyingVirtualBus(channel=channel)]
    try:
        msg = can.Message(timestamp=123.5, arbitration_id=0x181, is_extended_id=False,
                          data=bytearray(b"\x01\x02\x03\x04"))
        ours.send(msg)
        plain_sender.send(msg)
        for bus in receivers:
            mine, theirs = bus.recv(1.0), bus.recv(1.0)
            assert mine is not None and theirs is not None
            assert mine.equals(theirs, timestamp_delta=None, check_channel=True)
            assert mine.timestamp == theirs.timestamp == 123.5 and mine.is_rx
            assert mine.data == msg.data and mine.data is not msg.data
        msg.data[0] = 0xFF  # the sender's buffer is not the receivers'
        assert plain_sender.recv(0.2).data[0] == 0x01  # our frame, to the plain bus too
        assert ours.recv(0.2).data[0] == 0x01  # the plain bus's frame: no own echo
    finally:
        for bus in [ours, plain_sender, *receivers]:
            bus.shutdown()
