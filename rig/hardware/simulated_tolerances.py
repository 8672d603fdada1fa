"""How a simulated rig's devices are read: more tolerant than a real rig's configuration.

The simulators share a (possibly loaded, 2-core) machine with the measuring process, a
database server and a browser; a scheduling stall there is not a lost device. A real rig
keeps its configuration's values.
"""

SIMULATED_HEARTBEAT_MS = 500
"""Encoder heartbeat period a simulated rig is read with, ms (fault after 3 missed: 1.5 s),
instead of a real rig's 100 ms (0.25 s)."""
SIMULATED_MISSED_PERIODS = 400
"""SYNC periods a simulated encoder's position PDO may be missing (1.6 s at 4 ms)."""
