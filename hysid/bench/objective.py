"""``hysid bench objective``: objective evaluations per second, hysid vs the thesis' erreval.

hysid's :class:`~hysid_model.objective.Objective` (closed form, whole
population at once) and the faithful port of the thesis' MATLAB objective,
:class:`~hysid_model.thesis_port.ThesisObjective` (time grid, getloopdisp,
interp1 per candidate and loop), both on the 120-loop Synth set (section 5.2),
in one run, so their ratio does not depend on the machine. hysid is fed the
GA's batches (6000 initial chromosomes, then 18 x (500 offspring + 15 of the
additional population), section 5.1); the whole thesis budget is also timed on
one core, objective only (``thesis_ga_budget_s``) and as a full run of
:class:`island.ga.GA` with its operators (``thesis_ga_run_s``).
Targets: ratio >= 1000, budget < 1 s on one core.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from hysid.bench import peak_rss_mb, run_on_one_core
from hysid_model.objective import Objective
from hysid_model.problem import build_objective
from hysid_model.synth import synth_loops
from hysid_model.thesis_port import ThesisObjective
from island.ga import GA
from island.run import run as run_optimizer

THESIS_BATCHES = (6000,) + (500 + 15,) * 18
"""Candidates per GA ask: the initial population, then offspring + additional population per iteration."""
TARGET_RATIO = 1000.0
TARGET_BUDGET_S = 1.0
HYSID_SECONDS = 1.0
PORT_SECONDS = 3.0


def synth_objective() -> Objective:
    """hysid's objective of the thesis model on the noiseless Synth set, thesis weights."""
    return build_objective(synth_loops(0.0), "thesis", weights="thesis")


def budget_batches(bounds: np.ndarray, seed: int = 0) -> list[np.ndarray]:
    """Uniform random candidates in ``bounds``, one array per GA ask of the thesis budget."""
    rng = np.random.default_rng(seed)
    low, span = bounds[:, 0], bounds[:, 1] - bounds[:, 0]
    return [low + span * rng.random((n, bounds.shape[0])) for n in THESIS_BATCHES]


def hysid_rate(objective: Objective, seconds: float = HYSID_SECONDS) -> dict[str, float]:
    """Evaluations per second over repeated passes of the thesis budget (after one warm-up pass)."""
    batches = budget_batches(objective.bounds)
    for pop in batches:
        objective(pop)
    passes, evaluations, start = 0, 0, time.perf_counter()
    while passes == 0 or time.perf_counter() - start < seconds:
        for pop in batches:
            objective(pop)
        passes += 1
        evaluations += sum(THESIS_BATCHES)
    return {"evals_per_s": evaluations / (time.perf_counter() - start), "evaluations": evaluations}


def port_rate(port: ThesisObjective, seconds: float = PORT_SECONDS) -> dict[str, float]:
    """Evaluations per second of the port, one candidate at a time as the thesis' GA, for ``seconds``."""
    rng = np.random.default_rng(1)
    low, span = port.bounds[:, 0], port.bounds[:, 1] - port.bounds[:, 0]
    port(low + 0.5 * span)
    evaluations, start = 0, time.perf_counter()
    while evaluations < 5 or time.perf_counter() - start < seconds:
        port(low + span * rng.random(port.dim))
        evaluations += 1
    return {"evals_per_s": evaluations / (time.perf_counter() - start), "evaluations": evaluations}


def one_core_budget() -> dict[str, float]:
    """Median wall time of the thesis budget: objective only (5 passes) and a full GA run (3 runs).

    Meant to run pinned to one core (:func:`hysid.bench.run_on_one_core`).
    """
    objective = synth_objective()
    batches = budget_batches(objective.bounds)
    budget = []
    for _ in range(6):
        start = time.perf_counter()
        for pop in batches:
            objective(pop)
        budget.append(time.perf_counter() - start)
    runs, best = [], []
    for seed in range(4):
        ga = GA(objective.bounds, seed)
        start = time.perf_counter()
        run_optimizer(ga, objective)
        runs.append(time.perf_counter() - start)
        best.append(float(ga.best()[1][0]))
    return {
        "thesis_ga_budget_s": float(np.median(budget[1:])),
        "thesis_ga_run_s": float(np.median(runs[1:])),
        "thesis_ga_evaluations": ga.evaluations,
        "thesis_ga_best_fitness_median": float(np.median(best)),
    }


def run() -> dict[str, Any]:
    """Objective evaluations per second, hysid vs the thesis' erreval (port), and the thesis GA budget on one core."""
    objective = synth_objective()
    hysid = hysid_rate(objective)
    port = port_rate(ThesisObjective(objective.loops, objective.model))
    one_core = run_on_one_core("hysid.bench.objective:one_core_budget")
    ratio = hysid["evals_per_s"] / port["evals_per_s"]
    return {
        "hysid_evals_per_s": hysid["evals_per_s"],
        "thesis_port_evals_per_s": port["evals_per_s"],
        "ratio": ratio,
        **one_core,
        "peak_rss_mb": peak_rss_mb(),
        "loops": objective.loops.n_loops,
        "samples_per_loop": 2 * objective.loops.n_samples,
        "hysid_evaluations": hysid["evaluations"],
        "thesis_port_evaluations": port["evaluations"],
        "targets": {"ratio_min": TARGET_RATIO, "thesis_ga_budget_s_max": TARGET_BUDGET_S},
        "targets_met": bool(ratio >= TARGET_RATIO and one_core["thesis_ga_budget_s"] < TARGET_BUDGET_S),
    }


def to_text(result: dict[str, Any]) -> str:
    def verdict(ok: bool) -> str:
        return "met" if ok else "MISSED"

    ratio_ok = result["ratio"] >= result["targets"]["ratio_min"]
    budget_ok = result["thesis_ga_budget_s"] < result["targets"]["thesis_ga_budget_s_max"]
    return "\n".join([
        f"objective on the Synth set ({result['loops']} loops x {result['samples_per_loop']} samples), thesis model and weights",
        f"  hysid (closed form, GA batches)   {result['hysid_evals_per_s']:>14,.0f} evaluations/s",
        f"  thesis erreval (faithful port)    {result['thesis_port_evals_per_s']:>14,.1f} evaluations/s"
        f"  ({result['thesis_port_evaluations']} evaluations)",
        f"  ratio                             {result['ratio']:>14,.0f} x   (target >= {result['targets']['ratio_min']:g}: {verdict(ratio_ok)})",
        f"thesis GA budget on one core ({result['thesis_ga_evaluations']} evaluations)",
        f"  objective only                    {result['thesis_ga_budget_s']:>14.4f} s   "
        f"(target < {result['targets']['thesis_ga_budget_s_max']:g} s: {verdict(budget_ok)})",
        f"  full GA run (operators included)  {result['thesis_ga_run_s']:>14.4f} s",
        f"peak RSS {result['peak_rss_mb']:.0f} MB",
    ])
