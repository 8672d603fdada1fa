"""``rig measure``: one hysteresis run on the real or the simulated rig, into the store.

Exit codes (scripts rely on them): 0 every limit passed (outcome OK, or NO LIMITS when none
was set), 1 a limit failed (NOT OK), 2 an error or an incomplete run (bad input, a device
fault, an aborted run, a limited metric that could not be measured).

The run is measured by :func:`rig.measurement.single_run.measure_run`; this module turns the
options into its request and prints what it measured.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from rig.commands.options import DEFAULT_STORE, SamplesOption, StoreOption, json_option
from rig.commands.output import (
    console,
    exit_2_on_ctrl_c,
    exit_code,
    print_outcome,
    progress_bar,
    write_json,
)

if TYPE_CHECKING:
    from rich.console import Console

    from rig.measurement.single_run import MeasureRequest
    from rig.plans import Plan

TESTS = {"lost-motion": "lost_motion", "transmission-error": "transmission_error"}
"""``rig measure --test`` values and the run.json ``test.kind`` each measures."""

def register(app: typer.Typer) -> None:
    @app.command(short_help="Measure a hysteresis loop or a TE run into the store.")
    def measure(
        simulated: Annotated[bool, typer.Option(
            "--simulated", help="Start the simulated rig (its own process) for the run.")
        ] = False,
        rig: Annotated[Path | None, typer.Option(
            "--rig", help="Rig configuration (TOML) of real or simulated device addresses.")
        ] = None,
        unit: Annotated[Path | None, typer.Option(
            help="Unit data (run.json 'unit' JSON); with --simulated also the plant's unit.")
        ] = None,
        serial: Annotated[str | None, typer.Option(help="Serial number of the unit.")] = None,
        operator: Annotated[str | None, typer.Option(
            help="Who measures (kept in run.json and on the certificate).")] = None,
        calibration_override: Annotated[str | None, typer.Option(
            "--calibration-override", metavar="REASON",
            help="Measure although a sensor calibration of the rig configuration is past due; "
                 "the reason is recorded in run.json with the operator and the time.")
        ] = None,
        plant: Annotated[Path | None, typer.Option(
            help="Plant TOML for --simulated (default: the default plant with --unit).")
        ] = None,
        rated_torque: Annotated[float, typer.Option(help="Rated torque, N·m.")] = 10.0,
        amplitude: Annotated[float, typer.Option(help="Loop amplitude, % of rated.")] = 100.0,
        position: Annotated[float | None, typer.Option(
            help="Lock the input (eccentric shaft) at this angle first, deg.")] = None,
        mode: Annotated[str, typer.Option(
            help="equal_torque, equal_position or constant_rate.")] = "equal_torque",
        rate: Annotated[float, typer.Option(help="Loading rate, N·m/s.")] = 25.0,
        steps: Annotated[int, typer.Option(help="Torque steps per quarter cycle.")] = 4,
        dwell: Annotated[float, typer.Option(help="Dwell at each step, s.")] = 0.05,
        cycles: Annotated[int, typer.Option(help="Recorded cycles.")] = 1,
        pre_cycles: Annotated[int, typer.Option(help="Unrecorded cycles before.")] = 1,
        zero_band: Annotated[float, typer.Option(
            help="Cross |T| below this slowly, N·m (0: off).")] = 0.3,
        zero_rate: Annotated[float, typer.Option(help="Rate inside the zero band, N·m/s.")
                             ] = 0.3,
        extra_level: Annotated[list[float] | None, typer.Option(
            help="Extra settled levels, % of rated (repeat; default 3).")] = None,
        profile: Annotated[str, typer.Option(
            help="Lost-motion band: nabtesco (±3 %) or harmonic-drive (±4 %).")] = "nabtesco",
        max_lost_motion: Annotated[float | None, typer.Option(
            help="Limit: lost motion at most this, arcmin.")] = None,
        max_backlash: Annotated[float | None, typer.Option(
            help="Limit: backlash at most this, arcmin.")] = None,
        min_stiffness: Annotated[float | None, typer.Option(
            help="Limit: stiffness at least this, N·m/arcmin.")] = None,
        store: StoreOption = DEFAULT_STORE,
        samples: SamplesOption = None,
        json_file: json_option("Write the run's metrics, status and reason as JSON") = None,
        preview: Annotated[bool, typer.Option(
            "--preview", help="List the plan's steps and its duration; measure nothing.")
        ] = False,
        confirm_long: Annotated[bool, typer.Option(
            "--confirm-long", help="Run (or preview) a plan expected to take longer than "
            "8 h (at most 30 days).")] = False,
        test: Annotated[str, typer.Option(
            "--test", help="lost-motion (the hysteresis loop) or transmission-error (the "
            "input turned at --speed under a --brake torque, both encoders recorded).")
        ] = "lost-motion",
        speed: Annotated[float, typer.Option(
            help="transmission-error: input speed, rpm.")] = 120.0,
        brake: Annotated[float, typer.Option(
            help="transmission-error: brake torque, fraction of the rated torque "
                 "(within the torque limit).")] = 0.2,
        revolutions: Annotated[float, typer.Option(
            help="transmission-error: output revolutions in each direction (>= 1).")] = 1.0,
        ratio: Annotated[float | None, typer.Option(
            help="transmission-error: signed reduction ratio (output = input / ratio; "
                 "default: the unit's, -z_external / (z_internal - z_external) for an "
                 "internal involute pair).")] = None,
        coupling_index: Annotated[float | None, typer.Option(
            "--coupling-index-deg",
            help="transmission-error: where the coupling between the output and its encoder "
                 "is indexed, deg (0 as mounted, 180 for the second run of rig "
                 "te-calibrate); recorded as test.coupling_index_deg.")] = None,
    ) -> None:
        """Measure one hysteresis loop (GB/T order -T -> 0 -> +T -> 0 -> -T), or with --test
        transmission-error the transmission error in both directions, into the store."""
        from rig.core.errors import RigError
        from rig.core.ranges import POSITION_DEG
        from rig.measurement.single_run import measure_run, open_run_session, unit_data
        from rig.plans.estimate import check_duration, estimate
        from rig.store import Store

        out = console()
        if test not in TESTS:
            raise RigError(f"--test: expected one of {', '.join(TESTS)}, got {test!r}")
        unit_mapping = unit_data(unit)
        loop, limits = _loop_and_limits(
            rated_torque=rated_torque, amplitude_pct=amplitude, mode=mode, rate_Nm_per_s=rate,
            steps_per_quarter=steps, dwell_s=dwell, cycles=cycles, pre_cycles=pre_cycles,
            zero_band_Nm=zero_band, zero_rate_Nm_per_s=zero_rate, extra_level=extra_level,
            max_lost_motion=max_lost_motion, max_backlash=max_backlash,
            min_stiffness=min_stiffness)
        te = None
        if TESTS[test] == "transmission_error":
            te = _te_params(rated_torque, speed, brake, revolutions, ratio, unit_mapping,
                            plant, coupling_index)
        if position is not None and (problem := POSITION_DEG.problem("--position", position)):
            raise RigError(problem)
        request = _request(loop, te, position, unit_mapping, limits, profile)
        est = estimate(request.plan().steps())
        check_duration(est, confirmed=confirm_long, how="--confirm-long")
        if preview:
            _print_preview(out, request.plan(), est)
            return
        request = _ready(request, serial, operator, calibration_override, simulated, plant)
        st = Store(store, samples=samples)
        st.check_writable("a measurement")  # said before the rig starts
        with open_run_session(request, rig=rig, simulated=simulated) as session, \
                progress_bar(out, est.total_s) as on_event, \
                exit_2_on_ctrl_c(out, "the run is kept as aborted"):
            measured = measure_run(request, session, st, progress=on_event)
        result = measured.result
        write_json(json_file, result)
        raise typer.Exit(_print_result(out, result, st))


def _loop_and_limits(*, rated_torque: float, extra_level: list[float] | None,
                     zero_band_Nm: float, zero_rate_Nm_per_s: float,
                     max_lost_motion: float | None, max_backlash: float | None,
                     min_stiffness: float | None, **loop: Any) -> tuple[Any, Any]:
    """The loop parameters and limits of the options; RigError naming each bad option."""
    from pydantic import ValidationError

    from rig.core.errors import RigError
    from rig.plans import LoopParams
    from rig.plans.campaign_file import Limits

    try:
        params = LoopParams(
            rated_torque_Nm=rated_torque, zero_band_Nm=zero_band_Nm,
            zero_rate_Nm_per_s=zero_rate_Nm_per_s if zero_band_Nm > 0 else None,
            extra_levels_pct=[3.0] if extra_level is None else list(extra_level), **loop)
        limits = Limits(lost_motion_arcmin_max=max_lost_motion,
                        backlash_arcmin_max=max_backlash,
                        stiffness_Nm_per_arcmin_min=min_stiffness)
    except ValidationError as exc:
        raise RigError("; ".join(
            f"--{OPTION_NAMES.get(str(e['loc'][0]), '-'.join(str(p) for p in e['loc']))}: "
            f"{str(e['msg']).removeprefix('Value error, ')} (got {e.get('input')!r})"
            for e in exc.errors())) from exc
    return params, limits


OPTION_NAMES = {
    "rated_torque_Nm": "rated-torque", "amplitude_pct": "amplitude", "rate_Nm_per_s": "rate",
    "steps_per_quarter": "steps", "dwell_s": "dwell", "pre_cycles": "pre-cycles",
    "zero_band_Nm": "zero-band", "zero_rate_Nm_per_s": "zero-rate",
    "extra_levels_pct": "extra-level", "lost_motion_arcmin_max": "max-lost-motion",
    "backlash_arcmin_max": "max-backlash", "stiffness_Nm_per_arcmin_min": "min-stiffness",
    "input_speed_rpm": "speed", "brake_torque_fraction": "brake",
    "output_revolutions": "revolutions", "coupling_index_deg": "coupling-index-deg"}
"""The ``rig measure`` option of each LoopParams / Limits / TEParams field."""


def _request(loop: Any, te: Any, position: float | None, unit: dict[str, Any], limits: Any,
             profile: str) -> MeasureRequest:
    from rig.measurement.single_run import MeasureRequest

    return MeasureRequest(loop=loop, te=te, position_deg=position, unit=unit, limits=limits,
                          profile=profile)


def _print_preview(out: Console, plan: Plan, est: Any) -> None:
    """``--preview``: the plan's steps and its duration."""
    for line in plan.listing():
        out.print(line, highlight=False)
    out.print(f"{est.n_steps} steps, 1 run, about {est.total_s:.1f} s "
              f"({est.dwell_s:.1f} s dwelling)")


