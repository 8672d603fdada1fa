"""python-can's virtual bus with a cheap copy per receiver, for the simulated encoders.

:class:`can.interfaces.virtual.VirtualBus` deep-copies every frame once per receiver on its
channel; ``Message.__deepcopy__`` copies the data bytearray through ``copy``'s reduce
protocol. On the simulated rig (two encoders and the SLCAN adapter on one channel, 250
SYNCs a second) that copy was 30 % of the Python time the in-process rig held the GIL
(py-spy ``--gil``), and a rig simulated in a test's own process on a loaded CI machine fell
behind: its PDOs reached the engine up to 2 s late. :class:`CopyingVirtualBus` copies the
same fields with one constructor call (the data as a new bytearray); everything else, the
channel registry included, is python-can's, so it shares a channel with plain virtual buses.
"""

from __future__ import annotations

import queue
import time

import can
from can.interfaces.virtual import VirtualBus

__all__ = ["CopyingVirtualBus", "virtual_bus"]


class CopyingVirtualBus(VirtualBus):
    """A :class:`VirtualBus` whose ``send`` copies a frame per receiver without ``deepcopy``."""

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self._check_if_open()
        timestamp = msg.timestamp if self.preserve_timestamps else time.time()
        all_sent = True
        for bus_queue in self.channel:
            if bus_queue is self.queue and not self.receive_own_messages:
                continue
            copy = can.Message(
                timestamp=timestamp, arbitration_id=msg.arbitration_id,
                is_extended_id=msg.is_extended_id, is_remote_frame=msg.is_remote_frame,
                is_error_frame=msg.is_error_frame, channel=self.channel_id, dlc=msg.dlc,
                data=bytearray(msg.data), is_fd=msg.is_fd, is_rx=bus_queue is not self.queue,
                bitrate_switch=msg.bitrate_switch,
                error_state_indicator=msg.error_state_indicator, check=False)
            try:
                bus_queue.put(copy, block=True, timeout=timeout)
            except queue.Full:
                all_sent = False
        if not all_sent:
            raise can.CanOperationError("Could not send message to one or more recipients")


def virtual_bus(channel: str, **options: object) -> CopyingVirtualBus:
    """A :class:`CopyingVirtualBus` on ``channel`` (``options``: VirtualBus's own)."""
    return CopyingVirtualBus(channel=channel, **options)
