"""Real-time scheduling of a measuring process (optional, Linux).

A rig PC also runs a browser, reports and the diagnosis. The engine has its own process
(rig/web/engine_host.py), which the kernel's normal scheduler shares fairly with everything else;
under a load average of 5-8 on 2 cores that still leaves it waiting tens of milliseconds for
the CPU. ``[rig] realtime_priority`` (1-99) puts every thread of the measuring process under
``SCHED_FIFO``: runnable, it preempts every normal process. Measured by
``python -m bench load`` (docs/reliability.md, "What real-time priority buys").
It needs CAP_SYS_NICE (root, or ``setcap`` / a systemd unit's ``LimitRTPRIO``); without it the
process stays on the normal scheduler and says so.
"""

from __future__ import annotations

import logging
import os

__all__ = ["apply_realtime_priority"]

log = logging.getLogger(__name__)


def apply_realtime_priority(priority: int | None, *, what: str = "measuring process") -> str:
    """Put every thread of this process under SCHED_FIFO at ``priority`` (threads started
    later inherit it); one line saying what was done (also logged). None: nothing to do."""
    if priority is None:
        return "normal scheduler"
    try:
        param = os.sched_param(int(priority))
        tids = [int(t) for t in os.listdir("/proc/self/task")]
        for tid in tids:
            os.sched_setscheduler(tid, os.SCHED_FIFO, param)
    except (AttributeError, OSError, ValueError) as exc:
        message = (f"{what}: SCHED_FIFO {priority} not applied ({exc}); "
                   f"normal scheduler")
        log.warning(message)
        return message
    message = f"{what}: SCHED_FIFO priority {priority} ({len(tids)} threads)"
    log.info(message)
    return message
