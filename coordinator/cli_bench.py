"""CLI ``hysid bench <name> [--json]``: the benchmarks of ``coordinator/bench/<name>.py``.

To add a bench, write ``coordinator/bench/<name>.py`` with ``run() -> dict``
(JSON-serializable results; its docstring is the command's help) and
``to_text(result) -> str``, then add one line below: ``add_bench("<name>",
<module>.run, <module>.to_text)``. Every bench prints text, or with ``--json``
one JSON object that also carries ``date``, ``machine``, ``python`` and
``numpy``; ``bench/run.sh`` runs them all and stores that JSON under
``bench/results/``.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import typer

from coordinator.bench import environment
from coordinator.bench import accuracy as accuracy_bench
from coordinator.bench import islands as islands_bench
from coordinator.bench import objective as objective_bench

bench_app = typer.Typer(no_args_is_help=True, rich_markup_mode=None)


@bench_app.callback()
def bench_root() -> None:
    """Benchmarks (speed as ratios measured in one run); --json for machine-readable results."""


def add_bench(name: str, run: Callable[[], dict[str, Any]], to_text: Callable[[dict[str, Any]], str]) -> None:
    """Register ``hysid bench <name> [--json]``."""

    def command(as_json: bool = typer.Option(False, "--json", help="Print one JSON object (with date and machine) instead of text.")) -> None:
        result = run()
        if as_json:
            print(json.dumps({**result, **environment()}, indent=2))
        else:
            print(to_text(result))

    bench_app.command(name, help=(run.__doc__ or name).strip().splitlines()[0])(command)


add_bench("objective", objective_bench.run, objective_bench.to_text)
bench_app.command("accuracy")(accuracy_bench.command)
bench_app.command("islands")(islands_bench.command)


def bench_names() -> list[str]:
    """Names of the registered benches (``bench/run.sh`` runs them all)."""
    return [info.name for info in bench_app.registered_commands]


def register(app: typer.Typer) -> None:
    """Add ``hysid bench ...`` to the hysid app."""
    app.add_typer(bench_app, name="bench")
