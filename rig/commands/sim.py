"""``rig sim``: run the whole simulated rig (plant + every protocol face) as a process."""

from __future__ import annotations

import json
import os
import sys
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from rig.commands.options import in_range
from rig.core.ranges import SEED, SIM_SYNC_PERIOD_S, STREAM_RATE_HZ


class _Transducer(StrEnum):
    pty = "pty"
    tcp = "tcp"


class _Modbus(StrEnum):
    tcp = "tcp"
    rtu_tcp = "rtu-tcp"


def register(app: typer.Typer) -> None:
    @app.command(short_help="Start the simulated rig on 127.0.0.1.")
    def sim(
        config: Annotated[Path | None, typer.Option(
            "--config", help="Plant TOML (default: simulators/default_plant.toml).")] = None,
        port_base: Annotated[int | None, typer.Option(
            help="Fixed ports: Modbus on BASE, SLCAN on BASE+1, transducer (tcp) on BASE+2. "
                 "Default: free ports.")] = None,
        transducer: Annotated[_Transducer, typer.Option(
            help="Transducer face: a pseudo-terminal or a TCP port.")] = _Transducer.pty,
        modbus: Annotated[_Modbus, typer.Option(
            help="Modbus face: Modbus TCP or RTU frames over TCP.")] = _Modbus.tcp,
        seed: Annotated[int | None, typer.Option(
            callback=in_range(SEED), help="Plant noise seed.")] = None,
        input_encoder: Annotated[bool, typer.Option(
            help="Serve the input-shaft encoder (CANopen node 2).")] = True,
        rig_config: Annotated[Path | None, typer.Option(
            help="Write the rig configuration here (default: a temporary folder).")] = None,
        sync_period: Annotated[float, typer.Option(
            callback=in_range(SIM_SYNC_PERIOD_S),
            help="SYNC period written in the rig config, s.")] = 0.002,
        stream_rate: Annotated[float, typer.Option(
            callback=in_range(STREAM_RATE_HZ),
            help="Transducer stream rate written in the rig config, Hz.")] = 500.0,
        realtime_priority: Annotated[int | None, typer.Option(
            min=1, max=99, help="SCHED_FIFO priority of the simulated devices (they stand in "
            "for hardware a busy PC cannot starve), also written as [rig] realtime_priority "
            "into the rig config. Default: $RIG_SIM_REALTIME_PRIORITY, else none.")] = None,
        device_priority: Annotated[int | None, typer.Option(
            min=1, max=99, help="SCHED_FIFO priority of the simulated devices only (the rig "
            "config leaves the measuring program on the normal scheduler): for load tests of "
            "the software against devices that, like hardware, a busy PC cannot starve. "
            "Default: $RIG_SIM_DEVICE_PRIORITY, else none.")] = None,
        exit_with_parent: Annotated[bool, typer.Option(
            "--exit-with-parent", help="Stop when the process that started this one is gone "
            "(a measuring program killed with -9 leaves no simulator behind).")] = False,
    ) -> None:
        """Start the simulated rig on 127.0.0.1 and serve until SIGINT/SIGTERM.

        The first output line is one JSON object: the address of every device and
        "rig_config", the rig configuration file that connects to them.
        """
        from rig.core.process_exit import prepare_exit
        from rig.hardware.simrig import SimulatedRig, serve_until_signalled
        from simulators.plant.config import PlantConfigError

        try:
            sim_rig = SimulatedRig(config, in_process=True, transducer=transducer.value,
                                   modbus=modbus.value, port_base=port_base, seed=seed,
                                   input_encoder=input_encoder, rig_config_path=rig_config,
                                   sync_period_s=sync_period, stream_rate_Hz=stream_rate,
                                   realtime_priority=realtime_priority,
                                   device_priority=device_priority)
            addresses = sim_rig.start()
        except (PlantConfigError, ValueError, OSError) as exc:  # bad file, port taken, ...
            for line in str(exc).splitlines():
                print(f"rig: error: {line}", file=sys.stderr)
            raise typer.Exit(2) from exc
        from rig.core.realtime import apply_realtime_priority

        apply_realtime_priority(sim_rig.realtime_priority or sim_rig.device_priority,
                                what="simulated rig")
        print(json.dumps(addresses), flush=True)
        code = serve_until_signalled(sim_rig,
                                     parent_pid=os.getppid() if exit_with_parent else None)
        prepare_exit()  # the devices are stopped; a parent waits for this process to end
        raise typer.Exit(code)