def _ready(request: MeasureRequest, serial: str | None, operator: str | None,
           calibration_override: str | None, simulated: bool, plant: Path | None
           ) -> MeasureRequest:
    """The request to measure: the serial in the unit, the operator and the override
    (RigError when given empty), the simulated rig's plant."""
    from dataclasses import replace

    from rig.core.errors import RigError
    from rig.measurement.single_run import with_simulated_plant

    unit = dict(request.unit)
    if serial:
        unit["serial"] = serial
    if operator is not None and not operator.strip():
        raise RigError("--operator: must not be empty")
    if calibration_override is not None and not calibration_override.strip():
        raise RigError("--calibration-override: give the reason (it is recorded)")
    request = replace(request, unit=unit, operator=operator and operator.strip(),
                      calibration_override=calibration_override)
    return with_simulated_plant(request, plant) if simulated else request


def _print_result(out: Console, result: dict[str, Any], st: Any) -> int:
    """Where the run went, why it stopped, its verdict; the exit code."""
    out.print(f"run {result['run_id']} {result['status']} in {st.root}")
    if result["status"] != "completed":
        out.print(f"[red]aborted: {result['reason']}[/red]")
        print_outcome(out, result)
        return 2
    for note in result["not_applicable"]:
        out.print(f"n/a {note}")
    print_outcome(out, result)
    return exit_code(result["outcome"])


