"""The ask/tell loop that drives one optimizer against an objective, with hooks for the island node.

    rows = run(optimizer, objective, callback=print_row, should_stop=stop_event.is_set, migrate=exchange)

After every completed iteration (iteration 0 = the initial population) a
:class:`HistoryRow` is recorded and handed to ``callback``; then, unless the
budget is spent, ``migrate(optimizer)`` may publish the best and ``inject``
received migrants. ``should_stop()`` is asked before every ``ask`` and ends
the run early, leaving the optimizer resumable (``state_dict``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from island.population import PopulationOptimizer


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
    optimizer: PopulationOptimizer,
    objective: Callable[[np.ndarray], np.ndarray],
    *,
    callback: Callable[[HistoryRow], None] | None = None,
    should_stop: Callable[[], bool] | None = None,
    migrate: Callable[[PopulationOptimizer], None] | None = None,
) -> list[HistoryRow]:
    """Ask, evaluate, tell until the optimizer is done or ``should_stop()``; returns the rows of this run.

    A resumed optimizer continues where it stopped (a pending batch is asked again).
    """
    start = time.perf_counter()
    rows: list[HistoryRow] = []
    recorded = len(optimizer.history)
    while not optimizer.done:
        if should_stop is not None and should_stop():
            break
        x = optimizer.ask()
        optimizer.tell(x, objective(x))
        if len(optimizer.history) == recorded:
            continue
        recorded = len(optimizer.history)
        row = HistoryRow(optimizer.iteration, optimizer.history[-1], optimizer.evaluations, time.perf_counter() - start)
        rows.append(row)
        if callback is not None:
            callback(row)
        if migrate is not None and not optimizer.done:
            migrate(optimizer)
    return rows
