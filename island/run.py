"""One optimization run: the ask/tell loop, its record, and the polish that ends it.

    rows = run(optimizer, objective, callback=print_row, should_stop=stop_event.is_set, migrate=exchange)

After every completed iteration (iteration 0 = the initial population) a
:class:`HistoryRow` is recorded and handed to ``callback``; then, unless the
budget is spent, ``migrate(optimizer)`` may publish the best and ``inject``
received migrants, and may return the optimizer to go on with (an island that
a mixed campaign moves to another algorithm, :mod:`island.share`). ``should_stop()`` is asked before every ``ask`` and ends
the run early, leaving the optimizer resumable (``state_dict``); a
:class:`~island.termination.Termination` ends it by its rules.

:func:`optimize` is a whole single-node run: a seeded GA/PSO run, then the
least-squares polish of :mod:`island.polish`, recorded as a :class:`RunResult`
(:func:`polish_run` polishes any run the same way, e.g. a campaign's best).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any, Protocol, TypeVar

import numpy as np

from island.algorithms import make_optimizer
from island.polish import polish
from island.population import PopulationOptimizer
from island.termination import Termination


class Searcher(Protocol):
    """What :func:`run` drives: an ask/tell optimizer (:class:`PopulationOptimizer`, or a memetic island of
    :mod:`island.memetic`)."""

    @property
    def history(self) -> list[float]: ...
    @property
    def done(self) -> bool: ...
    @property
    def iteration(self) -> int: ...
    @property
    def evaluations(self) -> int: ...
    def ask(self) -> np.ndarray: ...
    def tell(self, x: np.ndarray, f: np.ndarray) -> None: ...


_S = TypeVar("_S", bound=Searcher)


@dataclass
class HistoryRow:
    """One completed iteration: best fitness so far, candidates told so far, seconds since ``run`` started."""

    iteration: int
    best_fitness: float
    evaluations: int
    wall_s: float

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def run(
    optimizer: _S,
    objective: Callable[[np.ndarray], np.ndarray],
    *,
    callback: Callable[[HistoryRow], None] | None = None,
    should_stop: Callable[[], bool] | None = None,
    migrate: Callable[[_S], _S | None] | None = None,
    termination: Termination | None = None,
) -> list[HistoryRow]:
    """Ask, evaluate, tell until the optimizer is done, ``should_stop()`` or a ``termination`` rule;
    returns the rows of this run.

    A resumed optimizer continues where it stopped (a pending batch is asked again).
    """
    start = time.perf_counter()
    rows: list[HistoryRow] = []
    recorded = len(optimizer.history)
    best, best_at = np.inf, 0
    while not optimizer.done:
        if should_stop is not None and should_stop():
            break
        if (
            termination is not None
            and rows
            and termination.reason(evaluations=optimizer.evaluations, best=best, best_at=best_at, elapsed_s=time.perf_counter() - start)
        ):
            break
        x = optimizer.ask()
        optimizer.tell(x, objective(x))
        if len(optimizer.history) == recorded:
            continue
        recorded = len(optimizer.history)
        row = HistoryRow(optimizer.iteration, optimizer.history[-1], optimizer.evaluations, time.perf_counter() - start)
        rows.append(row)
        if row.best_fitness < best:
            best, best_at = row.best_fitness, row.evaluations
        if callback is not None:
            callback(row)
        if migrate is not None and not optimizer.done:
            optimizer = migrate(optimizer) or optimizer
    return rows


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

    @classmethod
    def unpolished(
        cls, label: str, algo: str, seed: int, theta: np.ndarray, fitness: float, evaluations: int, history: list[dict[str, float]], wall_s: float = 0.0
    ) -> RunResult:
        """A search's result before any polish: what the search found (``search_theta``, ``search_fitness``) is the
        result itself (:func:`polish_run` may then move ``theta`` and ``fitness`` on)."""
        theta = np.asarray(theta, dtype=float)
        return cls(label, algo, seed, theta, fitness, evaluations, history, theta.copy(), fitness, wall_s)

    def __repr__(self) -> str:
        polish = ", polished" if self.polish else ""
        return f"<RunResult {self.label} ({self.algo}, seed {self.seed}): fitness {self.fitness:.6g} after {self.evaluations:,} evaluations{polish}>"

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


def polish_run(objective: Any, result: RunResult) -> RunResult:
    """``result`` refined by the least-squares polish (section 3.1): its theta where that is no worse, the cost counted."""
    p = polish(objective, result.theta)
    result.polish = {"fitness": float(p.fitness), "evaluations": int(p.evaluations), "success": bool(p.success), "message": str(p.message)}
    if p.fitness <= result.fitness:
        result.theta, result.fitness = np.asarray(p.theta, dtype=float), float(p.fitness)
    result.evaluations += int(p.evaluations)
    return result


def optimize(
    objective: Any,
    algo: str,
    seed: int,
    *,
    polish: bool = True,
    label: str = "",
    options: dict[str, Any] | None = None,
    termination: Termination | None = None,
    callback: Callable[[HistoryRow], None] | None = None,
    start: np.ndarray | None = None,
) -> RunResult:
    """One GA/PSO run on ``objective`` (thesis settings unless ``options`` override them), then an optional polish.

    ``start`` (a parameter vector, e.g. a linear estimate or an earlier best) joins the population
    after the initial one, as a migrant would (evaluated here, replacing the worst).
    """
    optimizer = make_optimizer(algo, objective.bounds, seed, options)
    began = time.perf_counter()
    before = objective.evaluations

    def seed_start(opt: PopulationOptimizer) -> None:
        if opt.iteration == 0 and start is not None:
            x = np.clip(np.asarray(start, dtype=float).reshape(1, -1), objective.bounds[:, 0], objective.bounds[:, 1])
            opt.inject(x, objective(x))

    rows = run(optimizer, objective, callback=callback, termination=termination, migrate=None if start is None else seed_start)
    x, f = optimizer.best(1)
    result = RunResult.unpolished(
        label or f"{algo.upper()} seed {seed}", algo, seed, x[0], float(f[0]), objective.evaluations - before, [row.as_dict() for row in rows]
    )
    if polish:
        polish_run(objective, result)
    result.wall_s = time.perf_counter() - began
    return result
