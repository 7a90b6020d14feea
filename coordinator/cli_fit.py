"""CLI commands ``hysid fit`` (single node, no network) and ``hysid reproduce thesis``."""

from __future__ import annotations

import datetime as dt
import sys
from pathlib import Path
from typing import Optional, TextIO

import typer

from coordinator.fit import FitResult, fit
from coordinator.report import jsondoc, write_report
from coordinator.report.markdown import loops_description, quality_text
from coordinator.reproduce import SETTINGS, parse_seeds, reproduce_thesis, write_reproduction
from coordinator.thesis_tables import ALGOS, NOISE_LEVELS
from hysid_model.datasets import load_dataset
from hysid_model.errors import HysidInputError
from island.run import HistoryRow


ROWS_PER_RUN = 18 + 1
"""History rows of a run with the thesis' settings: the initial population, then 18 iterations (section 5.1)."""


class ProgressBar:
    """A one-line progress bar on a terminal's stderr; silent when stderr is not a terminal."""

    def __init__(self, total: int, label: str, stream: TextIO | None = None) -> None:
        self.stream = sys.stderr if stream is None else stream
        self.enabled = self.stream.isatty()
        self.total = max(total, 1)
        self.label = label
        self.done = 0

    def step(self, text: str) -> None:
        self.done += 1
        if not self.enabled:
            return
        width = 28
        filled = int(width * min(self.done, self.total) / self.total)
        self.stream.write(f"\r{self.label} [{'#' * filled}{'.' * (width - filled)}] {text}\x1b[K")
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self.stream.write("\r\x1b[K")
            self.stream.flush()


def default_out(kind: str) -> Path:
    """``hysid-out/<kind>-<timestamp>`` (with a suffix if that already exists)."""
    stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    base = Path("hysid-out") / f"{kind}-{stamp}"
    out, n = base, 1
    while out.exists():
        n += 1
        out = base.with_name(f"{base.name}-{n}")
    return out


def out_dir(out: Path | None, kind: str) -> Path:
    """The report directory: ``--out`` if given (it must not be a file), else :func:`default_out`."""
    if out is None:
        return default_out(kind)
    if out.exists() and not out.is_dir():
        raise HysidInputError(f"--out {out}: exists and is not a directory")
    return out


def _text_table(headers: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(headers)]

    def line(cells: list[str]) -> str:
        return "  " + "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))

    return "\n".join([line(headers)] + [line(r) for r in rows])


def summary_text(result: FitResult, command: str = "hysid fit") -> str:
    """What a user reads after ``hysid fit`` (or ``command``): what was fitted, how well, and where the report is."""
    s = result.settings
    best = result.runs[result.best]
    true = result.loops.meta.get("true_params") or {}
    algo = str(s.get("algo", best.algo)).upper()
    polish = " + least-squares polish" if s.get("polish") else ""
    wall = sum(r.wall_s for r in result.runs)
    lines = [
        f"{command} {result.loops.name}: {loops_description(result)}",
        f"model {result.model.spec} ({', '.join(result.model.names)}); {algo} x {len(result.runs)} {'island' if command == 'hysid campaign' else 'run'}(s){polish}; {result.weights} weights",
        f"best: {best.label} (seed {best.seed}), fitness {best.fitness:.6g} after {result.evaluations:,} evaluations in {wall:.1f} s",
        f"fit quality: {quality_text(result)}",
        "",
    ]
    se = result.stderr
    headers = ["parameter", "value", "std. error", "unit"] + (["true"] if true else [])
    rows = []
    for p in result.model.parameters:
        row = [p.name, f"{result.params[p.name]:.7g}", f"{se[p.name]:.2g}", p.unit]
        if true:
            row.append(f"{true[p.name]:.7g}" if p.name in true else "")
        rows.append(row)
    lines += [_text_table(headers, rows), f"  (standard errors: {result.stderr_method})"]
    if result.at_bounds:
        lines.append(
            f"  warning: {', '.join(result.at_bounds)} ended on a bound of the search space, so the optimum may lie "
            "beyond it and its standard error means little; widen the bounds ([bounds] in dataset.toml)"
        )
    lines.append("")
    rows = []
    for a, hp in zip(result.amplitudes, result.half_power):
        half = f"{hp.xi:.5f} (grid resolution {hp.resolution:.2g})" if hp.ok else f"n/a ({hp.note})"
        rows.append([
            f"{a.x0 * 1e3:.4g}",
            f"{a.values['fn_hz']:.4f}",
            f"{a.values['xi']:.5f} +- {a.stderr['xi']:.1g}",
            half,
            f"{a.values['k']:.5g}",
            f"{a.values['c']:.4g}",
        ])
    lines += [
        _text_table(["X0 (mm)", "fn (Hz)", "xi (fit)", "xi half-power (Eq. 2.7)", "k (N/m)", "c (N s/m)"], rows),
        "",
    ]
    if result.report:
        lines.append(f"report: {result.report} (figures and result.json alongside)")
    return "\n".join(lines)


