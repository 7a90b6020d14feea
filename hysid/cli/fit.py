"""CLI commands ``hysid fit`` (single node, no network) and ``hysid reproduce thesis``."""

from __future__ import annotations

from pathlib import Path

import typer

from hysid import thesis_tables as tt
from hysid.cli import options as o
from hysid.cli.directories import report_dir
from hysid.cli.groups import LAID_OUT, Constraints, Output, Reading, grouped
from hysid.cli.progress import Progress
from hysid.fitting import fit
from hysid.report import jsondoc
from hysid.reproduce import SETTINGS, parse_seeds, reproduce_thesis
from island.run import HistoryRow

ROWS_PER_RUN = 18 + 1
"""History rows of a run with the thesis' settings: the initial population, then 18 iterations (section 5.1)."""


def register(app: typer.Typer) -> None:
    """Add ``fit`` and ``reproduce thesis`` to the hysid app."""

    @app.command("fit")
    @grouped
    def fit_command(
        dataset: str = o.DATASET,
        algo: str = o.ALGO,
        model: str = o.MODEL,
        runs: int = o.RUNS,
        seed: int = o.SEED,
        weights: str | None = o.WEIGHTS,
        output: Output = LAID_OUT,
        polish: bool = o.POLISH,
        reading: Reading = LAID_OUT,
        limits: Constraints = LAID_OUT,
    ) -> None:
        """Identify the model's parameters from DATASET in this process (no network)."""
        bounds, fixed, displacement = limits.bounds(), limits.fixed(), limits.displacement
        target = output.directory("fit")
        loops = reading.load(dataset)
        with Progress("fitting", max(runs, 1) * ROWS_PER_RUN, enabled=output.live) as progress:

            def show(i: int, row: HistoryRow) -> None:
                progress.update(i * ROWS_PER_RUN + row.iteration + 1, f"run {i + 1}/{runs}, best {row.best_fitness:.4g}")

            result = fit(
                loops,
                model,
                algo=algo,
                runs=runs,
                seed=seed,
                weights=weights,
                polish=polish,
                bounds=bounds,
                fixed=fixed,
                displacement=displacement,
                progress=show,
            )
        output.show(result, target)

    reproduce = typer.Typer(help="Regenerate the thesis' published results.", no_args_is_help=True)
    app.add_typer(reproduce, name="reproduce")

    @reproduce.command("thesis")
    def reproduce_thesis_command(
        runs: int = typer.Option(4, "--runs", help="Runs per algorithm, noise level and setting (the thesis: 4)."),
        out: Path | None = o.OUT,
        seeds_noise: str | None = typer.Option(None, "--seeds-noise", help="Comma-separated noise seeds, one per run (default 0..RUNS-1)."),
        seed: int = typer.Option(0, "--seed", help="Optimizer seed of the first run (run r uses SEED + r)."),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON object (tables and paths) on stdout."),
    ) -> None:
        """Section 5.2.1 again: Tables 5.5-5.13 and Figs. 5.2-5.13 next to the thesis' numbers."""
        noise_seeds = parse_seeds(seeds_noise, runs)
        target = report_dir(out, "reproduce")
        total = len(noise_seeds) * len(tt.NOISE_LEVELS) * len(SETTINGS) * len(tt.ALGOS)
        with Progress("reproducing", total, enabled=not as_json) as progress:
            rep = reproduce_thesis(noise_seeds=noise_seeds, seed=seed, progress=lambda what: progress.advance(what))
        rep.write_report(target)
        print(jsondoc.dumps(rep.to_dict()) if as_json else rep.summary())
