"""Part pygmo of ``hysid bench islands``: hysid's PSO islands over Zenoh against a pygmo archipelago of PSO islands
(``pygmo.pso`` with constriction and velocity memory, ring topology, multiprocessing islands, migration after every
5 generations) on the Synth set (section 5.2): same objective, number of islands, population and evaluation
budget; time to target and final parameter error against Table 5.3. pygmo is an optional, bench-only dependency
(``pip install pygmo``); without it the part says so.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from hysid.bench.island_campaigns import campaign, time_to
from hysid_model.problem import build_objective
from hysid_model.synth import TRUE_PARAMS, synth_loops
from island.migration import Migration
from island.termination import Termination


def parameter_error(x: np.ndarray, names: list[str]) -> float:
    """Largest relative error of a parameter vector against Table 5.3."""
    truth = np.array([TRUE_PARAMS[n] for n in names])
    return float(np.max(np.abs(np.asarray(x) - truth) / np.abs(truth)))


def pygmo_archipelago(islands: int, population: int, generations: int, budget: int, target: float, seed: int) -> dict[str, Any]:
    import pygmo as pg

    objective = build_objective(synth_loops())

    class Problem:
        """The hysid objective as a pygmo user-defined problem."""

        def __init__(self) -> None:
            self.bounds = objective.bounds

        def fitness(self, x: np.ndarray) -> list[float]:
            return [float(objective(np.asarray(x)[None, :])[0])]

        def get_bounds(self) -> tuple[list[float], list[float]]:
            return list(self.bounds[:, 0]), list(self.bounds[:, 1])

    pg.mp_island.init_pool(islands)  # worker processes started before the clock, as hysid's islands are
    archi = pg.archipelago(n=islands, t=pg.ring(), algo=pg.pso(gen=generations, memory=True), prob=Problem(), pop_size=population, seed=seed)
    start, reached = time.monotonic(), None
    while True:
        archi.evolve()
        archi.wait_check()
        best = float(np.min([f[0] for f in archi.get_champions_f()]))
        fevals = sum(isl.get_population().problem.get_fevals() for isl in archi)
        if reached is None and best <= target:
            reached = time.monotonic() - start
        if fevals >= budget:
            break
    champion = archi.get_champions_x()[int(np.argmin([f[0] for f in archi.get_champions_f()]))]
    return {"time_to_target_s": reached, "final_fitness": best, "evaluations": int(fevals), "parameter_error": parameter_error(champion, objective.model.names)}


def versus_pygmo(seeds: int = 3, islands: int = 4, population: int = 20, budget: int = 60_000, target: float = 1e-8) -> dict[str, Any]:
    """Part (c): hysid PSO islands over Zenoh vs a pygmo archipelago of PSO islands."""
    try:
        import pygmo  # noqa: F401
    except ImportError as exc:
        return {"skipped": f"pygmo is not installed ({exc}); it is an optional bench-only dependency: pip install pygmo"}
    out: dict[str, list[dict[str, Any]]] = {"hysid": [], "pygmo": []}
    names = build_objective(synth_loops()).model.names
    with tempfile.TemporaryDirectory(prefix="hysid-bench-") as tmp:
        for seed in range(seeds):
            options = {"population": population, "initial_population": population, "iterations": 100_000}
            c = campaign(Path(tmp), f"vs-pygmo-{seed}", "pso", islands, options, Migration(interval=5, k=2), Termination(budget=budget), seed)
            _, f, evaluations, x = [entry for entry in c.best_trace if entry[2] <= budget][-1]  # the best within the budget
            out["hysid"].append(
                {"time_to_target_s": time_to(c, target), "final_fitness": f, "evaluations": evaluations, "parameter_error": parameter_error(x, names)}
            )
            out["pygmo"].append(pygmo_archipelago(islands, population, 5, budget, target, seed))
    summary: dict[str, dict[str, Any]] = {}
    for k, runs in out.items():
        times = [r["time_to_target_s"] for r in runs]
        summary[k] = {
            "reached_target": sum(t is not None for t in times),
            "median_time_to_target_s": float(np.median([t for t in times if t is not None])) if any(t is not None for t in times) else None,
            "median_parameter_error": float(np.median([r["parameter_error"] for r in runs])),
        }
    both = summary["hysid"]["median_time_to_target_s"], summary["pygmo"]["median_time_to_target_s"]
    return {
        "islands": islands,
        "population": population,
        "budget_evaluations": budget,
        "target_fitness": target,
        "seeds": seeds,
        "runs": out,
        "summary": summary,
        "time_ratio_pygmo_over_hysid": both[1] / both[0] if None not in both else None,
    }
