"""``rig measure``: one hysteresis run on the real or the simulated rig, into the store.

Exit codes (scripts rely on them): 0 every limit passed (outcome OK, or NO LIMITS when none
was set), 1 a limit failed (NOT OK), 2 an error or an incomplete run (bad input, a device
fault, an aborted run, a limited metric that could not be measured).
"""

from __future__ import annotations

import json
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from rig.store.options import (
    DEFAULT_STORE,
    STORE_HELP,  # noqa: F401 (imported from here by other commands)
    SamplesOption,
    StoreOption,
)

if TYPE_CHECKING:
    from rig.engine.events import ProgressEvent


def console() -> Console:
    return Console(stderr=True, width=None if sys.stderr.isatty() else 120)


@contextmanager
def progress_bar(out: Console, total_s: float):
    """A rich progress bar over the plan's estimated time; yields the engine callback."""
    columns = (TextColumn("{task.description}"), BarColumn(),
               TextColumn("step {task.fields[step]}/{task.fields[n]}"), TimeRemainingColumn())
    with Progress(*columns, console=out, transient=False) as bar:
        task = bar.add_task("starting", total=max(total_s, 1e-3), step=0, n=0)

        def on_event(event: ProgressEvent) -> None:
            done = max(0.0, total_s - event.remaining_s)
            label = event.run_label or ""
            if event.kind == "step":
                bar.update(task, completed=done, step=event.step + 1, n=event.n_steps,
                           description=f"{label} {event.description}".strip()[:60])
            elif event.kind in ("run_finished", "fault", "abort", "estop", "paused",
                                "resumed"):
                style = "red" if event.kind in ("fault", "abort", "estop") else "green"
                bar.console.print(f"[{style}]{event.message}[/{style}]")
                _print_run(bar.console, event.data)
            elif event.kind == "finished":
                bar.update(task, completed=total_s if event.state == "completed" else done)

        yield on_event


def _print_run(out: Console, data: dict[str, Any]) -> None:
    if not data or data.get("status") != "completed":
        return
    if data.get("te_raw") is not None:
        _print_te(out, data)
        return

    def f(key: str, digits: int = 3) -> str:
        value = data.get(key)
        u = (data.get("uncertainty") or {}).get(key)
        if value is None:
            return "n/a"
        return f"{value:.{digits}f}" + (f" ± {u:.{digits}f}" if u is not None else "")

    model = data.get("model") or {}
    m = model.get("lost_motion_arcmin")
    verdict = f"{outcome_markup(data['outcome'])}: " if data.get("outcome") else ""
    out.print(f"  {verdict}lost motion {f('lost_motion_arcmin')} arcmin"
              + (f" (model {m:.3f})" if m is not None else "")
              + f", backlash {f('backlash_arcmin')} arcmin, stiffness "
              f"{f('stiffness_Nm_per_arcmin', 2)} N·m/arcmin")


def _print_te(out: Console, data: dict[str, Any]) -> None:
    """A transmission error run's raw figures (rig/results/te_curve.py: nothing removed)."""
    raw = data.get("te_raw") or {}

    def f(key: str, unit: str) -> str:
        value = raw.get(key)
        return "n/a" if value is None else f"{value:.1f} {unit}"

    verdict = f"{outcome_markup(data['outcome'])}: " if data.get("outcome") else ""
    pp, u = data.get("te_pp_arcsec"), data.get("te_pp_arcsec_u")
    if pp is not None:
        hyst = data.get("te_hysteresis_arcmin")
        out.print(f"  {verdict}TE peak-to-peak {pp:.1f}" + (f" ± {u:.1f}" if u is not None else "")
                  + " arcsec (the run's analysis, docs/transmission-error.md)"
                  + (f", hysteresis {hyst:.3f} arcmin" if hyst is not None else ""))
        verdict = ""
    out.print(f"  {verdict}TE peak-to-peak (raw) {f('pp_arcsec', 'arcsec')}: forward "
              f"{f('pp_forward_arcsec', 'arcsec')}, reverse {f('pp_reverse_arcsec', 'arcsec')}"
              f"; hysteresis {f('hysteresis_arcmin', 'arcmin')}")


