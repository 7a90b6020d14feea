"""What the thesis' GA and PSO share, in ask/tell form: batches, redraws, migrants, history, checkpoints.

Both programs of Appendix A evaluate candidates in a ``try``/``catch``: a
candidate whose fitness cannot be computed ("Couldn't calculate. Generating new
chromosome") is replaced by a uniform random one (Eq. 3.2) and evaluated
again, until every candidate of the batch has a fitness. Here a batch is asked
for as a whole; after ``tell`` the rows with non-finite fitness are redrawn
and asked for again, and only a complete batch moves the algorithm on. The
program retries forever; ``redraw_limit`` caps the rounds per batch so that a
model that cannot be computed anywhere still ends (its leftovers keep fitness
inf and sort last).

A subclass supplies the batches (``_next_batch``), what a complete batch does
(``_finish``), the migrant policy (``_take``), its known candidates
(``_known``), its own state and, where it asks more of the population size
than at least 1 (the GA: even), ``_checked_population``; everything else lives here.
"""

from __future__ import annotations

import inspect
from abc import abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from hysid_model.errors import HysidInputError
from island.addpop import addpop_size
from island.optimizer import AskTell
from island.rng import new_rng, rng_from_state, rng_state, uniform_population

MIGRANT_POLICIES = ("replace_worst",)
"""``replace_worst``: each migrant replaces the current worst member if it is better than it."""


def check_bounds(bounds: np.ndarray) -> np.ndarray:
    """``(D, 2)`` finite bounds with lower < upper, as a float array."""
    b = np.array(bounds, dtype=float)
    if b.ndim != 2 or b.shape[1] != 2 or b.shape[0] < 1:
        raise HysidInputError(f"bounds must be a (D, 2) array of [lower, upper] rows, got shape {b.shape}")
    if not np.all(np.isfinite(b)) or np.any(b[:, 0] >= b[:, 1]):
        raise HysidInputError(f"bounds must be finite with lower < upper in every row, got {b.tolist()}")
    return b


MAX_POPULATION = 1_000_000
"""Largest initial population or swarm (the thesis: 6000): a million candidates are evaluated in one
vectorized call within a few GB of memory."""
GAIN_AT_ZERO = 16.0
"""The gain counted for reaching an exact zero from a positive best: float64's 16 digits."""
MAX_ITERATIONS = 2**53
"""Largest iteration budget (iterations travel as exact float64 counts)."""


def check_int(algorithm: str, name: str, value: Any, minimum: int, maximum: int = 2**62) -> int:
    """An integer option in ``[minimum, maximum]``, else a one-line error naming the option."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise HysidInputError(f"{algorithm} {name} must be an integer >= {minimum}", param=name, value=value)
    if value > maximum:
        raise HysidInputError(f"{algorithm} {name} must be at most {maximum:,}", param=name, value=value)
    return int(value)


def check_float(algorithm: str, name: str, value: Any, minimum: float, maximum: float = np.inf) -> float:
    """A finite number in ``[minimum, maximum]``, else a one-line error naming the option."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise HysidInputError(f"{algorithm} {name} must be a number", param=name, value=value)
    if not (np.isfinite(value) and minimum <= value <= maximum):
        raise HysidInputError(f"{algorithm} {name} must be in [{minimum:g}, {maximum:g}]", param=name, value=value)
    return float(value)


def check_choice(algorithm: str, name: str, value: Any, choices: tuple[str, ...]) -> str:
    """One of ``choices``, else a one-line error naming the option."""
    if value not in choices:
        raise HysidInputError(f"{algorithm} {name} must be one of {', '.join(choices)}", param=name, value=value)
    return str(value)


@dataclass
class Batch:
    """Candidates of one step: ``f`` is NaN until told; ``todo`` rows are the ones asked for."""

    kind: str
    x: np.ndarray
    f: np.ndarray
    todo: np.ndarray
    rounds: int = 0

    def as_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "x": self.x.tolist(), "f": self.f.tolist(), "todo": self.todo.tolist(), "rounds": self.rounds}

    @classmethod
    def from_dict(cls, d: dict[str, Any], dim: int) -> Batch:
        return cls(
            kind=d["kind"],
            x=np.array(d["x"], dtype=float).reshape(-1, dim),
            f=np.array(d["f"], dtype=float),
            todo=np.array(d["todo"], dtype=np.intp),
            rounds=int(d["rounds"]),
        )


