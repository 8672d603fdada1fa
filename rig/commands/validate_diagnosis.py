"""``rig validate-diagnosis``: the diagnosis on withheld effects, ours or a labelled folder.

    rig validate-diagnosis [--cases N] [--seed S] [--jobs J] [--artifacts/--no-artifacts]
                           [--json SUMMARY.json]
    rig validate-diagnosis --kind cycloid|beveloid [--cases N] [--nulls M] [--seed S]
                           [--jobs J] [--artifacts/--no-artifacts] [--json SUMMARY.json]
    rig validate-diagnosis --cases-dir DIR --labels LABELS.json [--cases-dir ... --labels ...]
                           [--with-generator] [--jobs J] [--json SUMMARY.json]
    rig validate-diagnosis --like CAMPAIGN [--cases N] [--jobs J] [--seed S] --json FILE
    rig validate-diagnosis --over-the-wire [--cases N] [--jobs J] [--keep DIR] [--json FILE]
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.progress import Progress
from rich.table import Table

from rig.commands.options import in_range, json_option
from rig.commands.output import make_console
from rig.core.errors import RigError
from rig.core.ranges import SEED

console = make_console()


def _print_graded(summary: dict[str, Any], verbose: bool) -> None:
    """Per-effect confusion, per-category accuracy, false alarms, also, shrink, summary line."""
    from rig.validate.cases import summary_line

    name = summary["generator"]
    table = Table(title=f"{name}: confusion (true effect[+also] -> verdict[+also])")
    for col in ("true", "cases", "correct", "verdicts"):
        table.add_column(col)
    for key in sorted(summary["confusion"]):
        pe = summary["per_effect"][key]
        row = summary["confusion"][key]
        table.add_row(key, str(pe["n"]), f"{pe['correct']}/{pe['n']}", ", ".join(
            f"{v} x{n}" for v, n in sorted(row.items(), key=lambda kv: -kv[1])))
    console.print(table)
    cats = summary["per_category"]
    if len(cats) > 1 or "-" not in cats:
        console.print("by category: " + ", ".join(
            f"{c} {d['correct']}/{d['n']}" for c, d in sorted(cats.items())))
    ac = summary["also_counts"]
    console.print(f"false alarms on none: {summary['false_alarms']}/{summary['none_cases']} "
                  "(any verdict other than none, or any also entry)")
    if summary["two_effect_cases"]:
        console.print(f"also on {summary['two_effect_cases']} two-effect cases: "
                      f"{ac['listed']}/{ac['labelled']} listed, "
                      f"{ac['reported_true']}/{ac['reported']} reported entries true")
    ms = summary["median_shrink"]
    console.print(f"median shrink of correct verdicts: {'n/a' if ms is None else f'{ms:.2f}'} "
                  f"over {summary['shrinks']}; failures {summary['failures']}; median "
                  f"{summary['median_seconds_per_case'] or 0.0:.2f} s per case", soft_wrap=True)
    if verbose:
        for r in summary["results"]:
            got = (f"<{r['status']}>" if r["status"] != "ok"
                   else r["verdict"] + "".join("+" + a for a in r["also"]))
            form = f"{r['form']}/" if r.get("form") else ""
            console.print(f"  {r['case']:<16} {form + r['category']:<20} {r['truth_key']:<42} -> "
                          f"{got:<40} {'ok' if r['correct'] else '--'}"
                          + (f"  {r['error']}" if r.get("error") else ""), soft_wrap=True)
    console.print(f"[bold]{summary_line(summary)}[/bold]", soft_wrap=True)


def _ours(cases: int, seed: int, jobs: int, verbose: bool, artifacts: bool,
          nulls: int = 0) -> dict[str, Any]:
    from rig.validate import KINDS, graded_validation, meets_targets, summarise

    what = "with" if artifacts else "without"
    console.print(f"our generator, {what} a real rig's measuring-system artefacts")
    with Progress(console=console, transient=True) as progress:
        task = progress.add_task("our generator: diagnosing campaigns", total=cases + nulls)
        results, graded = graded_validation(cases, seed, jobs,
                                            progress=lambda _r: progress.advance(task),
                                            artifacts=artifacts, nulls=nulls)
    old = summarise(results)
    _print_graded(graded, verbose)
    by_form: dict[str, dict[str, int]] = {}
    for r in results:
        for key in (f"form {r.case.kind}:{r.case.form}", f"loading {r.case.loading}"):
            d = by_form.setdefault(key, {"n": 0, "correct": 0})
            d["n"] += 1
            d["correct"] += int(r.correct)
    console.print("our generator by form and loading: " + ", ".join(
        f"{k} {d['correct']}/{d['n']}" for k, d in sorted(by_form.items())), soft_wrap=True)

    def pct(x: float | None) -> str:
        return "n/a" if x is None else f"{x:.1%}"

    console.print(f"correct verdicts (in vocabulary + null): {pct(old['correct_share'])}"
                  f" (target >= 95 %); false alarms on null cases: "
                  f"{pct(old['false_alarm_share'])} (target 0); out-of-vocabulary "
                  f"unexplained/ambiguous: {pct(old['oov_unexplained_or_ambiguous_share'])}",
                  soft_wrap=True)
    console.print("targets met" if meets_targets(old) else "[red]targets NOT met[/red]")
    missing = [k for k in KINDS if k not in old["confusion"]]
    if missing:
        console.print(f"(kinds not drawn at {cases} cases: {', '.join(missing)})")
    return {**graded, "artifacts": artifacts, "seed": seed, "nulls_added": nulls,
            "by_form": by_form, "figures": old}


def _kind(kind: str, cases: int, nulls: int, seed: int, jobs: int, verbose: bool,
          artifacts: bool) -> dict[str, Any]:
    """Our generator for another unit kind (rig/validate/kinds.py): effects and nulls."""
    from rig.validate.kinds import check_kind, graded_kind_validation

    check_kind(kind)
    what = "with" if artifacts else "without"
    console.print(f"our {kind} generator (the {kind} plant), {what} a real rig's "
                  "measuring-system artefacts", soft_wrap=True)
    with Progress(console=console, transient=True) as progress:
        task = progress.add_task(f"{kind}: diagnosing campaigns", total=cases + nulls)
        _, graded = graded_kind_validation(kind, cases, nulls, seed, jobs, artifacts,
                                           progress=lambda _r: progress.advance(task))
    _print_graded(graded, verbose)
    for effect, why in graded["not_testable"].items():
        console.print(f"not withheld: {effect} ({why})", soft_wrap=True, markup=False)
    acc = graded["effect_accuracy"]
    console.print(f"{kind}: withheld effects {'n/a' if acc is None else f'{acc:.1%}'} correct "
                  f"over {graded['effect_cases']} (target >= 90 %); false alarms "
                  f"{graded['false_alarms']} of {graded['null_cases']} null campaigns (target "
                  "at most 1 in 20)", soft_wrap=True)
    console.print("targets met" if graded["targets_met"] else "[red]targets NOT met[/red]")
    return graded


def _fmt_size(size: dict[str, Any] | None) -> str:
    if not size:
        return "-"
    return ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                     for k, v in size.items() if k not in ("seed", "model"))


def print_like(summary: dict[str, Any]) -> None:
    """The self-check's confusion: per effect right/wrong and verdicts, the smallest size
    found, the false alarms on the nulls, the one summary line."""
    d = summary["design"]
    console.print(f"campaigns like {summary['campaign']}: {d['runs']} runs, twist noise "
                  f"{d['twist_noise_arcsec']:.3g} arcsec, encoder count "
                  f"{d['twist_resolution_arcsec']:.3g} arcsec, ADC count "
                  f"{d['torque_resolution_Nm']:.3g} N*m, torque lag "
                  f"{d['torque_lag_s'] * 1e3:.3g} ms",
                  soft_wrap=True)
    table = Table(title="withheld effect -> verdict[+also] (sizes in noise multiples)")
    for col in ("effect", "right", "wrong", "verdicts", "smallest found"):
        table.add_column(col)
    for kind, pe in sorted(summary["per_effect"].items()):
        best = summary["smallest_found"].get(kind)
        found = ("-" if kind == "none" else "not found" if best is None else
                 f"{best['noise_multiple']:.2g} x noise ({_fmt_size(best['size'])})")
        table.add_row(kind, str(pe["correct"]), str(pe["wrong"]), ", ".join(
            f"{v} x{n}" for v, n in sorted(pe["verdicts"].items(), key=lambda kv: -kv[1])),
            found)
    console.print(table)
    for kind, why in summary["untestable"].items():
        console.print(f"not withheld: {kind} ({why})")
    console.print(f"[bold]on {summary['cases']} campaigns like this one: right "
                  f"{summary['correct']}, false alarms {summary['false_alarms']} of "
                  f"{summary['nulls']} ({summary['seconds']:.0f} s)[/bold]", soft_wrap=True)


def _like(campaign: Path, cases: int, seed: int, jobs: int) -> dict[str, Any]:
    from rig.validate.like import self_check

    with Progress(console=console, transient=True) as progress:
        task = progress.add_task(f"campaigns like {campaign.name}: diagnosing", total=cases)
        summary = self_check(campaign, cases, jobs, seed,
                             progress=lambda _r: progress.advance(task))
    print_like(summary)
    return summary


def _over_the_wire(cases: int, seed: int, jobs: int, keep: Path | None, short: bool,
                   verbose: bool, nulls: int = 0) -> dict[str, Any]:
    """Record campaigns through the sequencer, drivers and simulated devices, then grade."""
    from rig.validate.wire import over_the_wire

    with Progress(console=console, transient=True) as progress:
        rec = progress.add_task("over the wire: recording campaigns", total=cases + nulls)
        grade = progress.add_task("over the wire: diagnosing", total=cases + nulls)

        def advance(stage: str, _r: dict[str, Any]) -> None:
            progress.advance(rec if stage == "recorded" else grade)

        summary = over_the_wire(cases, seed, jobs, keep, short, progress=advance, nulls=nulls)
    for r in summary["recordings"]:
        if r["status"] != "completed" or verbose:
            console.print(f"  recorded {r['case']}: {r['status']}, {r['runs']} runs, "
                          f"{r['record_seconds']:.0f} s" + (f" ({r['reason']})" if r.get(
                              "reason") else ""), soft_wrap=True, markup=False)
    _print_graded(summary, verbose)
    if keep is not None:
        console.print(f"recordings kept in {keep}: re-grade with rig validate-diagnosis "
                      f"--cases-dir {keep / 'cases'} --labels {keep / 'labels.json'}",
                      soft_wrap=True, markup=False)
    return summary


def register(app: typer.Typer) -> None:
    @app.command("validate-diagnosis",
                 short_help="Diagnose labelled campaigns blind and grade them.")
    def validate_diagnosis(
        cases: Annotated[int | None, typer.Option(
            min=1, help="Number of campaigns from our generator (default 33) or recorded "
            "over the wire (default 12).")] = None,
        seed: Annotated[int, typer.Option(
            callback=in_range(SEED), help="Seed of our generator's case draws.")] = 0,
        cases_dir: Annotated[list[Path] | None, typer.Option(
            "--cases-dir", help="A folder of labelled campaigns (one folder per case); "
            "repeatable, each with its --labels.")] = None,
        labels: Annotated[list[Path] | None, typer.Option(
            "--labels", help="labels.json of the --cases-dir in the same place "
            "({case_id: {effect, acceptable, also, category, ...}}).")] = None,
        like: Annotated[Path | None, typer.Option(
            "--like", help="A campaign folder: make --cases labelled campaigns with its "
            "design (positions, temperatures, torque history, sample times, unit data) and "
            "its measured noise, lag and resolution, withhold each effect it can show, "
            "diagnose them blind and print the confusion.")] = None,
        with_generator: Annotated[bool, typer.Option(
            "--with-generator", help="Also run our generator beside the --cases-dir sets.")
        ] = False,
        artifacts: Annotated[bool, typer.Option(
            "--artifacts/--no-artifacts", help="Our generator's campaigns measured through a "
            "real rig's measuring system (impacts and bounces, sensor lag, ADC grid, drive "
            "loop and ripple, drifting zero, Coulomb friction, encoder, jittered sampling with "
            "dropped rows, pre-cycles; docs/diagnosis.md), or the plant's columns.")] = True,
        kind: Annotated[str | None, typer.Option(
            "--kind", help="Our generator for another unit kind: cycloid (seed 002) or "
            "beveloid (seed 001): --cases withheld effects of the vocabulary (cycling) with "
            "min(20, cases) null campaigns of that kind's plant (--nulls adds more), graded "
            "per effect.")] = None,
        over_the_wire: Annotated[bool, typer.Option(
            "--over-the-wire", help="Record campaigns through the real sequencer, drivers and "
            "simulated devices (rig campaign run --simulated) with the rig's dynamics on and "
            "one withheld effect (or none) each, then diagnose and grade them.")] = False,
        keep: Annotated[Path | None, typer.Option(
            "--keep", help="With --over-the-wire: keep the recordings in DIR (DIR/cases/, "
            "DIR/labels.json) to grade again with --cases-dir/--labels.")] = None,
        short: Annotated[bool, typer.Option(
            "--short", help="With --over-the-wire: half the positions per campaign.")
        ] = False,
        nulls: Annotated[int, typer.Option(
            min=0, help="Add N null campaigns (no withheld effect) to our generator's or the "
            "over-the-wire cases: the false-alarm rate measured on its own (the target is at "
            "most 1 in 20).")] = 0,
        jobs: Annotated[int, typer.Option(min=1, help="Worker processes (with "
                                          "--over-the-wire: simulated rigs at a time).")] = 1,
        verbose: Annotated[bool, typer.Option("--verbose", help="One line per case.")] = False,
        json_file: json_option("Write the summary as JSON") = None,
    ) -> None:
        """Diagnose labelled campaigns blind and grade them: per-effect confusion, false alarms,
        also recall/precision, median shrink, one summary line per generator. Without
        --cases-dir: campaigns from our own generator (rig/validate/)."""
        from rig.commands.output import JsonOutput
        from rig.validate.cases import generator_name, grade_folder, summarise_graded

        json_out = JsonOutput(json_file)
        console.stderr = json_out.to_stdout  # with --json -: the tables on stderr

        if kind is not None:
            if like is not None or cases_dir or over_the_wire:
                raise RigError("--kind goes with our generator only (not with --like, "
                               "--cases-dir or --over-the-wire)")
            n = cases or 30
            json_out.write(_kind(kind, n, min(20, n) + nulls, seed, jobs, verbose, artifacts),
                           ensure_ascii=True)
            return
        if like is not None:
            if cases_dir:
                raise RigError("--like and --cases-dir: give one of them")
            json_out.write(_like(like, cases or 20, seed, jobs), ensure_ascii=True)
            return
        dirs, labs = list(cases_dir or []), list(labels or [])
        if len(dirs) != len(labs):
            raise RigError(f"--cases-dir given {len(dirs)} time(s), --labels {len(labs)}: "
                           "give one labels.json per folder of cases")
        if (keep is not None or short) and not over_the_wire:
            raise RigError("--keep and --short go with --over-the-wire")
        summaries = []
        if over_the_wire:
            summaries.append(_over_the_wire(cases or 12, seed, jobs, keep, short, verbose,
                                            nulls))
        if (not dirs and not over_the_wire) or with_generator:
            summaries.append(_ours(cases or 33, seed, jobs, verbose, artifacts,
                                   0 if over_the_wire else nulls))
        for d, lab in zip(dirs, labs, strict=True):
            name = generator_name(d)
            with Progress(console=console, transient=True) as progress:
                task = progress.add_task(f"{name}: diagnosing campaigns")
                records = grade_folder(d, lab, jobs,
                                       progress=lambda _r, t=task: progress.advance(t))
            summary = summarise_graded(name, records)
            summary["cases_dir"], summary["labels"] = str(d), str(lab)
            _print_graded(summary, verbose)
            summaries.append(summary)
        if len(summaries) > 1:
            from rig.validate.cases import summary_line

            console.print("each generator apart:")
            for s in summaries:
                console.print("  " + summary_line(s), soft_wrap=True)
        json_out.write(summaries[0] if len(summaries) == 1 else {
            "generators": {s["generator"]: s for s in summaries}}, ensure_ascii=True)
