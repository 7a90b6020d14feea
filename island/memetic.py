"""Memetic islands in one process: the search ``hysid fit`` runs on models a single run cannot fit.

    result = memetic_search(objective, starts=[theta0], seed=0, budget=40_000)

A model with memory (Bouc-Wen) or a force that is not smooth in time
(Coulomb friction's sgn) has an objective with narrow curved valleys and
several basins: a single GA/PSO run with one polish at its end (the thesis'
procedure, :func:`island.run.optimize`) lands in the wrong one for some seeds.
What makes a campaign of several islands succeed there, several cooperating
populations, is done here in one process, deterministically for a seed. Each
population is an :class:`Island`, the same one a campaign's node runs on such a
model (:mod:`island.node`, where migration and the global best travel over the
wire instead):

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
row per round (every island one iteration). :func:`starting_points` are the
starts a campaign's islands take: its ``start`` and what the model's terms read
off the loops.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.kinematics import Kinematics
from hysid_model.model import Model
from hysid_model.objective import Bounded
from island.algorithms import make_optimizer, switch_algorithm
from island.polish import MEMORY_NFEV, polish
from island.population import MAX_ITERATIONS
from island.run import HistoryRow, RunResult
from island.space import SpaceObjective
from island.termination import Termination

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
WIDENED_SHARE = 0.25
"""The share of the budget of a search again after a search bound was widened (fit and campaign alike): it
starts from the best so far."""
TIME_LIMIT_S = 40.0
"""Default time limit of ``hysid fit``'s search (the final polish comes after it): a fit within a minute."""
ISLAND_OPTIONS = {"population": POPULATION, "initial_population": 2 * POPULATION, "addpop_level": 1}
"""The island sizes of a campaign on such a model (:func:`hysid.campaigns.campaign`'s default there):
small swarms that the refinement feeds, as here."""
IMPROVED = 1e-9
"""Relative decrease of an island's best that counts as progress."""


def search_limits(termination: Termination | None, time_limit_s: float | None) -> tuple[int | None, float | None]:
    """The evaluations and seconds a memetic search may spend under the stop rules ``termination``: its budget and
    time limit where it has one of them (:attr:`~island.termination.Termination.bounded`), else :data:`BUDGET`
    evaluations and ``time_limit_s`` (``hysid fit``: :data:`TIME_LIMIT_S`; a campaign's refit: none)."""
    if termination is None or not termination.bounded:
        return BUDGET, time_limit_s
    return termination.budget, termination.time_limit_s


def needs_islands(model: Model) -> bool:
    """Whether ``model`` is one a single run cannot be trusted on: memory terms, a force evaluated sample
    by sample, or the sign of the velocity (Coulomb friction) among its force's features."""
    if model.has_memory:
        return True
    probe = Kinematics(x0=np.ones(1), omega=np.ones(1))
    return "sgn" in model.coefficients(model.bounds.mean(axis=1)[None, :], probe)


def starting_points(objective: Any, start: Sequence[float] | None) -> np.ndarray:
    """Rows in the model's parameters for an island's first population: ``start`` (the survey's linear
    estimate, a campaign's ``start``) and, on it, the values each of the model's terms reads off the loops'
    shape (:meth:`hysid_model.terms.Term.data_starts`, e.g. a Bouc-Wen spring's stiffness and yield from
    the reversals and the plateau), clipped into the bounds; none without ``start``."""
    model = objective.model
    if start is None:
        return np.empty((0, model.dim))
    base = dict(zip(model.names, map(float, start)))
    rows = [model.from_dict(base)] + [model.from_dict({**base, **point}) for t in model.terms for point in t.data_starts(objective.loops, model.names)]
    return np.clip(np.array(rows), objective.bounds[:, 0], objective.bounds[:, 1])


