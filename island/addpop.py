"""The additional population around the best partial solution (section 5.1, Table 5.1, Eq. 5.1).

After every iteration both the GA and the PSO of the thesis build, from the
best solution so far (BC in the GA program, Pg in the PSO program), one
candidate for every combination of 1..L of its D genes: the chosen genes are
moved by a Gaussian step of ``amount`` x (ub - lb), each kept only if strictly
inside its bounds, and a row that ends up identical to the best is replaced by
a fresh uniform chromosome (Eq. 3.2). Rows follow ``nchoosek`` order: all
single genes, then all pairs in lexicographic order, ... (Table 5.1).
"""

from __future__ import annotations

from functools import lru_cache
from itertools import combinations
from math import comb

import numpy as np

from island.rng import uniform_population


def addpop_size(dim: int, level: int) -> int:
    """AddPopNumber = sum_{i=1..L} C(D, i) (Eq. 5.1); 2^D - 1 when L >= D (15 for D = L = 4)."""
    return sum(comb(dim, i) for i in range(1, level + 1))


@lru_cache(maxsize=64)
def addpop_masks(dim: int, level: int) -> np.ndarray:
    """Which genes each additional candidate mutates, ``(AddPopNumber, D)`` read-only booleans (rows of Table 5.1)."""
    rows = [np.isin(np.arange(dim), genes) for i in range(1, level + 1) for genes in combinations(range(dim), i)]
    masks = np.array(rows, dtype=bool).reshape(-1, dim)
    masks.setflags(write=False)
    return masks


def additional_population(best: np.ndarray, bounds: np.ndarray, rng: np.random.Generator, *, amount: float = 0.2, level: int = 4) -> np.ndarray:
    """Gaussian-mutated versions of ``best`` for every gene combination up to ``level`` (Table 5.1).

    Same draws as the program's loops: one ``randn`` per mutated gene in row
    order, new = old + randn * amount * (ub - lb), kept only if lb < new < ub;
    an unchanged row becomes a uniform random chromosome (``genipop``).
    """
    best = np.asarray(best, dtype=float).reshape(-1)
    masks = addpop_masks(best.size, level)
    pop = np.tile(best, (masks.shape[0], 1))
    if pop.shape[0] == 0:
        return pop
    lower, upper = bounds[:, 0], bounds[:, 1]
    rows, cols = np.nonzero(masks)
    proposal = pop[rows, cols] + rng.standard_normal(rows.size) * amount * (upper - lower)[cols]
    inside = (proposal > lower[cols]) & (proposal < upper[cols])
    pop[rows[inside], cols[inside]] = proposal[inside]
    unchanged = np.all(pop == best, axis=1)
    if unchanged.any():
        pop[unchanged] = uniform_population(rng, bounds, int(unchanged.sum()))
    return pop