def _te_params(rated_torque: float, speed: float, brake: float, revolutions: float,
               ratio: float | None, unit: dict[str, Any], plant: Path | None,
               coupling_index_deg: float | None = None) -> Any:
    """The transmission error test of ``rig measure --test transmission-error``; the ratio
    by default the unit's (else the --plant's, else the default plant's)."""
    from pydantic import ValidationError

    from rig.core.errors import RigError
    from rig.measurement.single_run import default_unit
    from rig.plans import TEParams, unit_ratio

    unit = unit or default_unit(plant)
    if ratio is None:
        ratio = unit_ratio(unit)
        if ratio is None:
            raise RigError("--ratio: the unit data do not give the reduction ratio (an "
                           "internal involute pair's z_internal and z_external); give it")
    try:
        params = TEParams(rated_torque_Nm=rated_torque, ratio=ratio, input_speed_rpm=speed,
                          brake_torque_fraction=brake, output_revolutions=revolutions,
                          coupling_index_deg=coupling_index_deg)
    except ValidationError as exc:
        raise RigError("; ".join(
            f"--{OPTION_NAMES.get(str(e['loc'][0]), str(e['loc'][0]))}: "
            f"{str(e['msg']).removeprefix('Value error, ')} "
            f"(got {e.get('input')!r})" for e in exc.errors())) from exc
    return params
