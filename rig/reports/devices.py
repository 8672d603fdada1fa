"""The ``rig devices`` report (rig-devices/1): each device of a rig read for a while."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rig.hardware.config import RigConfig
from rig.hardware.device_check import DeviceReport


def devices_report(config: RigConfig, rig_file: Path, seconds: float,
                   reports: list[DeviceReport]) -> dict[str, Any]:
    """The JSON document of :func:`rig.hardware.device_check.check_devices`' ``reports`` on
    the rig of ``rig_file`` read for ``seconds`` (s): healthy when every device is."""
    return {
        "format": "rig-devices/1",
        "rig_id": config.rig.rig_id,
        "rig_config": str(rig_file),
        "seconds": seconds,
        "healthy": all(r.healthy for r in reports),
        "devices": {r.name: r.to_json() for r in reports},
    }