class PopulationOptimizer(AskTell):
    """Base of :class:`island.ga.GA` and :class:`island.pso.PSO` (see module docstring). The options every
    algorithm has are this class' keywords, with the thesis' values as defaults (section 5.1); an algorithm's
    ``__init__`` takes its own options and hands the rest (``**shared``) to this one. ``redraw_limit`` (not in
    the thesis) caps the rounds of "Couldn't calculate" redraws per batch."""

    __signature__: ClassVar[inspect.Signature]
    """An algorithm's whole signature, as :meth:`__init_subclass__` lays it out."""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Lay out the algorithm's signature as its callers see it (``help``, :mod:`inspect`): ``bounds, seed``,
        the sizes, its own options, then the other options every algorithm has, each with its default, in the
        order of :meth:`_settings_with`."""
        super().__init_subclass__(**kwargs)
        common = list(inspect.signature(PopulationOptimizer.__init__).parameters.values())[1:]
        own = [p for p in inspect.signature(cls.__init__).parameters.values() if p.kind is inspect.Parameter.KEYWORD_ONLY]
        after_sizes = [p.name for p in common].index("addpop_amount")
        cls.__signature__ = inspect.Signature([*common[:after_sizes], *own, *common[after_sizes:]], return_annotation=None)

    def __init__(
        self,
        bounds: np.ndarray,
        seed: int,
        *,
        initial_population: int = 6000,
        population: int = 500,
        iterations: int = 18,
        addpop_amount: float = 0.2,
        addpop_level: int = 4,
        migrant_policy: str = "replace_worst",
        redraw_limit: int = 100,
    ) -> None:
        self.bounds = check_bounds(bounds)
        self.seed = check_int(self.name, "seed", seed, 0)
        self.iterations = check_int(self.name, "iterations", iterations, 0, MAX_ITERATIONS)
        self.addpop_amount = check_float(self.name, "addpop_amount", addpop_amount, 0.0)
        self.addpop_level = check_int(self.name, "addpop_level", addpop_level, 0, 1000)
        self.migrant_policy = check_choice(self.name, "migrant_policy", migrant_policy, MIGRANT_POLICIES)
        self.redraw_limit = check_int(self.name, "redraw_limit", redraw_limit, 0, 10_000)
        self.population = self._checked_population(population)
        """The population (GA) or swarm (PSO) size."""
        self.initial_population = check_int(self.name, "initial_population", initial_population, self.population, MAX_POPULATION)
        """Candidates of iteration 0: at least the population."""
        self.rng = new_rng(self.seed)
        self.history: list[float] = []
        """Best fitness after each iteration; index 0 = after the initial population (the thesis' ``fhv``)."""
        self._evaluations = 0
        self._iteration = 0
        self._batch: Batch | None = None
        self.gain = 0.0
        """Orders of magnitude (log10) by which the algorithm's own moves (GA offspring, PSO particle
        moves) improved the best; the additional population and migrants do not count. What the
        share of a mixed campaign credits (:mod:`island.share`)."""

    # --- subclass hooks ---------------------------------------------------------
    def _checked_population(self, population: Any) -> int:
        """The population (or swarm) size, at least 1, else a one-line error naming the option."""
        return check_int(self.name, "population", population, 1, MAX_POPULATION)

    @abstractmethod
    def _next_batch(self) -> tuple[str, np.ndarray]:
        """Kind and candidates of the next step."""

    @abstractmethod
    def _finish(self, kind: str, x: np.ndarray, f: np.ndarray) -> None:
        """Use a completely evaluated batch (non-finite fitness already redrawn or set to inf)."""

    @abstractmethod
    def _adopt(self, x: np.ndarray, f: np.ndarray) -> None:
        """Make ``population`` evaluated candidates, best first, the population (or swarm)."""

    @abstractmethod
    def _take(self, x: np.ndarray, f: float) -> bool:
        """Apply the migrant policy to one valid migrant; True if it was taken."""

    @abstractmethod
    def _known(self) -> tuple[np.ndarray, np.ndarray]:
        """All candidates the optimizer keeps, with fitness (any order)."""

    @abstractmethod
    def _settings(self) -> dict[str, Any]:
        """The constructor's keyword options."""

    def _settings_with(self, own: dict[str, Any]) -> dict[str, Any]:
        """The keyword options of :meth:`_settings`: the sizes, the algorithm's ``own``, then those every algorithm has."""
        return {
            "initial_population": self.initial_population,
            "population": self.population,
            "iterations": self.iterations,
            **own,
            "addpop_amount": self.addpop_amount,
            "addpop_level": self.addpop_level,
            "migrant_policy": self.migrant_policy,
            "redraw_limit": self.redraw_limit,
        }

    @abstractmethod
    def _state(self) -> dict[str, Any]:
        """The subclass' own state as plain data."""

    @abstractmethod
    def _load(self, state: dict[str, Any]) -> None:
        """Restore what ``_state`` saved."""

    # --- ask/tell -----------------------------------------------------------------
    @property
    def dim(self) -> int:
        return self.bounds.shape[0]

    @property
    def addpop_number(self) -> int:
        """Size of the additional population per iteration (Eq. 5.1)."""
        return addpop_size(self.dim, self.addpop_level)

    @property
    def evaluations(self) -> int:
        """Candidates told so far (redrawn ones included)."""
        return self._evaluations

    @property
    def iteration(self) -> int:
        return self._iteration

    def evaluation_bound(self, iteration: Any) -> Any:
        """The most candidates ``tell`` can have counted by the end of ``iteration`` (a number or an
        array): the initial population, then a population plus the additional population per
        iteration, each batch told at most ``1 + redraw_limit`` times (a claim above it is impossible)."""
        per_iteration = self.population + self.addpop_number
        return (self.initial_population + iteration * per_iteration) * (1 + self.redraw_limit)

    @property
    def done(self) -> bool:
        return bool(self.history) and self._iteration >= self.iterations

    def ask(self) -> np.ndarray:
        """The candidates to evaluate next; asking again before ``tell`` returns the same ones."""
        if self.done:
            raise RuntimeError(f"{self.name}: the iteration budget is spent; nothing to ask")
        if self._batch is None:
            kind, x = self._next_batch()
            self._batch = Batch(kind, x, np.full(x.shape[0], np.nan), np.arange(x.shape[0]))
        return self._batch.x[self._batch.todo]

    def tell(self, x: np.ndarray, f: np.ndarray) -> None:
        batch = self._batch
        if batch is None:
            raise RuntimeError(f"{self.name}: tell() without a pending ask()")
        x = np.asarray(x, dtype=float)
        f = np.asarray(f, dtype=float).reshape(-1)
        if not np.array_equal(x, batch.x[batch.todo]) or f.size != batch.todo.size:
            raise ValueError(f"{self.name}: tell() needs the {batch.todo.size} candidates of the last ask() and one fitness each")
        self._evaluations += f.size
        batch.f[batch.todo] = f
        bad = ~np.isfinite(f)
        if bad.any() and batch.rounds < self.redraw_limit:
            batch.todo = batch.todo[bad]
            batch.x[batch.todo] = uniform_population(self.rng, self.bounds, batch.todo.size)
            batch.rounds += 1
            return
        self._batch = None
        self._finish(batch.kind, batch.x, np.where(np.isfinite(batch.f), batch.f, np.inf))

    def _gained(self, before: float, after: float) -> None:
        """Count an improvement of the best by the algorithm's own moves in :attr:`gain`."""
        if np.isfinite(before) and after < before:
            self.gain += float(np.log10(before / after)) if after > 0 else GAIN_AT_ZERO

    def _complete_iteration(self, best_fitness: float) -> None:
        self._iteration += 1
        self.history.append(float(best_fitness))

    def carry_on(self, other: PopulationOptimizer) -> None:
        """Go on with ``other``'s search between two of its iterations: its iteration and evaluation
        counts, history and random stream, and its known candidates (best first, cycled where this
        population is larger) as the population. A mixed campaign moves an island to another
        algorithm this way (:mod:`island.share`)."""
        if not other.history or other._batch is not None:
            raise ValueError(f"{other.name}: a search is carried on only between two of its iterations")
        x, f = other.best(other._known()[1].size)
        rows = np.arange(self.population) % f.size
        self._adopt(x[rows], f[rows])
        self.rng, self._iteration, self._evaluations = other.rng, other._iteration, other._evaluations
        self.history, self.gain = list(other.history), other.gain

    # --- migrants and results -------------------------------------------------------
    def inject(self, x: np.ndarray, f: np.ndarray) -> int:
        """Offer migrants with locally evaluated fitness; returns how many the policy took.

        Rows that are non-finite or outside the bounds are refused. Before the
        initial population is evaluated there is nobody to replace: none is taken.
        """
        x = np.asarray(x, dtype=float)
        f = np.asarray(f, dtype=float).reshape(-1)
        if x.ndim == 1:
            x = x.reshape(1, -1)
        if x.ndim != 2 or x.shape[1] != self.dim or x.shape[0] != f.size:
            raise HysidInputError(f"migrants must be a (k, {self.dim}) array with k fitness values, got shape {x.shape} and {f.size} values")
        valid = np.all(np.isfinite(x), axis=1) & np.isfinite(f) & np.all((x >= self.bounds[:, 0]) & (x <= self.bounds[:, 1]), axis=1)
        if not self.history:
            return 0
        return sum(self._take(xi.copy(), float(fi)) for xi, fi in zip(x[valid], f[valid]))

    def best(self, k: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` best known candidates and their fitness, best first (empty before the initial population)."""
        if not self.history:
            return np.empty((0, self.dim)), np.empty(0)
        x, f = self._known()
        order = np.argsort(f, kind="stable")[:k]
        return x[order].copy(), f[order].copy()

    # --- checkpoints -------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        return {
            "algorithm": self.name,
            "bounds": self.bounds.tolist(),
            "seed": self.seed,
            "settings": self._settings(),
            "rng": rng_state(self.rng),
            "evaluations": self._evaluations,
            "iteration": self._iteration,
            "history": list(self.history),
            "gain": self.gain,
            "batch": None if self._batch is None else self._batch.as_dict(),
            "own": self._state(),
        }

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> PopulationOptimizer:
        if not isinstance(state, dict) or state.get("algorithm") != cls.name:
            found = state.get("algorithm") if isinstance(state, dict) else type(state).__name__
            raise HysidInputError(f"checkpoint holds a {found!r} state, not {cls.name}")
        try:
            opt = cls(np.array(state["bounds"], dtype=float), state["seed"], **state["settings"])
            opt.rng = rng_from_state(state["rng"])
            opt._evaluations = int(state["evaluations"])
            opt._iteration = int(state["iteration"])
            opt.history = [float(v) for v in state["history"]]
            opt.gain = float(state.get("gain", 0.0))  # absent in checkpoints written before it
            opt._batch = None if state["batch"] is None else Batch.from_dict(state["batch"], opt.dim)
            opt._load(state["own"])
        except HysidInputError:
            raise
        except (KeyError, TypeError, ValueError) as exc:
            raise HysidInputError(f"checkpoint: malformed {cls.name} state ({type(exc).__name__}: {exc})") from exc
        return opt


def array_or_none(a: np.ndarray | None) -> list | None:
    """An optional array as nested lists for ``state_dict`` (floats round-trip msgpack exactly)."""
    return None if a is None else a.tolist()


def load_array(data: list | None, dim: int | None = None) -> np.ndarray | None:
    """Inverse of :func:`array_or_none` (``dim`` reshapes a 2-D array, also when it is empty)."""
    if data is None:
        return None
    a = np.array(data, dtype=float)
    return a if dim is None else a.reshape(-1, dim)
