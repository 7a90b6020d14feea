"""What a user would pick instead of hysid's islands, on the same objective, bounds and evaluation budget.

Every peer gets the weighted residuals of :class:`hysid_model.objective.Objective`
(whose sum of squares is the fitness), the same bounds and the same budget,
and its evaluations are counted alike through a :class:`Tracker`: a candidate
or a residual vector is one evaluation, a finite-difference Jacobian costs its
probes. The tracker also records the best fitness after every evaluation that
improved it (with the evaluations and seconds so far), from which the bench
reads the time to success.

* ``least_squares``: :func:`scipy.optimize.least_squares` (``trf``, its
  2-point Jacobian, ``x_scale="jac"``, its tolerances) from uniform random
  points within the bounds, one start after another until the budget is spent;
* ``differential_evolution``: :func:`scipy.optimize.differential_evolution`
  with its defaults (``best1bin``, population 15 D, ``polish=True``), its
  ``maxiter`` set so that its generations leave a tenth of the budget to its
  polish;
* ``cma_es``: pycma's ``fmin2`` with IPOP restarts (population doubled at each),
  in coordinates scaled to [0, 1] per parameter, sigma0 0.3, until the budget;
* ``pygmo``: a pygmo archipelago of 4 self-adaptive DE islands (``sade``,
  20 individuals each, ring, multiprocessing islands) evolved 10 generations at
  a time until the budget (its evaluations are counted by pygmo); no polish.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from hysid_model.objective import Objective

PYGMO_ISLANDS = 4
PYGMO_POPULATION = 20
PYGMO_GENERATIONS = 10


class BudgetSpent(Exception):
    """The tracker's budget is spent: the peer stops here."""


class Tracker:
    """Counts the evaluations of ``objective`` (a peer stops at ``budget``) and records the improvements."""

    def __init__(self, objective: Any, budget: int) -> None:
        self.objective, self.budget = objective, budget
        self.evaluations = 0
        self.best = np.inf
        self.best_x: np.ndarray | None = None
        self.trace: list[tuple[int, float, float]] = []
        """(evaluations, seconds, best fitness) at every improvement."""
        self.began = time.perf_counter()

    def _count(self, n: int) -> None:
        if self.evaluations >= self.budget:
            raise BudgetSpent
        self.evaluations += n

    def _seen(self, x: np.ndarray, f: np.ndarray) -> None:
        i = int(np.argmin(f))
        if f[i] < self.best:
            self.best, self.best_x = float(f[i]), np.array(x[i], dtype=float)
            self.trace.append((self.evaluations, time.perf_counter() - self.began, self.best))

    def fitness(self, pop: np.ndarray) -> np.ndarray:
        pop = np.atleast_2d(np.asarray(pop, dtype=float))
        self._count(pop.shape[0])
        f = self.objective(pop)
        self._seen(pop, f)
        return f

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        self._count(1)
        r = self.objective.weighted_residuals(theta)
        f = float(r @ r)
        self._seen(np.asarray(theta, dtype=float)[None, :], np.array([f if np.isfinite(f) else np.inf]))
        return np.where(np.isfinite(r), r, 1e150)

    def result(self) -> dict[str, Any]:
        return {"fitness": self.best, "evaluations": self.evaluations, "wall_s": time.perf_counter() - self.began, "trace": self.trace}


def least_squares_multistart(objective: Any, budget: int, seed: int) -> dict[str, Any]:
    from scipy.optimize import least_squares  # on first use: a fast CLI and island start

    tracker = Tracker(objective, budget)
    rng = np.random.default_rng(seed)
    lower, upper = objective.bounds[:, 0], objective.bounds[:, 1]
    starts = 0
    try:
        while True:
            starts += 1
            least_squares(tracker.residuals, lower + (upper - lower) * rng.random(lower.size), bounds=(lower, upper), method="trf", x_scale="jac")
    except BudgetSpent:
        pass
    return {**tracker.result(), "starts": starts}


def differential_evolution_peer(objective: Any, budget: int, seed: int) -> dict[str, Any]:
    from scipy.optimize import differential_evolution  # on first use: a fast CLI and island start

    tracker = Tracker(objective, budget)
    size = 15 * objective.dim
    maxiter = max(int(0.9 * budget / size) - 1, 1)
    try:
        differential_evolution(
            lambda x: tracker.fitness(np.asarray(x).T), objective.bounds, seed=seed, maxiter=maxiter, polish=True, vectorized=True, updating="deferred"
        )
    except BudgetSpent:
        pass
    return {**tracker.result(), "maxiter": maxiter}


def cma_es(objective: Any, budget: int, seed: int) -> dict[str, Any]:
    import cma

    tracker = Tracker(objective, budget)
    lower, upper = objective.bounds[:, 0], objective.bounds[:, 1]
    scaled = lambda u: lower + (upper - lower) * np.asarray(u, dtype=float)
    rng = np.random.default_rng(seed)
    options = {"bounds": [0.0, 1.0], "maxfevals": budget, "seed": seed + 1, "verbose": -9}
    try:
        cma.fmin2(
            None,
            lambda: rng.random(lower.size),
            0.3,
            options,
            restarts=9,
            incpopsize=2,
            parallel_objective=lambda xs: list(tracker.fitness(scaled(np.array(xs)))),
        )
    except BudgetSpent:
        pass
    return tracker.result()


class PygmoProblem:
    """The objective as a pygmo user-defined problem (batch fitness for its islands). pygmo copies it into
    every island and process: it travels as the loops, model and weights and is rebuilt there."""

    def __init__(self, objective: Any) -> None:
        self.objective = objective

    def __getstate__(self) -> dict[str, Any]:
        return {"loops": self.objective.loops, "model": self.objective.model, "weights": self.objective.weights}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.objective = Objective(state["loops"], state["model"], weights=state["weights"])

    def fitness(self, x: np.ndarray) -> list[float]:
        return [float(self.objective(np.asarray(x)[None, :])[0])]

    def batch_fitness(self, dvs: np.ndarray) -> np.ndarray:
        return self.objective(np.asarray(dvs).reshape(-1, self.objective.dim))

    def get_bounds(self) -> tuple[list[float], list[float]]:
        return list(self.objective.bounds[:, 0]), list(self.objective.bounds[:, 1])


def pygmo_archipelago(objective: Any, budget: int, seed: int) -> dict[str, Any]:
    import pygmo as pg

    began = time.perf_counter()
    archi = pg.archipelago(
        n=PYGMO_ISLANDS,
        t=pg.ring(),
        algo=pg.sade(gen=PYGMO_GENERATIONS),
        prob=PygmoProblem(objective),
        pop_size=PYGMO_POPULATION,
        seed=seed,
        udi=pg.mp_island(),
    )
    fevals = 0
    while fevals < budget:
        archi.evolve()
        archi.wait_check()
        fevals = sum(isl.get_population().problem.get_fevals() for isl in archi)
    best = float(np.min([f[0] for f in archi.get_champions_f()]))
    return {"fitness": best, "evaluations": int(fevals), "wall_s": time.perf_counter() - began, "trace": []}


def pygmo_available() -> str | None:
    """None if pygmo imports, else why not (the bench says so and leaves the peer out)."""
    try:
        import pygmo  # noqa: F401
    except ImportError as exc:
        return f"pygmo is not installed ({exc}); it is an optional bench-only dependency: pip install pygmo"
    return None


PEERS = {
    "least_squares": least_squares_multistart,
    "differential_evolution": differential_evolution_peer,
    "cma_es": cma_es,
    "pygmo": pygmo_archipelago,
}
