"""CLI ``hysid bench <name> [--json]``: the benchmarks of ``hysid/bench/<name>.py``.

To add a bench, write ``hysid/bench/<name>.py`` with ``run(...) -> dict``
(JSON-serializable results; its docstring's first line is the command's help)
and ``to_text(result) -> str``, then register it below. Every bench prints
text, or with ``--json`` one JSON object that also carries ``date``,
``machine``, ``python`` and ``numpy``; ``bench/run.sh`` runs them all and
stores that JSON under ``bench/results/``.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

import typer

from hysid.bench import (
    accuracy,
    coordinator,
    coverage,
    diagnose,
    discovery,
    environment,
    ingest,
    interrupt,
    islands,
    objective,
    proposals,
    scale,
    search,
    shaker,
    sites,
    validation,
    write_section,
)
from hysid.bench.netns import NamespacesUnavailable
from hysid.report import jsondoc
from hysid_model.errors import HysidInputError

bench_app = typer.Typer(no_args_is_help=True, rich_markup_mode=None)
BENCH_JSON = typer.Option(False, "--json", help="Print one JSON object (with date and machine) instead of text.")


@bench_app.callback()
def bench_root() -> None:
    """Benchmarks (speed as ratios measured in one run); --json for machine-readable results."""


def emit(result: dict[str, Any], to_text: Callable[[dict[str, Any]], str], as_json: bool) -> None:
    print(jsondoc.dumps({**result, **environment()}, indent=2) if as_json else to_text(result))


@bench_app.command("objective", help=(objective.run.__doc__ or "").strip().splitlines()[0])
def objective_command(as_json: bool = BENCH_JSON) -> None:
    emit(objective.run(), objective.to_text, as_json)


@bench_app.command("accuracy")
def accuracy_command(
    seeds: int = typer.Option(accuracy.DEFAULT_SEEDS, "--seeds", help="Noise draws per noise level for the Cramer-Rao target (at least 20)."),
    thesis_runs: int = typer.Option(accuracy.THESIS_RUNS, "--thesis-runs", help="Thesis-faithful runs per algorithm and noise level (a multiple of 4)."),
    as_json: bool = BENCH_JSON,
) -> None:
    """Accuracy on the Synth set: clean to 1e-6, RMS error vs the Cramer-Rao bound, thesis-faithful vs Table 5.13."""
    emit(accuracy.run(seeds, thesis_runs), accuracy.to_text, as_json)


@bench_app.command("coverage", help=(coverage.run.__doc__ or "").strip().splitlines()[0])
def coverage_command(
    seeds: int = typer.Option(coverage.SEEDS, "--seeds", help="Noise seeds per specimen (at least 10)."),
    specimens: str = typer.Option(",".join(coverage.specimens()), "--specimens", help="Comma-separated specimens to run."),
    as_json: bool = BENCH_JSON,
) -> None:
    emit(coverage.run(seeds, tuple(s for s in specimens.split(",") if s)), coverage.to_text, as_json)


@bench_app.command("islands")
def islands_command(
    part: str = typer.Argument("all", help="speedup, migration, mixed, pygmo, latency or all."),
    as_json: bool = BENCH_JSON,
) -> None:
    """Island model: 2-island speedup, migration vs isolation, mixed vs single-algorithm islands, hysid vs pygmo, migration latency."""
    emit(islands.run(islands.PARTS if part == "all" else [part]), islands.to_text, as_json)


@bench_app.command("search", help=(search.run.__doc__ or "").strip().splitlines()[0])
def search_command(
    seeds: int = typer.Option(search.MIN_SEEDS, "--seeds", help=f"Search seeds per problem and method ({search.MIN_SEEDS} for a verdict; fewer: preliminary)."),
    quick: bool = typer.Option(False, "--quick", help="3 seeds on two problems with small budgets: the machinery, not a verdict."),
    problems: str = typer.Option(",".join(search.PROBLEMS), "--problems", help="Comma-separated problems to run."),
    methods: str = typer.Option(
        ",".join(search.METHODS), "--methods", help="Comma-separated methods to run (the verdict needs the 4-island campaign and a peer)."
    ),
    budget: int = typer.Option(search.BUDGET, "--budget", help="Evaluations of every search."),
    partial: Path | None = typer.Option(None, "--partial", help="Write the results so far to this JSON file after every problem."),
    as_json: bool = BENCH_JSON,
) -> None:
    emit(
        search.run(seeds, quick, tuple(p for p in problems.split(",") if p), tuple(m for m in methods.split(",") if m), budget=budget, partial=partial),
        search.to_text,
        as_json,
    )


@bench_app.command("validation", help=(validation.run.__doc__ or "").strip().splitlines()[0])
def validation_command(
    cases: str = typer.Option("", "--cases", help="Comma-separated cases to run (default: all)."),
    markdown: Path | None = typer.Option(
        None, "--markdown", help="Also write the table as the validation section of this Markdown file (docs/VALIDATION.md; other sections kept)."
    ),
    as_json: bool = BENCH_JSON,
) -> None:
    names = [c for c in cases.split(",") if c] or None
    known = [c.name for c in validation.cases()]
    unknown = [c for c in names or [] if c not in known]
    if unknown:
        raise HysidInputError(f"--cases: unknown case {unknown[0]!r}; choose from {', '.join(known)}")
    result = validation.run(names)
    if markdown is not None:
        write_section(markdown, "validation", validation.to_markdown(result, environment()))
    emit(result, validation.to_text, as_json)


@bench_app.command("discovery", help=(discovery.run.__doc__ or "").strip().splitlines()[0])
def discovery_command(
    quick: bool = typer.Option(False, "--quick", help=f"4 loops a specimen and {discovery.QUICK_SEEDS} control draws: the machinery, not a verdict."),
    seeds: int | None = typer.Option(None, "--seeds", help=f"Noise draws per control (default {discovery.CONTROL_SEEDS}; --quick {discovery.QUICK_SEEDS})."),
    laws: str = typer.Option(",".join(discovery.dc.LAWS), "--laws", help="Comma-separated hidden laws to run (none: '')."),
    controls: str = typer.Option(",".join(discovery.dc.CONTROLS), "--controls", help="Comma-separated controls to run (none: '')."),
    noise: str = typer.Option(
        ",".join(f"{n:g}" for n in discovery.dc.NOISE_PCT), "--noise", help="Comma-separated force noise levels of the laws, per cent of each record's peak."
    ),
    real: bool = typer.Option(True, "--real/--no-real", help="Also diagnose the real friction damper (data/arts-friction-damper) with and without discovery."),
    merge: list[Path] | None = typer.Option(None, "--merge", help="Run nothing: merge the --json output of runs of disjoint parts (repeat the option)."),
    markdown: Path | None = typer.Option(None, "--markdown", help="Also write the discovery section of this Markdown file (docs/VALIDATION.md)."),
    as_json: bool = BENCH_JSON,
) -> None:
    if merge:
        result = discovery.combined([json_file(path, "--merge") for path in merge])
    else:
        result = discovery.run(
            quick, seeds, tuple(n for n in laws.split(",") if n), tuple(n for n in controls.split(",") if n), tuple(number_list(noise, "--noise")), real=real
        )
    if markdown is not None:
        write_section(markdown, "discovery", discovery.to_markdown(result, environment()))
    emit(result, discovery.to_text, as_json)


@bench_app.command("diagnose", help=(diagnose.run.__doc__ or "").strip().splitlines()[0])
def diagnose_command(
    cases: str = typer.Option("", "--cases", help="Comma-separated cases to run (default: all; the test reads a run of all)."),
    workers: int = typer.Option(0, "--workers", help="Processes diagnosing seeds side by side (default: one per core this process may use)."),
    as_json: bool = BENCH_JSON,
) -> None:
    report = lambda done, total, what: typer.echo(f"hysid bench diagnose: {done}/{total} {what}", err=True)
    emit(diagnose.run(tuple(c for c in cases.split(",") if c), workers or None, report), diagnose.to_text, as_json)


def register_sweep(module: ModuleType) -> None:
    """``hysid bench NAME`` of a seed sweep a test reads (:func:`hysid.bench.sweep`): its progress on stderr, its result."""
    name = module.__name__.rsplit(".", 1)[-1]

    @bench_app.command(name, help=(module.run.__doc__ or "").strip().splitlines()[0])
    def sweep_command(as_json: bool = BENCH_JSON) -> None:
        report = lambda done, total, what: typer.echo(f"hysid bench {name}: {done}/{total} {what}", err=True)
        emit(module.run(report), module.to_text, as_json)


for sweep_module in (scale, proposals, shaker):
    register_sweep(sweep_module)


@bench_app.command("coordinator", help=(coordinator.run.__doc__ or "").strip().splitlines()[0])
def coordinator_command(
    part: str = typer.Argument("all", help=f"{', '.join(coordinator.PARTS)} or all."),
    seconds: float = typer.Option(10.0, "--seconds", help="Duration of the 32-island load."),
    sustain: float = typer.Option(180.0, "--sustain", help="Duration of the 32-island run whose memory is watched."),
    ramp: float = typer.Option(12.0, "--ramp-seconds", help="Duration of each step of the island ramp."),
    as_json: bool = BENCH_JSON,
) -> None:
    if part != "all" and part not in coordinator.PARTS:
        raise HysidInputError(f"unknown part {part!r}; choose from {', '.join(coordinator.PARTS)} or all")
    emit(coordinator.run(seconds, sustain, ramp, coordinator.PARTS if part == "all" else (part,)), coordinator.to_text, as_json)


@bench_app.command("ingest")
def ingest_command(
    part: str = typer.Argument("all", help="generated, large, lab, damper, daq, small or all."),
    records: int = typer.Option(ingest.RECORDS, "--records", help="Raw records of the generated set (at least 1)."),
    seconds: float = typer.Option(ingest.SECONDS, "--seconds", help="Length of each generated record in s."),
    rate: float = typer.Option(ingest.SAMPLE_RATE_HZ, "--rate", help="Sample rate of the generated records in Hz."),
    rounds: int = typer.Option(ingest.ROUNDS, "--rounds", help="Alternating rounds of parse and load per set (at least 1)."),
    as_json: bool = BENCH_JSON,
) -> None:
    """Ingestion: hysid.load of raw records (200 MB and 800 MB sets, a lab's export, the real damper, DAQ-shaped sets) against numpy's parse of the same files, and memory against the largest file."""
    emit(ingest.run(ingest.PARTS if part == "all" else [part], records, seconds, rate, rounds), ingest.to_text, as_json)


@bench_app.command("sites", help=(sites.run.__doc__ or "").strip().splitlines()[0])
def sites_command(
    time_limit: float = typer.Option(120.0, "--time-limit", help="Campaign length in s, start-up included (the cut comes 15 s after every island joined)."),
    large: bool = typer.Option(False, "--large", help="256 islands, 42-43 in each island process (hysid island --count), instead of 32 processes of one."),
    as_json: bool = BENCH_JSON,
) -> None:
    try:
        result = sites.run(time_limit, large)
    except NamespacesUnavailable as exc:
        raise HysidInputError(f"the sites bench needs network namespaces: {exc}") from None
    except RuntimeError as exc:  # a stage of the campaign that did not come in time, or a process that failed
        typer.echo(f"hysid: error: the sites bench stopped: {exc}", err=True)
        raise typer.Exit(1) from None
    emit(result, sites.to_text, as_json)


@bench_app.command("interrupt", help=(interrupt.run.__doc__ or "").strip().splitlines()[0])
def interrupt_command(
    runs: int = typer.Option(interrupt.RUNS, "--runs", help="Campaigns stopped by Ctrl-C per model."),
    as_json: bool = BENCH_JSON,
) -> None:
    try:
        result = interrupt.run(runs)
    except RuntimeError as exc:  # a campaign that did not search, say it stops or exit in time
        typer.echo(f"hysid: error: the interrupt bench stopped: {exc}", err=True)
        raise typer.Exit(1) from None
    emit(result, interrupt.to_text, as_json)


def json_file(path: Path, option: str) -> dict[str, Any]:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise HysidInputError(f"{option} {path}: not a readable JSON file ({exc})") from None


def number_list(text: str, option: str) -> list[float]:
    try:
        return [float(n) for n in text.split(",") if n.strip()]
    except ValueError:
        raise HysidInputError(f"{option}: give comma-separated numbers, not {text!r}") from None


def bench_names() -> list[str]:
    """Names of the registered benches (``bench/run.sh`` runs them all)."""
    return [info.name or "" for info in bench_app.registered_commands]


def register(app: typer.Typer) -> None:
    """Add ``hysid bench ...`` to the hysid app."""
    app.add_typer(bench_app, name="bench")
