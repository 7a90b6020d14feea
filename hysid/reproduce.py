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

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hysid import thesis_tables as tt
from hysid.fit_result import FitResult
from hysid.fitting import fit
from hysid.report import reproduction
from hysid.report.records import ReproductionCurves
from hysid_model.errors import HysidInputError
from hysid_model.loops import LoopSet
from hysid_model.objective import Objective
from hysid_model.problem import build_objective
from hysid_model.synth import TRUE_PARAMS, synth_loops
from hysid_model.uncertainty import cramer_rao_stderr

MODEL = "thesis"
PARAMS = tt.PARAMS


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


def parse_seeds(seeds: str | None, runs: int) -> list[int]:
    """Comma-separated noise seeds as a list (one seed per run), default ``0..runs-1``."""
    if isinstance(runs, bool) or not isinstance(runs, int) or runs < 1:
        raise HysidInputError("the number of runs must be at least 1", param="runs", value=runs)
    if seeds is None:
        return list(range(runs))
    try:
        parsed = [int(part) for part in seeds.split(",") if part.strip()]
    except ValueError:
        raise HysidInputError("expected comma-separated integers, e.g. 0,1,2,3", param="noise_seeds", value=seeds) from None
    if not parsed or any(s < 0 for s in parsed):
        raise HysidInputError("expected non-negative integers, e.g. 0,1,2,3", param="noise_seeds", value=seeds)
    if len(parsed) != runs:
        raise HysidInputError(f"{len(parsed)} seed(s) for {runs} run(s); give one noise seed per run", param="noise_seeds", value=seeds)
    return parsed


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
        obj = build_objective(synth_loops(noise, seed=0), MODEL, weights="ml")
        assert isinstance(obj, Objective)  # the closed form (build_objective's default kind)
        out[noise] = cramer_rao_stderr(obj, obj.model.from_dict(TRUE_PARAMS))
    return out


@dataclass
class Reproduction:
    """Every fit of the reproduction, keyed by :data:`Cell`, one :class:`FitResult` per run."""

    noise_seeds: list[int]
    seed: int
    results: dict[Cell, list[FitResult]]
    cramer_rao: dict[int, np.ndarray]
    settings: tuple[Setting, ...] = SETTINGS
    report: str | None = None
    """The report written last (:meth:`write_report`)."""

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

    def to_dict(self) -> dict[str, Any]:
        """The JSON document of ``hysid reproduce thesis --json`` (and ``reproduction.json``)."""
        cells = []
        for (setting, algo, noise), results in self.results.items():
            st = self.stats((setting, algo, noise))
            cells.append(
                {
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
                }
            )
        return {
            "noise_seeds": self.noise_seeds,
            "seed": self.seed,
            "true_params": TRUE_PARAMS,
            "cramer_rao": {str(n): dict(zip(PARAMS, b)) for n, b in self.cramer_rao.items()},
            "cells": cells,
            "published_table_5_13": {p: {f"{a}_{n}": v for (a, n), v in tt.TABLE_5_13[p].items()} for p in PARAMS},
            "report": self.report,
        }

    def summary(self) -> str:
        """Table 5.13 side by side (published, thesis-faithful, hysid defaults), as text."""
        return reproduction.reproduction_summary(self.to_dict(), self.labels())

    def labels(self) -> dict[str, str]:
        """Each setting's words by its key, as the writers show them."""
        return {s.key: s.label for s in self.settings}

    def curves(self) -> ReproductionCurves:
        """What the report's figures draw: the thesis-faithful runs of each (algorithm, noise %), and the loops of the
        first thesis-faithful PSO run at each noise % with its model's force."""
        runs = {(algo, noise): [r.runs[0] for r in results] for (setting, algo, noise), results in self.results.items() if setting == "thesis"}
        first = {noise: results[0] for (setting, algo, noise), results in self.results.items() if (setting, algo) == ("thesis", "pso")}
        return ReproductionCurves(runs, {noise: (r.loops, r.objective().predict(r.theta)[0]) for noise, r in first.items()})

    def write_report(self, out_dir: str | Path) -> Path:
        """``report.md``, ``reproduction.json`` and Figs. 5.2-5.13 in ``out_dir``; returns the report's path."""
        out_dir = Path(out_dir)
        self.report = str(out_dir / reproduction.REPORT)
        return reproduction.write_reproduction_report(self.to_dict(), self.labels(), self.curves(), out_dir)


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
