"""CLI command ``hysid diagnose``: which physical effect is the model missing?"""

from __future__ import annotations

import typer

from hysid.cli import options as o
from hysid.cli.groups import LAID_OUT, Constraints, Output, Reading, grouped, laid_out
from hysid.cli.progress import Progress
from hysid.diagnosis.scoring import candidate_effects
from hysid.diagnosis.selection import diagnose

REPORT_WORK = 4.0
"""The report's work in the bar, in fits: its figures took 3.6-4.2 s where a memoryless refit takes about 1 s."""


READING = laid_out("points", "skip_rows", "noise", "noise_seed")
"""The loops' reading options in the order ``diagnose --help`` has always listed them."""
LIMITS = laid_out("bound", "displacement")
"""The constraints ``diagnose`` takes: not ``--fix`` (:func:`hysid.diagnosis.selection.diagnose` fits every parameter)."""


def register(app: typer.Typer) -> None:
    """Add ``hysid diagnose`` to the hysid app."""

    @app.command("diagnose")
    @grouped
    def diagnose_command(
        dataset: str = o.DATASET,
        model: str = o.START_MODEL,
        output: Output = LAID_OUT,
        reading: Reading = READING,
        limits: Constraints = LIMITS,
        candidates: str | None = o.CANDIDATES,
        no_discover: bool = o.NO_DISCOVER,
    ) -> None:
        """Find which effects of the library (and --candidates of your own) the model misses, step by step, and write a report."""
        effects = candidate_effects(o.parse_list(candidates))
        target = output.directory("diagnose")
        loops = reading.load(dataset)
        with Progress("diagnosing", 1, enabled=output.live) as progress:  # in fits (hysid.diagnosis.tally)
            result = diagnose(
                loops,
                model,
                bounds=limits.bounds(),
                candidates=effects,
                displacement=limits.displacement,
                discover=not no_discover,
                progress=lambda done, total, what: progress.update(done, what, total + REPORT_WORK),
            )
            progress.update(progress.done, "writing the report and its figures")
            tables = output.write(result, target, dataset)
            progress.update(progress.total, f"report written: {target}")
        output.print(result, tables)
