"""Memetic islands in one process: the search ``hysid fit`` runs on models a single run cannot fit.

    result = memetic_search(objective, starts=[theta0], seed=0, budget=40_000)

A model with memory (Bouc-Wen) or a force that is not smooth in time
(Coulomb friction's sgn) has an objective with narrow curved valleys and
several basins: a single GA/PSO run with one polish at its end (the thesis'
procedure, :func:`island.run.optimize`) lands in the wrong one for some seeds.
What makes a campaign of several islands succeed there, several cooperating
populations, is done here in one process, deterministically for a seed:

* the islands search in the coordinates of :mod:`island.space` (positive scale
  parameters on a log scale: the ridges k_bw z_y = const become straight and
  uniform draws cover every decade), each a PSO of the thesis (section 5.1) with
  a small swarm, advanced one iteration at a time in turn;
* the starting points (the survey's linear estimate, a term's guesses from the
  loops' shape) join the first island's swarm after its initial population;
* memetic refinement (Moscato 1989; the island model's "local refinement" of
  section 3.1): every :data:`REFINE_EVERY` iterations an island's best is
  polished by bounded least squares (:mod:`island.polish`) with a small budget,
  and the refined point replaces its worst particle, so that the swarm moves
  on from the bottom of the valley it found rather than from its rim;
* ring migration of each island's :data:`MIGRANTS` best every
  :data:`MIGRATE_EVERY` iterations, as a campaign's islands do;
* restarts: an island whose best has not improved for :data:`STALL` refinement
  rounds (other than the island holding the global best, which the search also
  keeps) starts afresh from a new uniform draw and takes no migrants for
  :data:`QUIET` iterations, so the budget keeps exploring other basins;
* the global best is polished to convergence at the end, with a budget that
  does not run out on memory models (:data:`island.polish.MEMORY_NFEV` residual calls).

The budget (``budget`` evaluations and/or ``time_limit_s``) counts every model
evaluation: candidates, residual vectors and Jacobian probes
(:class:`island.space.SpaceObjective`); it is checked between steps, so the
search may overshoot it by one refinement or one population, and the final
polish comes on top. The result is a
:class:`island.run.RunResult` in the model's parameters; its history has one
row per round (every island one iteration).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.model import Model
from hysid_model.terms import Kinematics
from island.polish import MEMORY_NFEV, polish
from island.population import MAX_ITERATIONS, PopulationOptimizer
from island.pso import PSO
from island.run import HistoryRow, RunResult
from island.space import SpaceObjective

ISLANDS = 4
POPULATION = 16
"""Particles per island (the initial draw is twice that)."""
REFINE_EVERY = 3
"""Iterations of an island between two refinements of its best."""
REFINE_NFEV = 30
"""Residual calls of one refinement (each Jacobian costs 2 D probes more)."""
MIGRATE_EVERY = 3
MIGRANTS = 2
STALL = 3
"""Refinement rounds without improvement after which an island restarts (all but the one holding the best:
with migration the others soon hold the same best, and a basin that every island shares is the one a
restart must be free to leave)."""
QUIET = 9
"""Iterations for which a restarted island takes no migrants: else the old best pulls it back at once."""
BUDGET = 10_000
"""Default evaluations of a search (and of a campaign on such a model): enough for the hard problems of
``hysid bench search``, a few seconds on ten loops."""
TIME_LIMIT_S = 40.0
"""Default time limit of ``hysid fit``'s search (the final polish comes after it): a fit within a minute."""
ISLAND_OPTIONS = {"population": POPULATION, "initial_population": 2 * POPULATION, "addpop_level": 1}
"""The island sizes of a campaign on such a model (:func:`hysid.campaigns.campaign`'s default there):
small swarms that the refinement feeds, as here."""
IMPROVED = 1e-9
"""Relative decrease of an island's best that counts as progress."""


def needs_islands(model: Model) -> bool:
    """Whether ``model`` is one a single run cannot be trusted on: memory terms, a force evaluated sample
    by sample, or the sign of the velocity (Coulomb friction) among its force's features."""
    if model.has_memory:
        return True
    probe = Kinematics(x0=np.ones(1), omega=np.ones(1))
    return "sgn" in model.coefficients(model.bounds.mean(axis=1)[None, :], probe)


class Refiner:
    """Memetic refinement for an island that searches in the model's parameters (a campaign's node):
    its best polished with :data:`REFINE_NFEV` residual calls in the coordinates of :mod:`island.space`
    and handed back as a migrant would be. Each point is refined once."""

    def __init__(self, objective: Any) -> None:
        self.space = SpaceObjective(objective)
        self.refined: set[bytes] = set()

    def __call__(self, optimizer: PopulationOptimizer) -> int:
        """Refine ``optimizer``'s best; returns the evaluations it cost."""
        x, f = optimizer.best(1)
        if not f.size or x[0].tobytes() in self.refined:
            return 0
        before = self.space.evaluations
        p = polish(self.space, self.space.space.to_u(x[0]), max_nfev=REFINE_NFEV)
        self.refined.add(x[0].tobytes())
        if p.fitness < f[0]:
            theta = self.space.space.to_theta(p.theta)
            self.refined.add(theta.tobytes())
            optimizer.inject(theta[None, :], np.array([p.fitness]))
        return self.space.evaluations - before