TESTS = {"lost-motion": "lost_motion", "transmission-error": "transmission_error"}
"""``rig measure --test`` values and the run.json ``test.kind`` each measures."""


OUTCOME_STYLE = {"ok": "green", "not_ok": "red", "incomplete": "yellow"}
"""How the CLI colours an outcome's word (the words: rig/results/outcome.py)."""


def outcome_markup(code: str | None) -> str:
    """The outcome's word (rig/results/outcome.py, the one vocabulary) in its colour, rich
    markup."""
    from rich.markup import escape

    from rig.results.outcome import outcome_word

    word = escape(outcome_word(code))
    style = OUTCOME_STYLE.get(code or "")
    return f"[{style}]{word}[/{style}]" if style else word


def print_outcome(out: Console, result: dict[str, Any]) -> None:
    """``outcome: WORD (what it means)`` and each cause on its own indented line."""
    from rich.markup import escape

    from rig.results.outcome import OUTCOME_MEANINGS

    code = result.get("outcome")
    meaning = OUTCOME_MEANINGS.get(code or "")
    out.print(f"outcome: {outcome_markup(code)}" + (f" ({meaning})" if meaning else ""))
    for cause in result.get("failures") or []:
        out.print(f"  {escape(cause)}")


def exit_code(code: str | None) -> int:
    """0 OK or NO LIMITS (nothing failed), 1 NOT OK, 2 INCOMPLETE (no verdict)."""
    return {"ok": 0, "no_limits": 0, "not_ok": 1}.get(code or "", 2)


def write_json(path: Path, payload: dict[str, Any]) -> None:
    from rig.core.json_files import finite_for_json

    text = json.dumps(finite_for_json(payload), indent=2, allow_nan=False,
                      ensure_ascii=False) + "\n"
    if str(path) == "-":
        sys.stdout.write(text)
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")


