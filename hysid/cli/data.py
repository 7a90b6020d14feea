"""CLI commands for data: ``hysid synth`` writes the Synth set, ``hysid loops`` lists a dataset's loops."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from hysid.cli import options as o
from hysid.cli.directories import report_dir
from hysid.cli.groups import LAID_OUT, Reading, grouped
from hysid.report import jsondoc
from hysid.report.text import loops_table
from hysid_model.datasets import write_dataset
from hysid_model.loops import LoopSet
from hysid_model.notices import stored
from hysid_model.plausibility import Clipping
from hysid_model.survey import survey
from hysid_model.synth import BOUNDS, MEQ_KG, TRUE_PARAMS, synth_loops, synth_raw


def register(app: typer.Typer) -> None:
    """Add ``synth`` and ``loops`` to the hysid app."""

    @app.command("synth")
    def synth_command(
        out_dir: Path = typer.Argument(..., help="New (or empty) directory to write the dataset to."),
        noise: float = o.NOISE,
        noise_seed: int = o.SYNTH_NOISE_SEED,
        raw: bool = typer.Option(False, "--raw", help="Write raw time series (one CSV per loop, manifest.csv, dataset.toml) instead of branches."),
    ) -> None:
        """Write the thesis' Synth set (Tables 5.2-5.4, 120 loops) as a dataset directory."""
        out_dir = report_dir(out_dir, "synth", param="out_dir")
        if raw:
            records = synth_raw(noise, noise_seed)
            write_dataset(
                out_dir,
                records,
                name=f"synth-raw-{noise:g}pct-seed{noise_seed}",
                meq_kg=MEQ_KG,
                bounds=BOUNDS,
                true_params=TRUE_PARAMS,
                description="Thesis Synth set (section 5.2) as raw time series",
            )
            print(f"wrote {len(records)} raw records, manifest.csv and dataset.toml to {out_dir}")
        else:
            loops = synth_loops(noise, noise_seed)
            write_dataset(out_dir, loops)
            print(f"wrote {loops.n_loops} loops to {out_dir / 'loops.csv'}")

    @app.command("loops")
    @grouped
    def loops_command(
        dataset: str = o.DATASET,
        as_json: bool = typer.Option(False, "--json", help="Print a JSON list of objects (one per loop) instead of a table."),
        reading: Reading = LAID_OUT,
        out: Path | None = typer.Option(
            None,
            "--out",
            help="Also write the loops (loops.csv: fit, diagnose and campaign read this directory without extracting again), survey.png and loops.json to this new (or empty) directory.",
        ),
    ) -> None:
        """List a dataset's loops and their equivalent-linear survey: frequency, X0, force, noise, cycles,
        dynamic stiffness, equivalent damping, loss factor, energy per cycle, and fn, xi where the mass is known or estimated;
        displacement distortion and clipping, and, without a manifest, the manifest.csv of the frequencies estimated."""
        target = None if out is None else report_dir(out, "loops")
        loops = reading.load(dataset)
        found = survey(loops)
        rows = [{**row, **extra} for row, extra in zip(loops.rows(), found.rows())]
        if target is not None:
            from hysid.report import figures  # matplotlib loads only when a figure is drawn

            write_dataset(target, loops)
            figures.survey_figure(target / "survey.png", found)
            jsondoc.write(
                target / "loops.json", {"dataset": loops.name, "warnings": stored(loops.meta), "mass": found.mass_source, "meq_kg": found.meq_kg, "loops": rows}
            )
        print(jsondoc.dumps(rows, indent=1) if as_json else loops_table(loops, rows, found) + _loop_notes(loops, rows))


def _loop_notes(loops: LoopSet, rows: list[dict[str, Any]]) -> str:
    """What ``hysid loops`` adds under its table: clipped records, and the manifest a folder without one would need."""
    lines = [f"clipped: {row['label']}: {Clipping(row['clipped'], row['clip_level']).describe(row['x0_m'])}" for row in rows if row.get("clipped")]
    if "estimated_manifest" in loops.meta:
        lines += ["no manifest.csv: frequencies estimated from the data; the manifest.csv it would write:", loops.meta["estimated_manifest"].rstrip("\n")]
    return "".join("\n" + line for line in lines)
