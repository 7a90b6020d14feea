"""``hysid reproduce thesis``: section 5.2.1 (the Synth benchmark) regenerated next to the published numbers.

For each algorithm (GA, PSO), noise level (0, 10, 20, 30 %) and run r the
Synth set is drawn with noise seed r (Table 5.2-5.4, Appendix A noise) and
fitted twice:

* **thesis-faithful**: the thesis' GA/PSO settings (section 5.1), the thesis'
  loop weights (Appendix A), no polish;
* **hysid defaults**: the same search, then the least-squares polish, with ML
  weights (1/sigma^2) when the data are noisy.

The report has Tables 5.5-5.12 (each run, mean, sigma, sigma/mean), Table 5.13
(|mean - actual|), Figs. 5.2-5.5 (parameter scatter per noise level with the
true value dashed), 5.6-5.9 (convergence) and 5.10-5.13 (loops), each next to
the thesis' published numbers and the Cramer-Rao bound of every parameter at
every noise level.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from coordinator import thesis_tables as tt
from coordinator.fit import FitResult, build_objective, fit
from coordinator.report import figures, jsondoc
from coordinator.report.markdown import FITNESS_LABEL, image, num, table
from hysid_model.errors import HysidInputError
from hysid_model.loops import LoopSet
from hysid_model.synth import TRUE_PARAMS, synth_loops
from hysid_model.uncertainty import cramer_rao_stderr

MODEL = "thesis"
PARAMS = tt.PARAMS
UNITS = {"xi0": "1", "S_xi": "1/m", "w0": "rad/s", "S_w": "rad/s/m"}


@dataclass(frozen=True)
class Setting:
    """How a run is configured: loop weights and polish."""

    key: str
    label: str
    polish: bool
    ml_when_noisy: bool

    def weights(self, noise: float) -> str:
        return "ml" if self.ml_when_noisy and noise > 0 else "thesis"


SETTINGS = (
    Setting("thesis", "thesis-faithful", polish=False, ml_when_noisy=False),
    Setting("hysid", "hysid defaults", polish=True, ml_when_noisy=True),
)

Cell = tuple[str, str, int]
"""(setting key, algorithm, noise %)."""


def parse_seeds(text: str | None, runs: int) -> list[int]:
    """``--seeds-noise`` as a list (one seed per run), default ``0..runs-1``."""
    if runs < 1:
        raise HysidInputError(f"--runs {runs}: the number of runs must be at least 1")
    if text is None:
        return list(range(runs))
    try:
        seeds = [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise HysidInputError(f"--seeds-noise {text!r}: expected comma-separated integers, e.g. 0,1,2,3") from None
    if not seeds or any(s < 0 for s in seeds):
        raise HysidInputError(f"--seeds-noise {text!r}: expected non-negative integers, e.g. 0,1,2,3")
    if len(seeds) != runs:
        raise HysidInputError(f"--seeds-noise {text!r}: {len(seeds)} seed(s) for --runs {runs}; give one noise seed per run")
    return seeds


def cramer_rao_bounds(noise_levels: tuple[int, ...] = tt.NOISE_LEVELS) -> dict[int, np.ndarray]:
    """The Cramer-Rao bound (one standard error) of each parameter at the true values, per noise level.

    It depends on the noise sigma and the loops' geometry only, not on the
    noise draw; 0 % noise has a zero bound.
    """
    out = {}
    for noise in noise_levels:
        if noise == 0:
            out[noise] = np.zeros(len(PARAMS))
            continue
        obj = build_objective(synth_loops(noise, seed=0), MODEL, "ml")
        out[noise] = cramer_rao_stderr(obj, obj.model.from_dict(TRUE_PARAMS))
    return out


@dataclass
class Reproduction:
    """Every fit of the reproduction, keyed by :data:`Cell`, one :class:`FitResult` per run."""

    noise_seeds: list[int]
    seed: int
    results: dict[Cell, list[FitResult]]
    cramer_rao: dict[int, np.ndarray]

    @property
    def n_runs(self) -> int:
        return len(self.noise_seeds)

    def values(self, cell: Cell) -> np.ndarray:
        """Parameters of every run of a cell, ``(runs, 4)`` in the order of :data:`PARAMS`."""
        return np.array([[r.params[p] for p in PARAMS] for r in self.results[cell]])

    def stats(self, cell: Cell) -> dict[str, np.ndarray]:
        """Mean, sample standard deviation, |sigma/mean| and |mean - actual| of each parameter (Tables 5.5-5.13)."""
        v = self.values(cell)
        mean = v.mean(axis=0)
        std = v.std(axis=0, ddof=1) if v.shape[0] > 1 else np.full(v.shape[1], np.nan)
        true = np.array([TRUE_PARAMS[p] for p in PARAMS])
        return {"mean": mean, "std": std, "rel_std": np.abs(std / mean), "error": np.abs(mean - true)}

    def as_dict(self) -> dict[str, Any]:
        cells = []
        for (setting, algo, noise), results in self.results.items():
            st = self.stats((setting, algo, noise))
            cells.append({
                "setting": setting,
                "algo": algo,
                "noise_pct": noise,
                "weights": results[0].weights,
                "polish": bool(results[0].settings["polish"]),
                "runs": {p: self.values((setting, algo, noise))[:, i] for i, p in enumerate(PARAMS)},
                "mean": dict(zip(PARAMS, st["mean"])),
                "std": dict(zip(PARAMS, st["std"])),
                "rel_std": dict(zip(PARAMS, st["rel_std"])),
                "abs_error_of_mean": dict(zip(PARAMS, st["error"])),
                "evaluations": [r.evaluations for r in results],
            })
        return {
            "noise_seeds": self.noise_seeds,
            "seed": self.seed,
            "true_params": TRUE_PARAMS,
            "cramer_rao": {str(n): dict(zip(PARAMS, b)) for n, b in self.cramer_rao.items()},
            "cells": cells,
            "published_table_5_13": {p: {f"{a}_{n}": v for (a, n), v in tt.TABLE_5_13[p].items()} for p in PARAMS},
        }

    def summary_text(self) -> str:
        """Table 5.13 side by side, for the terminal."""
        lines = [f"Table 5.13, |mean - actual| over {self.n_runs} run(s) (noise seeds {', '.join(map(str, self.noise_seeds))}):"]
        head = f"  {'parameter':<9} {'source':<16}" + "".join(f"{f'{n}% ' + a.upper():>11}" for n in tt.NOISE_LEVELS for a in tt.ALGOS)
        lines.append(head)
        for i, p in enumerate(PARAMS):
            row = f"  {p:<9} {'published':<16}" + "".join(f"{tt.TABLE_5_13[p][(a, n)]:>11.3g}" for n in tt.NOISE_LEVELS for a in tt.ALGOS)
            lines.append(row)
            for s in SETTINGS:
                row = f"  {'':<9} {s.label:<16}" + "".join(
                    f"{self.stats((s.key, a, n))['error'][i]:>11.3g}" for n in tt.NOISE_LEVELS for a in tt.ALGOS
                )
                lines.append(row)
        return "\n".join(lines)


def reproduce_thesis(
    noise_seeds: list[int],
    seed: int = 0,
    *,
    noise_levels: tuple[int, ...] = tt.NOISE_LEVELS,
    algos: tuple[str, ...] = tt.ALGOS,
    progress: Callable[[str], None] | None = None,
) -> Reproduction:
    """Run every (setting, algorithm, noise, run); run r uses noise seed ``noise_seeds[r]`` and optimizer seed ``seed + r``."""
    loops: dict[tuple[int, int], LoopSet] = {}
    results: dict[Cell, list[FitResult]] = {}
    for noise in noise_levels:
        for r, noise_seed in enumerate(noise_seeds):
            data = loops.setdefault((noise, noise_seed), synth_loops(noise, seed=noise_seed))
            for setting in SETTINGS:
                for algo in algos:
                    result = fit(data, model=MODEL, algo=algo, runs=1, seed=seed + r, weights=setting.weights(noise), polish=setting.polish)
                    result.runs[0].label = f"run {r + 1}"
                    results.setdefault((setting.key, algo, noise), []).append(result)
                    if progress is not None:
                        progress(f"{noise} % noise, run {r + 1}, {algo.upper()}, {setting.label}")
    return Reproduction(noise_seeds=list(noise_seeds), seed=seed, results=results, cramer_rao=cramer_rao_bounds(noise_levels))


def _run_table(rep: Reproduction, algo: str, noise: int) -> str:
    n_cols = max(rep.n_runs, 4)
    headers = ["parameter", "source", "actual"] + [f"run {i + 1}" for i in range(n_cols)] + ["mean", "sigma", "sigma/mean", "Cramer-Rao"]
    rows = []
    for i, p in enumerate(PARAMS):
        pub = tt.RUNS[(algo, noise)][p]
        mean, std, rel = tt.SUMMARY[(algo, noise)][p]
        cr = num(rep.cramer_rao[noise][i], 3) if noise > 0 else "0"
        rows.append([f"`{p}`", "published", num(TRUE_PARAMS[p], 7)] + [num(v, 7) for v in pub] + [""] * (n_cols - 4) + [num(mean, 7), num(std, 4), num(rel, 4), cr])
        for s in SETTINGS:
            v = rep.values((s.key, algo, noise))[:, i]
            st = rep.stats((s.key, algo, noise))
            rows.append(
                ["", s.label, ""] + [num(x, 7) for x in v] + [""] * (n_cols - v.size)
                + [num(st["mean"][i], 7), num(st["std"][i], 4), num(st["rel_std"][i], 4), ""]
            )
    return table(headers, rows)


def _table_5_13(rep: Reproduction) -> str:
    headers = ["parameter", "source"] + [f"{n} % {a.upper()}" for n in tt.NOISE_LEVELS for a in tt.ALGOS]
    rows = []
    for i, p in enumerate(PARAMS):
        rows.append([f"`{p}`", "published"] + [num(tt.TABLE_5_13[p][(a, n)], 3) for n in tt.NOISE_LEVELS for a in tt.ALGOS])
        for s in SETTINGS:
            rows.append(["", s.label] + [num(rep.stats((s.key, a, n))["error"][i], 3) for n in tt.NOISE_LEVELS for a in tt.ALGOS])
        rows.append(["", f"CR / sqrt({rep.n_runs})"] + [num(rep.cramer_rao[n][i] / np.sqrt(rep.n_runs), 3) for n in tt.NOISE_LEVELS for _ in tt.ALGOS])
    return table(headers, rows)


def write_reproduction(rep: Reproduction, out_dir: Path | str) -> Path:
    """Write ``report.md``, ``reproduction.json`` and Figs. 5.2-5.13 into ``out_dir``; returns the report path."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    jsondoc.write(out_dir / "reproduction.json", rep.as_dict())
    parts = [
        "# hysid reproduce thesis: the Synth benchmark of section 5.2.1",
        f"Written {dt.datetime.now().isoformat(timespec='seconds')}. {rep.n_runs} run(s) per algorithm, noise level and "
        f"setting; run r uses noise seed {', '.join(map(str, rep.noise_seeds))} (in order) and optimizer seed "
        f"{rep.seed} + r. All numbers are also in [`reproduction.json`](reproduction.json).",
        "- **thesis-faithful**: the thesis' GA and PSO (section 5.1: 6000 initial, 500 per iteration, 18 iterations), "
        "the thesis' loop weights (Appendix A), no polish.\n"
        "- **hysid defaults**: the same search, then a bounded least-squares polish; maximum-likelihood weights "
        "(1/sigma^2) when the data are noisy.\n"
        "- **published**: the thesis' Tables 5.5-5.13 as printed. **Cramer-Rao**: the smallest standard error any "
        "unbiased estimator can reach at that noise level (one run).",
    ]
    parts += ["## Table 5.13: |mean - actual|", _table_5_13(rep)]
    n_fig = 2
    parts.append("## Figs. 5.2-5.5: parameter scatter per noise level")
    for i, p in enumerate(PARAMS):
        panels = [
            (f"({'ab'[k]}) {algo.upper()}", [
                ("published", {n: np.array(tt.RUNS[(algo, n)][p]) for n in tt.NOISE_LEVELS}),
                *[(s.label, {n: rep.values((s.key, algo, n))[:, i] for n in tt.NOISE_LEVELS if (s.key, algo, n) in rep.results}) for s in SETTINGS],
            ])
            for k, algo in enumerate(tt.ALGOS)
        ]
        path = figures.scatter_figure(out_dir / f"fig5_{n_fig}_{p}.png", p, UNITS[p], TRUE_PARAMS[p], panels, {n: b[i] for n, b in rep.cramer_rao.items()})
        parts.append(image(path, out_dir, f"Fig. 5.{n_fig}: {p} per noise level; hollow: runs, filled: mean, red dashed: true value, "
                           "grey band: true +- Cramer-Rao bound"))
        n_fig += 1
    parts.append("## Figs. 5.6-5.9: convergence (thesis-faithful runs)")
    for noise in tt.NOISE_LEVELS:
        panels = [(f"({'ab'[k]}) {algo.upper()}", [r.runs[0] for r in rep.results[("thesis", algo, noise)]]) for k, algo in enumerate(tt.ALGOS)]
        path = figures.convergence_figure(out_dir / f"fig5_{n_fig}_convergence_{noise}pct.png", panels, FITNESS_LABEL["thesis"], f"{noise} % noise")
        parts.append(image(path, out_dir, f"Fig. 5.{n_fig}: convergence at {noise} % noise, all runs overlaid, matching scales"))
        n_fig += 1
    parts.append("## Figs. 5.10-5.13: trial vs model loops (thesis-faithful PSO, run 1)")
    for noise in tt.NOISE_LEVELS:
        result = rep.results[("thesis", "pso", noise)][0]
        predicted = result.objective().predict(result.theta)[0]
        path = figures.loops_figure(out_dir / f"fig5_{n_fig}_loops_{noise}pct.png", result.loops, predicted, title=f"{noise} % noise")
        parts.append(image(path, out_dir, f"Fig. 5.{n_fig}: loops at {noise} % noise; rows: 0.5, 1.0, 1.5 mm"))
        n_fig += 1
    parts.append("## Tables 5.5-5.12: every run")
    for algo in tt.ALGOS:
        for noise in tt.NOISE_LEVELS:
            parts += [f"### Table 5.{tt.TABLE_NUMBERS[(algo, noise)]}: {algo.upper()}, {noise} % noise", _run_table(rep, algo, noise)]
    report = out_dir / "report.md"
    report.write_text("\n\n".join(parts) + "\n")
    return report