def register(app: typer.Typer) -> None:
    """Add ``fit`` and ``reproduce thesis`` to the hysid app."""

    @app.command("fit")
    def fit_command(
        dataset: str = typer.Argument(..., help="Dataset directory, loops file, .mat or .lvm directory, or 'synth' (the thesis' Synth set)."),
        algo: str = typer.Option("pso", "--algo", help="Optimizer: ga or pso (the thesis' settings, section 5.1)."),
        model: str = typer.Option("thesis", "--model", help="thesis, baseline, or a preset with +effects (see 'hysid models')."),
        runs: int = typer.Option(1, "--runs", help="Independent runs with seeds SEED..SEED+RUNS-1; the best is reported."),
        seed: int = typer.Option(0, "--seed", help="Seed of the first run."),
        weights: Optional[str] = typer.Option(None, "--weights", help="thesis or ml (1/sigma^2); default: ml when every loop's noise sigma is known."),
        out: Optional[Path] = typer.Option(None, "--out", help="Report directory (default hysid-out/fit-<timestamp>)."),
        json_out: bool = typer.Option(False, "--json", help="Print one JSON object on stdout instead of the summary."),
        polish: bool = typer.Option(True, "--polish/--no-polish", help="Refine each run's best by bounded least squares."),
        noise: float = typer.Option(0.0, "--noise", help="Gaussian force noise, % of each loop's peak force (as the thesis' Synth tests)."),
        noise_seed: int = typer.Option(0, "--noise-seed", help="Seed of that noise."),
    ) -> None:
        """Identify the model's parameters from DATASET in this process (no network)."""
        if runs < 1:
            raise HysidInputError(f"--runs {runs}: the number of runs must be at least 1")
        target = out_dir(out, "fit")
        loops = load_dataset(dataset, noise_pct=noise, noise_seed=noise_seed)
        progress = ProgressBar(runs * ROWS_PER_RUN, "fitting")

        def show(i: int, row: HistoryRow) -> None:
            progress.step(f"run {i + 1}/{runs}, iteration {row.iteration}, best {row.best_fitness:.4g}")

        try:
            result = fit(loops, model=model, algo=algo, runs=runs, seed=seed, weights=weights, polish=polish, progress=show)
        finally:
            progress.close()
        write_report(result, target)
        if json_out:
            print(jsondoc.dumps(result.as_dict()))
        else:
            print(summary_text(result))

    reproduce = typer.Typer(help="Regenerate the thesis' published results.", no_args_is_help=True)
    app.add_typer(reproduce, name="reproduce")

    @reproduce.command("thesis")
    def reproduce_thesis_command(
        runs: int = typer.Option(4, "--runs", help="Runs per algorithm, noise level and setting (the thesis: 4)."),
        out: Optional[Path] = typer.Option(None, "--out", help="Report directory (default hysid-out/reproduce-<timestamp>)."),
        seeds_noise: Optional[str] = typer.Option(None, "--seeds-noise", help="Comma-separated noise seeds, one per run (default 0..RUNS-1)."),
        seed: int = typer.Option(0, "--seed", help="Optimizer seed of the first run (run r uses SEED + r)."),
        json_out: bool = typer.Option(False, "--json", help="Print one JSON object (tables and paths) on stdout."),
    ) -> None:
        """Section 5.2.1 again: Tables 5.5-5.13 and Figs. 5.2-5.13 next to the thesis' numbers."""
        noise_seeds = parse_seeds(seeds_noise, runs)
        target = out_dir(out, "reproduce")
        progress = ProgressBar(len(noise_seeds) * len(NOISE_LEVELS) * len(SETTINGS) * len(ALGOS), "reproducing")
        try:
            rep = reproduce_thesis(noise_seeds=noise_seeds, seed=seed, progress=progress.step)
        finally:
            progress.close()
        report = write_reproduction(rep, target)
        if json_out:
            print(jsondoc.dumps({**rep.as_dict(), "report": str(report)}))
        else:
            print(rep.summary_text())
            print(f"\nreport: {report}")
