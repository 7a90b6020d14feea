"""CLI commands for data: ``hysid synth`` writes the Synth set, ``hysid loops`` lists a dataset's loops."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import typer

from hysid_model.datasets import load_dataset, write_dataset
from hysid_model.loops import LoopSet
from hysid_model.synth import BOUNDS, MEQ_KG, TRUE_PARAMS, synth_loops, synth_raw


def loop_rows(loops: LoopSet) -> list[dict[str, Any]]:
    """One dict per loop: label, frequency, X0, peak force, noise sigma, cycles (+ phase, distortion when extracted)."""
    per_loop = loops.meta.get("per_loop", {})
    rows = []
    for j in range(loops.n_loops):
        sigma = float(loops.sigma[j])
        row: dict[str, Any] = {
            "label": loops.labels[j],
            "frequency_hz": float(loops.freq_hz[j]),
            "x0_m": float(loops.x0[j]),
            "peak_force_n": float(loops.peak_force[j]),
            "sigma_n": sigma if math.isfinite(sigma) else None,
            "cycles": int(loops.cycles[j]),
        }
        for key in ("phase_deg", "x_distortion"):
            if key in per_loop:
                row[key] = float(per_loop[key][j])
        rows.append(row)
    return rows


def _table(loops: LoopSet, rows: list[dict[str, Any]]) -> str:
    columns = [("label", "label", "{}"), ("frequency_hz", "freq_Hz", "{:.6g}"), ("x0_m", "X0_mm", "{:.4f}"),
               ("peak_force_n", "Fpk_N", "{:.5g}"), ("sigma_n", "sigma_N", "{:.3g}"), ("cycles", "cycles", "{:d}")]
    if "phase_deg" in rows[0]:
        columns += [("phase_deg", "phase_deg", "{:.2f}"), ("x_distortion", "x_thd_%", "{:.2f}")]
    scale = {"x0_m": 1e3, "x_distortion": 100.0}
    cells = [[title for _, title, _ in columns]]
    for row in rows:
        line = []
        for key, _, fmt in columns:
            value = row[key]
            line.append("-" if value is None else fmt.format(value * scale[key] if key in scale else value))
        cells.append(line)
    widths = [max(len(r[i]) for r in cells) for i in range(len(columns))]
    text = [
        "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths)))
        for r in cells
    ]
    mass = "unknown (fitted)" if loops.meq_kg is None else f"{loops.meq_kg:g} kg"
    head = f"{loops.name}: {loops.n_loops} loops, {loops.n_samples} points per branch, meq = {mass}"
    return "\n".join([head] + text)


def register(app: typer.Typer) -> None:
    """Add this module's commands to the hysid app."""

    @app.command("synth")
    def synth_command(
        out_dir: Path = typer.Argument(..., help="New (or empty) directory to write the dataset to."),
        noise: float = typer.Option(0.0, "--noise", help="Gaussian force noise, % of each loop's peak force (thesis: 0, 10, 20, 30)."),
        seed: int = typer.Option(0, "--seed", help="Noise seed."),
        raw: bool = typer.Option(False, "--raw", help="Write raw time series (one CSV per loop, manifest.csv, dataset.toml) instead of branches."),
    ) -> None:
        """Write the thesis' Synth set (Tables 5.2-5.4, 120 loops) as a dataset directory."""
        if raw:
            records = synth_raw(noise, seed)
            write_dataset(out_dir, records, name=f"synth-raw-{noise:g}pct-seed{seed}", meq_kg=MEQ_KG, bounds=BOUNDS,
                          true_params=TRUE_PARAMS, description="Thesis Synth set (section 5.2) as raw time series")
            print(f"wrote {len(records)} raw records, manifest.csv and dataset.toml to {out_dir}")
        else:
            loops = synth_loops(noise, seed)
            write_dataset(out_dir, loops)
            print(f"wrote {loops.n_loops} loops to {out_dir / 'loops.csv'}")

    @app.command("loops")
    def loops_command(
        dataset: str = typer.Argument(..., help="Dataset directory, loops file, .mat/.lvm files, or 'synth'."),
        as_json: bool = typer.Option(False, "--json", help="Print a JSON list of objects instead of a table."),
        noise: float = typer.Option(0.0, "--noise", help="Add Gaussian force noise, % of each loop's peak force."),
        noise_seed: int = typer.Option(0, "--noise-seed", help="Seed of the added noise."),
        points: int | None = typer.Option(None, "--points", help="Points per branch (default 100; a loops file keeps its own)."),
    ) -> None:
        """List a dataset's loops: label, frequency, X0, peak force, noise sigma, cycles used."""
        loops = load_dataset(dataset, noise_pct=noise, noise_seed=noise_seed, n_points=points)
        rows = loop_rows(loops)
        print(json.dumps(rows, indent=1) if as_json else _table(loops, rows))