class Island:
    """One population of the search, its refinement bookkeeping and its restarts."""

    def __init__(self, bounds: np.ndarray, seed: int, population: int) -> None:
        self.seed, self.population, self.bounds = seed, population, bounds
        self.restarts = 0
        self.optimizer = self._fresh()
        self.since_refined = 0
        self.stalled = 0
        self.last_best = np.inf

    def _fresh(self) -> PopulationOptimizer:
        return PSO(self.bounds, self.seed + 7919 * self.restarts, population=self.population,
                   initial_population=2 * self.population, iterations=MAX_ITERATIONS, addpop_level=1, synchronous=True)

    def restart(self) -> None:
        self.restarts += 1
        self.optimizer = self._fresh()
        self.since_refined, self.stalled, self.last_best = 0, 0, np.inf

    def step(self, objective: SpaceObjective) -> None:
        """One iteration (the initial population first)."""
        done = len(self.optimizer.history)
        while len(self.optimizer.history) == done:
            x = self.optimizer.ask()
            self.optimizer.tell(x, objective(x))

    @property
    def best(self) -> tuple[np.ndarray, float]:
        """The island's best and its fitness (inf, at the bounds' centre, before its first population)."""
        x, f = self.optimizer.best(1)
        return (x[0], float(f[0])) if f.size else (self.bounds.mean(axis=1), np.inf)


def memetic_search(
    objective: Any,
    starts: Sequence[np.ndarray] = (),
    seed: int = 0,
    *,
    budget: int | None = BUDGET,
    time_limit_s: float | None = None,
    islands: int = ISLANDS,
    population: int = POPULATION,
    label: str = "",
    callback: Callable[[HistoryRow], None] | None = None,
) -> RunResult:
    """The best of ``objective`` found by memetic islands (module docstring) within ``budget`` evaluations
    and/or ``time_limit_s`` seconds (at least one must be set); ``starts`` are parameter vectors in the
    model's parameters. ``objective`` has the contract of :class:`hysid_model.objective.Objective`
    (``__call__``, ``weighted_residuals``, ``jacobian``, ``bounds``, ``model``), as
    :class:`hysid_model.harmonics.HarmonicObjective` has."""
    if budget is None and time_limit_s is None:
        raise HysidInputError("a memetic search needs a budget of evaluations or a time limit", param="budget", value=None)
    if budget is not None and (isinstance(budget, bool) or not isinstance(budget, int) or budget < 1):
        raise HysidInputError("must be a positive number of evaluations", param="budget", value=budget)
    if time_limit_s is not None and not (isinstance(time_limit_s, (int, float)) and time_limit_s > 0):
        raise HysidInputError("must be a positive number of seconds", param="time_limit_s", value=time_limit_s)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise HysidInputError("seeds must be non-negative integers", param="seed", value=seed)
    space = SpaceObjective(objective)
    began = time.perf_counter()
    pool = [Island(space.bounds, seed * 1000 + i, population) for i in range(islands)]
    rows: list[HistoryRow] = []
    polished: dict[bytes, float] = {}
    """Points already refined (their bytes) and what refining them gave: never refined twice."""
    best_u, best_f = None, np.inf

    def spent() -> bool:
        return (budget is not None and space.evaluations >= budget) or (
            time_limit_s is not None and time.perf_counter() - began >= time_limit_s
        )

    def refine(island: Island) -> None:
        x, f = island.best
        key = x.tobytes()
        if key in polished:
            return
        p = polish(space, x, max_nfev=REFINE_NFEV)
        polished[key] = p.fitness
        if p.fitness < f:
            polished[np.asarray(p.theta, dtype=float).tobytes()] = p.fitness
            island.optimizer.inject(np.asarray(p.theta, dtype=float)[None, :], np.array([p.fitness]))

    round_ = 0
    while not spent():
        for i, island in enumerate(pool):
            island.step(space)
            if island.optimizer.iteration == 0 and i == 0 and starts:
                u = space.space.to_u(np.clip(np.asarray(starts, dtype=float).reshape(-1, space.dim), *objective.bounds.T))
                island.optimizer.inject(u, space(u))
            island.since_refined += 1
            if island.since_refined >= REFINE_EVERY and not spent():
                island.since_refined = 0
                refine(island)
                _, f = island.best
                island.stalled = 0 if f < island.last_best * (1 - IMPROVED) else island.stalled + 1
                island.last_best = min(island.last_best, f)
            if spent():
                break
        round_ += 1
        if round_ % MIGRATE_EVERY == 0 and len(pool) > 1:
            outgoing = [island.optimizer.best(MIGRANTS) for island in pool]
            for i, island in enumerate(pool):
                if island.restarts == 0 or island.optimizer.iteration >= QUIET:
                    x, f = outgoing[i - 1]
                    island.optimizer.inject(x, f)  # the fitness was evaluated here, in this process
        leader = min(range(len(pool)), key=lambda i: pool[i].best[1])
        x, f = pool[leader].best
        if f < best_f:
            best_u, best_f = x.copy(), f
        for i, island in enumerate(pool):
            if i != leader and island.stalled >= STALL:
                island.restart()
        row = HistoryRow(round_, best_f, space.evaluations, time.perf_counter() - began)
        rows.append(row)
        if callback is not None:
            callback(row)
    assert best_u is not None
    search_theta, search_f = space.space.to_theta(best_u), best_f
    final = polish(space, best_u, max_nfev=MEMORY_NFEV)
    theta = space.space.to_theta(final.theta if final.fitness <= best_f else best_u)
    fitness = float(objective(theta[None, :])[0])
    return RunResult(
        label=label or f"memetic islands seed {seed}", algo="memetic", seed=seed, theta=theta, fitness=fitness,
        evaluations=space.evaluations + 1, history=[r.as_dict() for r in rows], search_theta=search_theta,
        search_fitness=float(search_f), wall_s=time.perf_counter() - began,
        polish={"fitness": float(final.fitness), "evaluations": int(final.evaluations), "success": bool(final.success),
                "message": str(final.message), "islands": islands, "restarts": sum(i.restarts for i in pool)},
    )