def register(app: typer.Typer) -> None:
    @app.command()
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
        json_file: Annotated[Path | None, typer.Option(
            "--json", help="Write the run's metrics, status and reason as JSON ('-': stdout).")
        ] = None,
        preview: Annotated[bool, typer.Option(
            "--preview", help="List the plan's steps and its duration; measure nothing.")
        ] = False,
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
    ) -> None:
        """Measure one hysteresis loop (GB/T order -T -> 0 -> +T -> 0 -> -T), or with --test
        transmission-error the transmission error in both directions, into the store."""
        from pydantic import ValidationError

        from rig.core.errors import RigError
        from rig.measurement.service import (
            measure_plan,
            open_session,
            plant_config_for,
            run_meta,
            run_result,
        )
        from rig.plans import LoopParams, hysteresis_plan
        from rig.plans.campaign_file import Limits
        from rig.plans.estimate import estimate
        from rig.store import Store
        from simulators.plant.config import PlantConfigError, load_plant_config

        out = console()
        if test not in TESTS:
            raise RigError(f"--test: expected one of {', '.join(TESTS)}, got {test!r}")
        unit_data: dict[str, Any] = {}
        if unit is not None:
            from rig.core.json_files import read_json_file

            unit_data = read_json_file(unit, RigError, "unit data")
            if not isinstance(unit_data, dict):
                raise RigError(f"{unit}: the unit data must be a JSON object")
        try:
            loop = LoopParams(
                rated_torque_Nm=rated_torque, amplitude_pct=amplitude, mode=mode,
                rate_Nm_per_s=rate, steps_per_quarter=steps, dwell_s=dwell, cycles=cycles,
                pre_cycles=pre_cycles, zero_band_Nm=zero_band,
                zero_rate_Nm_per_s=zero_rate if zero_band > 0 else None,
                extra_levels_pct=[3.0] if extra_level is None else list(extra_level))
            limits = Limits(lost_motion_arcmin_max=max_lost_motion,
                            backlash_arcmin_max=max_backlash,
                            stiffness_Nm_per_arcmin_min=min_stiffness)
        except ValidationError as exc:
            raise RigError("; ".join(f"--{'-'.join(str(p) for p in e['loc'])}: {e['msg']}"
                                     for e in exc.errors())) from exc
        if TESTS[test] == "transmission_error":
            plan = _te_plan(rated_torque, speed, brake, revolutions, ratio,
                            unit_data or (load_plant_config(plant).unit if plant is not None
                                          else load_plant_config().unit))
        else:
            plan = hysteresis_plan(loop, position)
        est = estimate(plan.steps())
        if preview:
            for line in plan.listing():
                out.print(line, highlight=False)
            out.print(f"{est.n_steps} steps, 1 run, about {est.total_s:.1f} s "
                      f"({est.dwell_s:.1f} s dwelling)")
            return
        if serial:
            unit_data["serial"] = serial
        if operator is not None and not operator.strip():
            raise RigError("--operator: must not be empty")
        if calibration_override is not None and not calibration_override.strip():
            raise RigError("--calibration-override: give the reason (it is recorded)")
        plant_cfg = None
        if simulated:
            try:
                plant_cfg = (load_plant_config(plant) if plant is not None
                             else plant_config_for(unit_data or load_plant_config().unit))
            except PlantConfigError as exc:
                raise RigError(str(exc)) from exc
            if not unit_data:
                unit_data = dict(plant_cfg.unit)
        if rig is not None:  # an expired calibration is refused before the rig is opened
            from rig.hardware.calibration import calibration_meta
            from rig.hardware.config import load_rig_config

            calibration_meta(load_rig_config(rig).calibration, calibration_override)
        st = Store(store, samples=samples)
        with open_session(rig=rig, simulated=simulated, plant=plant_cfg) as session, \
                progress_bar(out, est.total_s) as on_event:
            from analysis.loop import PROFILES
            from rig.engine import EngineOptions
            from rig.measurement.service import simulated_truth

            options = EngineOptions(profile=profile, stale_timeout_s=session.stale_timeout_s,
                                    limits=limits.model_dump(),
                                    run_meta=simulated_truth(
                                        session, PROFILES.get(profile, 3.0), rated_torque,
                                        [position if position is not None else 0.0]))
            meta = run_meta(unit_data, session, operator and operator.strip(),
                            calibration_override)
            try:
                engine, outcomes = measure_plan(session, st, plan, meta,
                                                options=options, progress=on_event)
            except KeyboardInterrupt:
                out.print("[red]interrupted: the rig is in its safe state; the run is kept "
                          "as aborted[/red]")
                raise typer.Exit(2) from None
        if not outcomes:
            raise RigError(f"no run was recorded: {engine.stopping_reason}")
        result = run_result(outcomes[-1].to_dict(), limits)
        if json_file is not None:
            write_json(json_file, result)
        out.print(f"run {result['run_id']} {result['status']} in {st.root}")
        if result["status"] != "completed":
            out.print(f"[red]aborted: {result['reason']}[/red]")
            print_outcome(out, result)
            raise typer.Exit(2)
        for note in result["not_applicable"]:
            out.print(f"n/a {note}")
        print_outcome(out, result)
        raise typer.Exit(exit_code(result["outcome"]))


def _te_plan(rated_torque: float, speed: float, brake: float, revolutions: float,
             ratio: float | None, unit: dict[str, Any]) -> Any:
    """The transmission error plan of ``rig measure --test transmission-error``."""
    from pydantic import ValidationError

    from rig.core.errors import RigError
    from rig.plans import TEParams, te_plan, unit_ratio

    if ratio is None:
        ratio = unit_ratio(unit)
        if ratio is None:
            raise RigError("--ratio: the unit data do not give the reduction ratio (an "
                           "internal involute pair's z_internal and z_external); give it")
    names = {"input_speed_rpm": "speed", "brake_torque_fraction": "brake",
             "output_revolutions": "revolutions", "rated_torque_Nm": "rated-torque"}
    try:
        params = TEParams(rated_torque_Nm=rated_torque, ratio=ratio, input_speed_rpm=speed,
                          brake_torque_fraction=brake, output_revolutions=revolutions)
    except ValidationError as exc:
        raise RigError("; ".join(
            f"--{names.get(str(e['loc'][0]), str(e['loc'][0]))}: {e['msg']} "
            f"(got {e.get('input')!r})" for e in exc.errors())) from exc
    return te_plan(params)
