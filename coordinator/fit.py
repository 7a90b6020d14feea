"""The single-node fit: GA or PSO runs on one loop set, an optional polish, and the result.

One process, no network: each run is the thesis' GA or PSO (section 5.1)
driven by :func:`island.run.run`, then (by default) a least-squares polish from
its best candidate. :class:`FitResult` gathers the runs of one identification
(a campaign builds the same object from its islands with
:meth:`FitResult.from_runs`) and derives what a user reads: the best run's
parameters with standard errors (Cramer-Rao bound for ML weights, sandwich
covariance for the thesis weights), xi, fn and physical k, c, m at every
amplitude (as listed under Table 5.3), and the half-power cross-check of the
damping (Eq. 2.7, Fig. 6.1).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.frf import HalfPower, amplitude_levels, first_harmonic, half_power_by_amplitude
from hysid_model.loops import LoopSet
from hysid_model.model import Model, build_model, to_physical
from hysid_model.objective import WEIGHTS, Objective
from hysid_model.uncertainty import covariance, fisher_information
from island.ga import GA
from island.optimizer import AskTell
from island.polish import polish as least_squares_polish
from island.pso import PSO
from island.run import HistoryRow, run

ALGORITHMS: dict[str, type[AskTell]] = {"ga": GA, "pso": PSO}
"""The thesis' optimizers (section 5.1) by command-line name."""

Progress = Callable[[int, HistoryRow], None]
"""Called with (run index, history row) after every iteration of a run."""


def check_algorithm(algo: str) -> str:
    if algo not in ALGORITHMS:
        raise HysidInputError(f"--algo {algo!r}: unknown algorithm; choose one of {', '.join(ALGORITHMS)}")
    return algo


def resolve_weights(loops: LoopSet, weights: str | None) -> str:
    """The loop weights to use: as asked, else ML (1/sigma^2) when every loop's sigma is known, else the thesis'."""
    if weights is None:
        return "ml" if loops.has_sigma else "thesis"
    if weights not in WEIGHTS:
        raise HysidInputError(f"--weights {weights!r}: unknown weights; choose one of {', '.join(WEIGHTS)}")
    return weights


def build_objective(loops: LoopSet, model_spec: str = "thesis", weights: str | None = None) -> Objective:
    """The objective of ``model_spec`` on ``loops``: model default bounds, overridden by ``loops.meta['bounds']``.

    Dataset bounds for parameters the model does not have (e.g. S_xi when
    fitting the baseline) are left out.
    """
    model = build_model(model_spec, meq_kg=loops.meq_kg)
    given = loops.meta.get("bounds") or {}
    model.set_bounds({name: tuple(b) for name, b in given.items() if name in model.names})
    return Objective(loops, model, weights=resolve_weights(loops, weights))


@dataclass
class RunResult:
    """One optimization: the search (GA/PSO) and, if done, its polish."""

    label: str
    algo: str
    seed: int
    theta: np.ndarray
    fitness: float
    evaluations: int
    history: list[dict[str, float]]
    search_theta: np.ndarray
    search_fitness: float
    wall_s: float
    polish: dict[str, Any] | None = None

    def as_dict(self, names: list[str]) -> dict[str, Any]:
        return {
            "label": self.label,
            "algo": self.algo,
            "seed": self.seed,
            "params": dict(zip(names, map(float, self.theta))),
            "fitness": float(self.fitness),
            "evaluations": int(self.evaluations),
            "search_params": dict(zip(names, map(float, self.search_theta))),
            "search_fitness": float(self.search_fitness),
            "polish": self.polish,
            "wall_s": float(self.wall_s),
            "history": self.history,
        }


@dataclass
class AmplitudeResult:
    """Modal and physical quantities at one amplitude level, with standard errors (delta method)."""

    x0: float
    values: dict[str, float]
    stderr: dict[str, float]

    def as_dict(self) -> dict[str, Any]:
        return {"x0_m": self.x0, **self.values, "stderr": self.stderr}


DERIVED = ("xi", "fn_hz", "k", "c", "m")
DERIVED_UNITS = {"xi": "1", "fn_hz": "Hz", "k": "N/m", "c": "N s/m", "m": "kg"}