class Island(Bounded):
    """One memetic island in the coordinates of :mod:`island.space` (module docstring): the thesis' PSO
    or GA with small populations, its best refined every :data:`REFINE_EVERY` iterations, a fresh start
    once it has stalled.

    It is driven as an ask/tell optimizer, by :func:`memetic_search`'s rounds and by a campaign's node
    (:mod:`island.node`, through :func:`island.run.run`): ``iteration``, ``evaluations`` (its own
    refinements and starting points included), ``gain`` and ``history`` (the best so far after each
    iteration) run on across restarts, while :meth:`best` and :meth:`inject` are the current search's:
    what it migrates, refines and takes in. ``starts`` (rows in ``objective``'s coordinates) join its
    first population; ``polished`` maps points already refined (their bytes), shared by the islands of
    one search, to what refining them gave: no point is refined twice.
    """

    def __init__(
        self,
        objective: SpaceObjective,
        algo: str,
        seed: int,
        options: Mapping[str, Any] | None = None,
        *,
        starts: np.ndarray | None = None,
        polished: dict[bytes, float] | None = None,
    ) -> None:
        self.objective = objective
        self.algo, self.seed, self.options = algo, seed, dict(options or {})
        self.starts = None if starts is None or not len(starts) else np.asarray(starts, dtype=float).reshape(-1, objective.dim)
        self.polished = {} if polished is None else polished
        self.optimizer = make_optimizer(algo, objective.bounds, seed, self.options)
        self.history: list[float] = []
        """The best fitness so far after each iteration (across restarts)."""
        self.restarts = 0
        self.since_refined, self.stalled, self.last_best = 0, 0, np.inf
        self._earlier = (0, 0, 0.0)
        """Iterations, evaluations and gain of the searches before the current one."""
        self._own = 0
        """Evaluations of its starting points and refinements."""
        self._restart = False

    @property
    def bounds(self) -> np.ndarray:
        return self.objective.bounds

    @property
    def iteration(self) -> int:
        return self._earlier[0] + self.optimizer.iteration

    @property
    def evaluations(self) -> int:
        return self._earlier[1] + self.optimizer.evaluations + self._own

    @property
    def gain(self) -> float:
        return self._earlier[2] + self.optimizer.gain

    @property
    def done(self) -> bool:
        return bool(self.history) and self.iteration >= self.optimizer.iterations

    @property
    def fitness(self) -> float:
        """The current search's best fitness (inf before its initial population)."""
        _, f = self.optimizer.best(1)
        return float(f[0]) if f.size else np.inf

    @property
    def quiet(self) -> bool:
        """A restarted search takes no migrants for its first :data:`QUIET` iterations."""
        return self.restarts > 0 and self.optimizer.iteration < QUIET

    @property
    def stale(self) -> bool:
        """No progress for :data:`STALL` refinements: time to restart, unless it holds the best."""
        return self.stalled >= STALL

    def ask(self) -> np.ndarray:
        if self._restart:
            self._fresh()
        return self.optimizer.ask()

    def tell(self, x: np.ndarray, f: np.ndarray) -> None:
        told = len(self.optimizer.history)
        self.optimizer.tell(x, f)
        if len(self.optimizer.history) == told:
            return
        if not told and not self.restarts and self.starts is not None:
            self.optimizer.inject(self.starts, self._evaluate(self.starts))
        self.history.append(min(self.history[-1] if self.history else np.inf, self.fitness))

    def step(self) -> None:
        """One iteration (the initial population first) on its objective."""
        done = len(self.history)
        while len(self.history) == done:
            x = self.ask()
            self.tell(x, self.objective(x))

    def inject(self, x: np.ndarray, f: np.ndarray) -> int:
        """Migrants with locally evaluated fitness, offered to the current search (none while it is quiet)."""
        return 0 if self.quiet else self.optimizer.inject(x, f)

    def best(self, k: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """The current search's ``k`` best and their fitness, best first."""
        return self.optimizer.best(k)

    def switch(self, algo: str, options: Mapping[str, Any]) -> Island:
        """The current search carried on by ``algo`` (a mixed campaign's share, :func:`island.algorithms.switch_algorithm`),
        and every restart after it."""
        self.optimizer = switch_algorithm(self.optimizer, algo, dict(options))
        self.algo, self.options = algo, dict(options)
        return self

    def refine(self) -> None:
        """Every :data:`REFINE_EVERY`-th call (one per iteration): the current search's best polished with
        :data:`REFINE_NFEV` residual calls, the refined point in the place of its worst, and the count of
        refinements without progress (:attr:`stale`) updated."""
        self.since_refined += 1
        if self.since_refined < REFINE_EVERY:
            return
        self.since_refined = 0
        x, f = self.best(1)
        key = x[0].tobytes()
        if key not in self.polished:
            before = self.objective.evaluations
            p = polish(self.objective, x[0], max_nfev=REFINE_NFEV)
            self._own += self.objective.evaluations - before
            self.polished[key] = p.fitness
            if p.fitness < f[0]:
                u = np.asarray(p.theta, dtype=float)
                self.polished[u.tobytes()] = p.fitness
                self.optimizer.inject(u[None, :], np.array([p.fitness]))
        best = float(self.fitness)
        self.stalled = 0 if best < self.last_best * (1 - IMPROVED) else self.stalled + 1
        self.last_best = min(self.last_best, best)

    def restart(self) -> None:
        """Start afresh at the next :meth:`ask`: a new initial population from a random stream of its own."""
        self._restart = True

    def _fresh(self) -> None:
        self._earlier = (self.iteration + 1, self._earlier[1] + self.optimizer.evaluations, self.gain)
        self.restarts += 1
        self.optimizer = make_optimizer(self.algo, self.bounds, self.seed + 7919 * self.restarts, self.options)
        self.since_refined, self.stalled, self.last_best, self._restart = 0, 0, np.inf, False

    def _evaluate(self, x: np.ndarray) -> np.ndarray:
        self._own += x.shape[0]
        return self.objective(x)


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
    (``__call__``, ``weighted_residuals``, ``residual_rows``, ``jacobian``, ``bounds``, ``model``), as
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
    options = {**ISLAND_OPTIONS, "population": population, "initial_population": 2 * population, "synchronous": True, "iterations": MAX_ITERATIONS}
    first = space.space.to_u(np.clip(np.asarray(starts, dtype=float).reshape(-1, space.dim), *objective.bounds.T)) if len(starts) else None
    polished: dict[bytes, float] = {}
    pool = [Island(space, "pso", seed * 1000 + i, options, starts=first if i == 0 else None, polished=polished) for i in range(islands)]
    rows: list[HistoryRow] = []
    best_u, best_f = None, np.inf

    def spent() -> bool:
        return (budget is not None and space.evaluations >= budget) or (time_limit_s is not None and time.perf_counter() - began >= time_limit_s)

    round_ = 0
    while not spent():
        for island in pool:
            island.step()
            if not spent():
                island.refine()
            if spent():
                break
        round_ += 1
        if round_ % MIGRATE_EVERY == 0 and len(pool) > 1:
            outgoing = [island.best(MIGRANTS) for island in pool]
            for i, island in enumerate(pool):
                island.inject(*outgoing[i - 1])  # the fitness was evaluated here, in this process
        leader = min(range(len(pool)), key=lambda i: pool[i].fitness)
        x, f = pool[leader].best(1)
        if f[0] < best_f:
            best_u, best_f = x[0].copy(), float(f[0])
        for i, island in enumerate(pool):
            if i != leader and island.stale:
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
        label=label or f"memetic islands seed {seed}",
        algo="memetic",
        seed=seed,
        theta=theta,
        fitness=fitness,
        evaluations=space.evaluations + 1,
        history=[r.as_dict() for r in rows],
        search_theta=search_theta,
        search_fitness=float(search_f),
        wall_s=time.perf_counter() - began,
        polish={
            "fitness": float(final.fitness),
            "evaluations": int(final.evaluations),
            "success": bool(final.success),
            "message": str(final.message),
            "islands": islands,
            "restarts": sum(i.restarts for i in pool),
        },
    )
