"""CLI command ``hysid diagnose``: which physical effect is the model missing?"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from coordinator.cli_fit import default_out
from coordinator.diagnose.report import write_report
from coordinator.diagnose.selection import diagnose
from coordinator.report import jsondoc
from hysid_model.datasets import load_dataset
from hysid_model.errors import HysidInputError
from hysid_model.model import PRESETS


def summary_text(doc: dict, report: Path) -> str:
    lines = [f"hysid diagnose {doc['dataset']}: start model {doc['start_model']}, noise {doc['noise_sigma']}"]
    gap = doc["gap"]
    lines.append(f"  {'start':<40} whitened RMS {gap[0]['whitened_rms']:10.4g}")
    for step, after in zip(doc["steps"], gap[1:]):
        also = f" (confusable with {', '.join(step['confusable_with'])})" if step["confusable_with"] else ""
        lines.append(f"  + {step['effect'] + also:<38} whitened RMS {after['whitened_rms']:10.4g}   score {step['score']:.4g}")
    if doc["status"] == "adequate":
        lines.append(f"status: adequate, the final model {doc['final_model']} leaves only noise")
    else:
        lines.append(f"status: unexplained, {doc['unexplained_signature']['description']}")
    for effect, absorbed in doc["not_identifiable"].items():
        lines.append(f"not identifiable here: {effect} (absorbed by {', '.join(absorbed)})")
    lines.append(f"report: {report}")
    return "\n".join(lines)


def register(app: typer.Typer) -> None:
    """Add ``hysid diagnose`` to the hysid app."""

    @app.command("diagnose")
    def diagnose_command(
        dataset: str = typer.Argument(..., help="dataset directory, loops file or 'synth'"),
        model: str = typer.Option("baseline", "--model", help=f"start model: {' or '.join(PRESETS)}"),
        out: Optional[Path] = typer.Option(None, "--out", help="report directory, new or empty (default hysid-out/diagnose-<time>)"),
        as_json: bool = typer.Option(False, "--json", help="print the result as JSON instead of a summary"),
        points: Optional[int] = typer.Option(None, "--points", help="samples per branch when loops are extracted from raw records (default 100)"),
    ) -> None:
        """Find which effects of the library the model misses, step by step, and write a report."""
        if model not in PRESETS:
            raise HysidInputError(f"--model {model!r}: choose one of {', '.join(PRESETS)}")
        out_dir = default_out("diagnose") if out is None else out
        if out_dir.exists() and (not out_dir.is_dir() or any(out_dir.iterdir())):
            raise HysidInputError(f"--out {out_dir}: already exists and is not an empty directory; choose a new one (nothing was written)")
        loops = load_dataset(dataset, n_points=points)
        result = diagnose(loops, model)
        report, doc = write_report(result, out_dir, dataset)
        print(jsondoc.dumps(doc, indent=2) if as_json else summary_text(doc, report))