def derived_quantities(model: Model, theta: np.ndarray, x0: np.ndarray, meq_kg: float | None) -> np.ndarray:
    """xi, fn (Hz), k (N/m), c (N s/m), m (kg) at each amplitude, shape ``(5, K)`` (Eq. 4.8, 4.9, 2.4)."""
    state = model.modal(theta, x0, meq_kg)
    phys = to_physical(state)
    return np.stack([state.xi, state.wn / (2.0 * np.pi), phys["k"], phys["c"], phys["m"]])


def derived_table(model: Model, theta: np.ndarray, cov: np.ndarray, x0: np.ndarray, meq_kg: float | None) -> list[AmplitudeResult]:
    """:func:`derived_quantities` with standard errors from the parameter covariance (central differences)."""
    span = model.bounds[:, 1] - model.bounds[:, 0]
    h = 1e-6 * span
    grads = np.stack([
        (derived_quantities(model, theta + h[i] * e, x0, meq_kg) - derived_quantities(model, theta - h[i] * e, x0, meq_kg)) / (2.0 * h[i])
        for i, e in enumerate(np.eye(theta.size))
    ], axis=-1)  # (5, K, D)
    values = derived_quantities(model, theta, x0, meq_kg)
    var = np.einsum("qkd,de,qke->qk", grads, cov, grads)
    se = np.sqrt(np.clip(var, 0.0, None))
    return [
        AmplitudeResult(float(a), {q: float(values[i, k]) for i, q in enumerate(DERIVED)}, {q: float(se[i, k]) for i, q in enumerate(DERIVED)})
        for k, a in enumerate(x0)
    ]


@dataclass
class FitResult:
    """Everything one identification produced; build it with :meth:`from_runs`."""

    loops: LoopSet
    model: Model
    weights: str
    runs: list[RunResult]
    settings: dict[str, Any]
    best: int
    covariance: np.ndarray
    stderr_method: str
    amplitudes: list[AmplitudeResult]
    half_power: list[HalfPower]
    quality: dict[str, float | None]
    report: str | None = None

    @classmethod
    def from_runs(cls, objective: Objective, runs: list[RunResult], settings: dict[str, Any]) -> "FitResult":
        """Pick the best run, and derive standard errors, per-amplitude quantities and the half-power check."""
        if not runs:
            raise ValueError("a fit result needs at least one run")
        best = int(np.argmin([r.fitness for r in runs]))
        theta = runs[best].theta
        loops, model = objective.loops, objective.model
        if objective.weights == "ml":
            cov = np.linalg.pinv(fisher_information(objective, theta))
            method = "Cramer-Rao bound of the ML weights, noise sigma known"
        else:
            cov = covariance(objective, theta)
            source = "known" if loops.has_sigma else "estimated from the residuals"
            method = f"sandwich covariance of the thesis-weighted least squares, noise sigma {source}"
        levels, _ = amplitude_levels(loops.x0)
        force_amplitude = np.abs(first_harmonic(loops))
        relative = objective.residuals(theta) / force_amplitude[:, None]
        quality = {
            "rms_residual_pct": float(100.0 * np.sqrt(np.mean(relative**2))),
            "noise_sigma_pct": float(100.0 * np.sqrt(np.mean((loops.sigma / force_amplitude) ** 2))) if loops.has_sigma else None,
        }
        return cls(
            loops=loops,
            model=model,
            weights=objective.weights,
            runs=runs,
            settings=settings,
            best=best,
            covariance=cov,
            stderr_method=method,
            amplitudes=derived_table(model, theta, cov, levels, loops.meq_kg),
            half_power=half_power_by_amplitude(loops),
            quality=quality,
        )

    @property
    def theta(self) -> np.ndarray:
        return self.runs[self.best].theta

    @property
    def fitness(self) -> float:
        return float(self.runs[self.best].fitness)

    @property
    def evaluations(self) -> int:
        return int(sum(r.evaluations for r in self.runs))

    @property
    def params(self) -> dict[str, float]:
        return self.model.as_dict(self.theta)

    @property
    def stderr(self) -> dict[str, float]:
        return self.model.as_dict(np.sqrt(np.clip(np.diag(self.covariance), 0.0, None)))

    @property
    def at_bounds(self) -> list[str]:
        """Parameters that ended on a bound of the search space (the optimum may lie beyond it)."""
        return [
            p.name
            for p, v in zip(self.model.parameters, self.theta)
            if min(v - p.lower, p.upper - v) <= 1e-6 * (p.upper - p.lower)
        ]

    def objective(self) -> Objective:
        """A fresh objective of this fit (same loops, model and weights)."""
        return Objective(self.loops, self.model, weights=self.weights)

    def as_dict(self) -> dict[str, Any]:
        """The JSON document of ``hysid fit --json``."""
        names = self.model.names
        return {
            "params": self.params,
            "stderr": self.stderr,
            "stderr_method": self.stderr_method,
            "fitness": self.fitness,
            "evaluations": self.evaluations,
            "history": self.runs[self.best].history,
            "units": {p.name: p.unit for p in self.model.parameters},
            "bounds": {p.name: [p.lower, p.upper] for p in self.model.parameters},
            "at_bounds": self.at_bounds,
            "derived": [a.as_dict() for a in self.amplitudes],
            "half_power": [
                {**hp.as_dict(), "xi_fit": a.values["xi"]} for hp, a in zip(self.half_power, self.amplitudes)
            ],
            "dataset": {
                "name": self.loops.name,
                "loops": self.loops.n_loops,
                "meq_kg": self.loops.meq_kg,
                "true_params": self.loops.meta.get("true_params"),
            },
            "model": self.model.spec,
            "weights": self.weights,
            "settings": self.settings,
            "best_run": self.best,
            "quality": self.quality,
            "runs": [r.as_dict(names) for r in self.runs],
            "report": self.report,
        }


