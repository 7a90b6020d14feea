"""The thesis' real-coded GA (sections 3.1 and 5.1, GA program of Appendix A) as an ask/tell optimizer.

Iteration 0 draws ``initial_population`` chromosomes uniformly in the bounds
(Eq. 3.2), evaluates them and keeps the best ``population`` (mu). Each
iteration then follows the 4 steps of section 5.1:

1. offspring of size mu: rank-based roulette selection (Eq. 3.5) of mu/2
   couples without self-mating, single-point BLX-alpha crossover (Eq. 3.6 as
   the program draws it), Gaussian mutation of round(mu D rate) offspring genes;
2. the additional population around the best chromosome (Table 5.1, Eq. 5.1);
3. its best member;
4. survival of the best mu of parents + offspring + that member, the
   (mu + (mu + 1)) elitist strategy, so the best fitness never increases.

``ask`` returns offspring and additional population together (500 + 15 = 515
per iteration with the defaults), so the thesis budget is
6000 + 18 x 515 = 15270 evaluations.

Reconstructed from the text (lines missing from the listing's extraction): the
main-loop start (evaluate the initial population, sort by fitness with
``sortrows``, keep the best ``rempop``, BC = the best) and the rank-based
roulette: ``cumprob = cumsum`` of Eq. 3.5 over the ranked parents, and for
each mate ``r = rand; jj = 1; while r > cumprob(jj), jj = jj + 1`` (Fig. 3.5);
the visible code then redraws the second parent of a couple while it equals
the first. The operators are vectorized with the same distributions as the
program's loops (the random stream differs from MATLAB's).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hysid_model.errors import HysidInputError
from island.addpop import additional_population
from island.population import MAX_POPULATION, PopulationOptimizer, array_or_none, check_float, check_int, load_array
from island.rng import uniform_population

__all__ = ["GA", "blx_crossover", "gaussian_mutation", "mutation_count", "rank_probabilities", "select_couples"]


def rank_probabilities(m: int) -> np.ndarray:
    """P_i = 2 (M - i + 1) / (M (1 + M)) for ranks i = 1..M, best first (Eq. 3.5)."""
    rank = np.arange(1, m + 1)
    return 2.0 * (m - rank + 1) / (m * (1.0 + m))


def select_couples(rng: np.random.Generator, m: int, couples: int) -> np.ndarray:
    """Indices (into the ranked parents) of ``couples`` pairs by roulette over Eq. 3.5, ``(couples, 2)``.

    A second parent equal to the first is redrawn until they differ (no self-mating).
    """
    if m < 2:
        raise ValueError("mating needs at least 2 parents")
    cumprob = np.cumsum(rank_probabilities(m))
    cumprob[-1] = 1.0  # the wheel is closed: no rounding gap past the last section
    mates = np.searchsorted(cumprob, rng.random((couples, 2)), side="left")
    same = np.flatnonzero(mates[:, 0] == mates[:, 1])
    while same.size:
        mates[same, 1] = np.searchsorted(cumprob, rng.random(same.size), side="left")
        same = same[mates[same, 0] == mates[same, 1]]
    return mates


def blx_crossover(rng: np.random.Generator, p1: np.ndarray, p2: np.ndarray, bounds: np.ndarray, alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """Single-point crossover over a gene with BLX-alpha blending (Figs. 3.6b, 3.8; Eq. 3.6).

    Per couple, crosspnt = ceil(D rand): genes before it are copied, genes
    after it swapped, and the gene at it blended as the program does,
    t = (1 + alpha) rand, child1 = p1 - t (p1 - p2), child2 = p2 + t (p1 - p2)
    (so child1 lies on the line from p1 through p2 up to 1 + alpha times their
    distance). A blended gene outside its bounds keeps that parent's gene.
    """
    n: int
    dim: int
    n, dim = p1.shape
    point = rng.integers(dim, size=n)[:, None]
    t = (1.0 + alpha) * rng.random(n)[:, None]
    gene = np.arange(dim)[None, :]
    lower, upper = bounds[:, 0], bounds[:, 1]
    blend1 = p1 - t * (p1 - p2)
    blend2 = p2 + t * (p1 - p2)
    blend1 = np.where((blend1 < lower) | (blend1 > upper), p1, blend1)
    blend2 = np.where((blend2 < lower) | (blend2 > upper), p2, blend2)
    child1 = np.where(gene < point, p1, np.where(gene == point, blend1, p2))
    child2 = np.where(gene < point, p2, np.where(gene == point, blend2, p1))
    return child1, child2


def mutation_count(mu: int, dim: int, rate: float) -> int:
    """mutations = round(rempop np mutrate), MATLAB rounding (halves away from zero)."""
    return int(np.floor(mu * dim * rate + 0.5))


def gaussian_mutation(rng: np.random.Generator, offspring: np.ndarray, bounds: np.ndarray, rate: float, amount: float) -> np.ndarray:
    """Mutate ``mutation_count`` random genes (drawn with replacement) of the offspring.

    new = old + randn amount (ub - lb), kept only if lb < new < ub. A gene
    drawn twice is mutated twice in draw order, as the program's loop does.
    """
    mu, dim = offspring.shape
    n = mutation_count(mu, dim, rate)
    rows = rng.integers(mu, size=n)
    cols = rng.integers(dim, size=n)
    steps = rng.standard_normal(n) * amount * (bounds[:, 1] - bounds[:, 0])[cols]
    out = offspring.copy()
    pending = np.arange(n)
    while pending.size:
        _, first = np.unique(rows[pending] * dim + cols[pending], return_index=True)
        now = pending[first]
        r, c = rows[now], cols[now]
        proposal = out[r, c] + steps[now]
        ok = (proposal > bounds[c, 0]) & (proposal < bounds[c, 1])
        out[r[ok], c[ok]] = proposal[ok]
        pending = np.delete(pending, first)
    return out


class GA(PopulationOptimizer):
    """Real-coded GA of the thesis (section 3.1, Figs. 3.6-3.8); every setting an option with the thesis value as
    default (section 5.1), ``redraw_limit`` as :class:`island.population.PopulationOptimizer` says."""

    name = "GA"

    def __init__(
        self, bounds: np.ndarray, seed: int, *, alpha_blx: float = 0.3, mutation_rate: float = 0.05, mutation_amount: float = 0.3, **shared: Any
    ) -> None:
        """``shared``: the options every algorithm has (:class:`island.population.PopulationOptimizer`)."""
        super().__init__(bounds, seed, **shared)
        self.alpha_blx = check_float(self.name, "alpha_blx", alpha_blx, 0.0)
        self.mutation_rate = check_float(self.name, "mutation_rate", mutation_rate, 0.0, 1.0)
        self.mutation_amount = check_float(self.name, "mutation_amount", mutation_amount, 0.0)
        self.pop: np.ndarray | None = None
        """Parents ranked best first, ``(mu, D)``; None before the initial population is evaluated."""
        self.fit: np.ndarray | None = None

    def _checked_population(self, population: Any) -> int:
        """An even population of at least 2 (mu/2 couples), else a one-line error naming the option."""
        mu = check_int(self.name, "population", population, 2, MAX_POPULATION)
        if mu % 2:
            raise HysidInputError("GA population must be even (mu/2 couples)", param="population", value=population)
        return mu

    def _settings(self) -> dict[str, Any]:
        return self._settings_with({"alpha_blx": self.alpha_blx, "mutation_rate": self.mutation_rate, "mutation_amount": self.mutation_amount})

    def _next_batch(self) -> tuple[str, np.ndarray]:
        if self.pop is None:
            return "initial", uniform_population(self.rng, self.bounds, self.initial_population)
        couples = select_couples(self.rng, self.population, self.population // 2)
        child1, child2 = blx_crossover(self.rng, self.pop[couples[:, 0]], self.pop[couples[:, 1]], self.bounds, self.alpha_blx)
        offspring = np.empty((self.population, self.dim))
        offspring[0::2], offspring[1::2] = child1, child2
        extra = additional_population(self.pop[0], self.bounds, self.rng, amount=self.addpop_amount, level=self.addpop_level)
        offspring = gaussian_mutation(self.rng, offspring, self.bounds, self.mutation_rate, self.mutation_amount)
        return "generation", np.vstack([offspring, extra])

    def _finish(self, kind: str, x: np.ndarray, f: np.ndarray) -> None:
        if kind == "initial":
            keep = np.argsort(f, kind="stable")[: self.population]
            self._adopt(x[keep], f[keep])
            assert self.fit is not None  # just adopted
            self.history.append(float(self.fit[0]))
            return
        assert self.pop is not None and self.fit is not None  # set by the initial population
        mu = self.population
        self._gained(float(self.fit[0]), float(np.min(f[:mu])))
        pool_x, pool_f = [x[:mu]], [f[:mu]]
        if x.shape[0] > mu:
            j = mu + int(np.argmin(f[mu:]))
            pool_x.append(x[j : j + 1])
            pool_f.append(f[j : j + 1])
        pool_x.append(self.pop)
        pool_f.append(self.fit)
        xs, fs = np.vstack(pool_x), np.concatenate(pool_f)
        keep = np.argsort(fs, kind="stable")[:mu]
        self.pop, self.fit = xs[keep], fs[keep]
        self._complete_iteration(self.fit[0])

    def _adopt(self, x: np.ndarray, f: np.ndarray) -> None:
        self.pop, self.fit = x, f

    def _take(self, x: np.ndarray, f: float) -> bool:
        assert self.pop is not None and self.fit is not None  # set by the initial population
        if not f < self.fit[-1]:
            return False
        slot = int(np.searchsorted(self.fit, f, side="right"))
        self.pop = np.insert(self.pop[:-1], slot, x, axis=0)
        self.fit = np.insert(self.fit[:-1], slot, f)
        return True

    def _known(self) -> tuple[np.ndarray, np.ndarray]:
        assert self.pop is not None and self.fit is not None  # set by the initial population
        return self.pop, self.fit

    def _state(self) -> dict[str, Any]:
        return {"pop": array_or_none(self.pop), "fit": array_or_none(self.fit)}

    def _load(self, state: dict[str, Any]) -> None:
        self.pop = load_array(state["pop"], self.dim)
        self.fit = load_array(state["fit"])
