"""CLI command ``hysid diagnose``: which physical effect is the model missing?"""

from __future__ import annotations

from pathlib import Path

import typer

from hysid.cli import options as o
from hysid.cli.groups import Reading, grouped, laid_out
from hysid.cli.progress import Progress
from hysid.diagnosis.scoring import candidate_effects
from hysid.diagnosis.selection import diagnose

REPORT_WORK = 4.0
"""The report's work in the bar, in fits: its figures took 3.6-4.2 s where a memoryless refit takes about 1 s."""


READING = laid_out("points", "skip_rows", "noise", "noise_seed")
"""The loops' reading options in the order ``diagnose --help`` has always listed them."""


def register(app: typer.Typer) -> None:
    """Add ``hysid diagnose`` to the hysid app."""

    @app.command("diagnose")
    @grouped
    def diagnose_command(
        dataset: str = o.DATASET,
        model: str = o.START_MODEL,
        out: Path | None = o.OUT,
        as_json: bool = o.JSON,
        reading: Reading = READING,
        csv: bool = o.CSV,
        quiet: bool = o.QUIET,
        bound: list[str] | None = o.BOUND,
        displacement: str = o.DISPLACEMENT,
        candidates: str | None = o.CANDIDATES,
        no_discover: bool = o.NO_DISCOVER,
        figures: bool = o.FIGURES,
    ) -> None:
        """Find which effects of the library (and --candidates of your own) the model misses, step by step, and write a report."""
        bounds, effects = o.parse_bounds(bound), candidate_effects(o.parse_list(candidates))
        target = o.report_dir(out, "diagnose")
        loops = reading.load(dataset)
        with Progress("diagnosing", 1, enabled=not (quiet or as_json)) as progress:  # in fits (hysid.diagnosis.tally)
            result = diagnose(
                loops,
                model,
                bounds=bounds,
                candidates=effects,
                displacement=displacement,
                discover=not no_discover,
                progress=lambda done, total, what: progress.update(done, what, total + REPORT_WORK),
            )
            progress.update(progress.done, "writing the report and its figures")
            tables = o.write_result(result, target, csv, dataset, figures)
            progress.update(progress.total, f"report written: {target}")
        o.print_result(result, as_json, tables)