def fit_run(
    objective: Objective,
    algo: str,
    seed: int,
    *,
    polish: bool = True,
    label: str = "",
    options: dict[str, Any] | None = None,
    progress: Callable[[HistoryRow], None] | None = None,
) -> RunResult:
    """One GA/PSO run (thesis settings unless ``options`` override them), then an optional polish."""
    optimizer = ALGORITHMS[check_algorithm(algo)](objective.bounds, seed, **(options or {}))
    start = time.perf_counter()
    before = objective.evaluations
    rows = run(optimizer, objective, callback=progress)
    x, f = optimizer.best(1)
    search_theta, search_fitness = np.asarray(x[0], dtype=float), float(f[0])
    evaluations = objective.evaluations - before
    theta, fitness, polish_info = search_theta, search_fitness, None
    if polish:
        result = least_squares_polish(objective, search_theta)
        evaluations += int(result.evaluations)
        polish_info = {
            "fitness": float(result.fitness),
            "evaluations": int(result.evaluations),
            "success": bool(result.success),
            "message": str(result.message),
        }
        if result.fitness <= search_fitness:
            theta, fitness = np.asarray(result.theta, dtype=float), float(result.fitness)
    return RunResult(
        label=label or f"{algo.upper()} seed {seed}",
        algo=algo,
        seed=seed,
        theta=theta,
        fitness=fitness,
        evaluations=evaluations,
        history=[row.as_dict() for row in rows],
        search_theta=search_theta,
        search_fitness=search_fitness,
        wall_s=time.perf_counter() - start,
        polish=polish_info,
    )


def fit(
    loops: LoopSet,
    *,
    model: str = "thesis",
    algo: str = "pso",
    runs: int = 1,
    seed: int = 0,
    weights: str | None = None,
    polish: bool = True,
    options: dict[str, Any] | None = None,
    progress: Progress | None = None,
) -> FitResult:
    """``runs`` independent runs with seeds ``seed .. seed+runs-1``; the best one is the result."""
    check_algorithm(algo)
    if runs < 1:
        raise HysidInputError(f"--runs {runs}: the number of runs must be at least 1")
    if seed < 0:
        raise HysidInputError(f"--seed {seed}: seeds must be non-negative")
    objective = build_objective(loops, model, weights)
    results = []
    for i in range(runs):
        callback = None if progress is None else (lambda row, i=i: progress(i, row))
        results.append(fit_run(objective, algo, seed + i, polish=polish, label=f"run {i + 1}", options=options, progress=callback))
    settings = {
        "algo": algo,
        "runs": runs,
        "seeds": list(range(seed, seed + runs)),
        "polish": polish,
        "weights": objective.weights,
        "model": model,
        "options": dict(options or {}),
        "bounds_from_dataset": sorted(n for n in (loops.meta.get("bounds") or {}) if n in objective.model.names),
    }
    return FitResult.from_runs(objective, results, settings)
