"""The island algorithms by name: the thesis' GA and PSO (section 5.1).

Both take the same size options, so a campaign can give every island the same
sizes whatever its algorithm: ``initial_population`` (the random start,
Eq. 3.2), ``population`` (the GA's mu, the PSO's swarm) and ``iterations``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hysid_model.errors import HysidInputError
from island.ga import GA
from island.population import PopulationOptimizer
from island.pso import PSO

ALGORITHMS: dict[str, type[PopulationOptimizer]] = {"ga": GA, "pso": PSO}
"""The thesis' optimizers (section 5.1) by name."""
ROLES: dict[str, str] = {"ga": "explore", "pso": "converge"}
"""What each algorithm does best in a mixed campaign (the ``staged`` share, :mod:`island.share`).

``converge``: the PSO. The thesis found its convergence much faster than the
GA's on every data set ("the slopes of the convergence plots in the initial
iterations ... much steeper in PSO than in GA", chapter 6, on Figs. 5.6-5.9 and
5.18-5.20), and from scratch hysid's PSO-only campaigns end orders of magnitude
below GA-only ones (``hysid bench islands mixed``).

``explore``: the GA, which hysid gives the first migration interval of each
of its runs: on the bench, half-GA campaigns whose GA runs then move to PSO
match PSO-only ones, where a fixed half-GA share falls far behind."""


def check_algorithm(algo: Any, param: str = "algo") -> str:
    """``algo`` if it names an algorithm of :data:`ALGORITHMS`, else a :class:`HysidInputError`."""
    if algo not in ALGORITHMS:
        raise HysidInputError(f"unknown algorithm; choose one of {', '.join(ALGORITHMS)}", param=param, value=algo)
    return str(algo)


def make_optimizer(algo: str, bounds: np.ndarray, seed: int, options: dict[str, Any] | None = None) -> PopulationOptimizer:
    """A seeded optimizer of ``algo`` on ``bounds`` with keyword ``options`` (thesis settings where not given)."""
    return ALGORITHMS[check_algorithm(algo)](bounds, seed, **(options or {}))


def switch_algorithm(optimizer: PopulationOptimizer, algo: str, options: dict[str, Any] | None = None) -> PopulationOptimizer:
    """``optimizer``'s search carried on by ``algo`` with keyword ``options`` (same bounds and seed;
    :meth:`~island.population.PopulationOptimizer.carry_on`), or ``optimizer`` itself if it runs ``algo``."""
    if ALGORITHMS[check_algorithm(algo)] is type(optimizer):
        return optimizer
    switched = make_optimizer(algo, optimizer.bounds, optimizer.seed, options)
    switched.carry_on(optimizer)
    return switched
