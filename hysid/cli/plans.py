"""The islands of ``hysid campaign`` and ``hysid coordinator``: their sizes and budgets from ``--population``,
``--initial``, ``--iterations`` and the stop rules, by the library's rule where none is given."""

from __future__ import annotations

from typing import Any

from hysid.campaigns import default_options, island_settings
from hysid.cli.options import ISLAND_INITIAL, ISLAND_ITERATIONS, ISLAND_POPULATION
from hysid_model.errors import HysidInputError
from hysid_model.loops import LoopSet
from island.algorithms import ALGORITHMS
from island.termination import Termination


def island_sizes(population: int | None, initial: int | None, iterations: int | None) -> dict[str, dict[str, Any]]:
    """The per-island sizes of ``--population``, ``--initial``, ``--iterations`` (None: not given) for every algorithm."""
    population = ISLAND_POPULATION if population is None else population
    initial = max(ISLAND_INITIAL, population) if initial is None else initial
    if initial < population:
        raise HysidInputError(f"must be at least --population {population}", param="initial_population", value=initial)
    counts = {} if iterations is None else {"iterations": iterations}
    return {algo: {"population": population, "initial_population": initial, **counts} for algo in ALGORITHMS}


def island_plan(
    loops: LoopSet,
    model: str,
    bounds: dict[str, tuple[float, float]] | None,
    algos: list[str],
    population: int | None,
    initial: int | None,
    iterations: int | None,
    termination: Termination,
) -> tuple[dict[str, dict[str, Any]] | None, Termination, bool, int | None]:
    """The islands' ``(options, termination, until_stopped, iterations)`` from ``--population``, ``--initial``,
    ``--iterations`` and the stop rules: with none of the three given on a model with memory, the library's
    defaults (:func:`hysid.campaigns.island_settings`: memetic islands), so that the command line and Python
    search alike; else these sizes, each island running :func:`island_budget`'s iterations."""
    if population is None and initial is None and iterations is None and default_options(loops, model, bounds, algos) is not None:
        options, chosen, until_stopped = island_settings(loops, model, bounds, algos, None, termination, None)
        return options, chosen or termination, until_stopped, None  # chosen: never None when termination is given
    iterations, until_stopped = island_budget(iterations, termination)
    return island_sizes(population, initial, iterations), termination, until_stopped, iterations


def island_budget(iterations: int | None, termination: Termination) -> tuple[int | None, bool]:
    """Each island's iteration budget and whether it searches until the campaign stops: without
    ``--iterations``, a budget in evaluations or time (:attr:`Termination.bounded`) lets every island
    run until the stop order, else each runs :data:`ISLAND_ITERATIONS`."""
    if iterations is not None:
        return iterations, False
    return (None, True) if termination.bounded else (ISLAND_ITERATIONS, False)
