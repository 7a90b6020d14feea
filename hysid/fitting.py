"""The single-node fit: GA or PSO runs on one loop set, a polish, and a result that reports itself.

    result = hysid.fit(loops, "thesis", algo="pso", runs=2)
    print(result.summary())
    result.write_report("out")

One process, no network: each run is the thesis' GA or PSO (section 5.1)
driven by :func:`island.run.optimize`, then (by default) a least-squares
polish from its best candidate; where the model has memory or a
non-smooth force, memetic islands in this process (:func:`island.memetic.memetic_search`).
Bounds the data suggested are widened where the best run ends on them, and the runs repeated under the
other displacement reading where the fitted model prefers it (:func:`hysid.motion.refit_under_other_reading`).
The runs become a :class:`hysid.fit_result.FitResult`, which derives what a user reads.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from hysid.fit_result import FitResult
from hysid.motion import choose_motion, refit_under_other_reading
from hysid_model import notices
from hysid_model.errors import HysidInputError
from hysid_model.loops import LoopSet
from hysid_model.model import MAX_WIDENINGS, Model
from hysid_model.objective import Objective
from hysid_model.problem import build_objective, starting_point
from island.algorithms import check_algorithm
from island.memetic import TIME_LIMIT_S, WIDENED_SHARE, memetic_search, needs_islands, search_limits
from island.run import HistoryRow, RunResult, optimize
from island.termination import Termination

MIN_SEARCH_S = 1.0
"""The least time a memetic run is given once the fit's time limit is spent (its final polish follows)."""
RunCallback = Callable[[int, HistoryRow], None]
"""Called with (run index, history row) after every iteration of a run."""


@notices.keeps_warnings
def fit(
    loops: LoopSet,
    model: str | Model = "thesis",
    *,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    fixed: Mapping[str, float] | None = None,
    algo: str = "pso",
    runs: int = 1,
    seed: int = 0,
    weights: str | None = None,
    displacement: str = "auto",
    polish: bool = True,
    start: bool = True,
    options: dict[str, Any] | None = None,
    termination: Termination | None = None,
    progress: RunCallback | None = None,
    islands: bool | None = None,
) -> FitResult:
    """Identify ``model``'s parameters from ``loops``: ``runs`` independent runs (seeds ``seed .. seed+runs-1``); the best is the result.

    ``model`` is a string (``"thesis+coulomb_friction"``) or a :class:`~hysid_model.model.Model`;
    ``bounds`` (``{"w0": (10, 200)}``) and ``fixed`` (``{"meq": 0.2}``) override the dataset's and
    the model's; ``options`` are the algorithm's settings (``population``, ``initial_population``,
    ``iterations``, ...; the thesis' by default); ``displacement`` is ``"auto"`` (the data decide
    whether each loop's measured waveform is the motion or the sensor's distortion of its fundamental,
    :mod:`hysid.motion`; the choice and its evidence are ``result.displacement_model``), ``"measured"``,
    ``"fundamental"`` or ``"sine"`` (Eq. 4.5, as the thesis); ``start`` adds the
    survey's linear estimate to every run's population (:func:`hysid_model.problem.starting_point`);
    ``termination`` may end runs early; ``progress(run, row)`` is called after every iteration.

    ``islands``: each run is a search of memetic islands in this process (:func:`island.memetic.memetic_search`:
    several cooperating populations, refined by least squares, as a campaign's islands) instead of one
    GA/PSO run and its polish; by default (None) on models with memory or a non-smooth force
    (:func:`island.memetic.needs_islands`) unless ``options`` are given, within ``termination``'s budget
    and time limit (else :data:`island.memetic.BUDGET` evaluations, :data:`island.memetic.TIME_LIMIT_S` s).

    Bounds the data suggested (soft, see :mod:`hysid_model.problem`) that the best run ends on are
    widened and every run repeated from that best, up to ``MAX_WIDENINGS`` times, before the result
    is reported; bounds given by a user or a dataset are kept.
    """
    check_algorithm(algo)
    if isinstance(runs, bool) or not isinstance(runs, int) or runs < 1:
        raise HysidInputError("the number of runs must be at least 1", param="runs", value=runs)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise HysidInputError("seeds must be non-negative integers", param="seed", value=seed)
    began = time.perf_counter()
    motion = choose_motion(loops, model, displacement, bounds=bounds, fixed=fixed)
    objective = build_objective(loops, model, weights=weights, bounds=bounds, fixed=fixed, displacement=motion.displacement)
    assert isinstance(objective, Objective)  # the closed form (build_objective's default kind)
    first = starting_point(objective.loops, objective.model) if start else None
    widened: list[dict[str, Any]] = []
    memetic = needs_islands(objective.model) and options is None if islands is None else bool(islands)
    budget, seconds = search_limits(termination, TIME_LIMIT_S)
    deadline = None if seconds is None else time.monotonic() + seconds
    """The memetic runs share the time limit, the searches after a widening included."""

    def search(objective: Objective, first: np.ndarray | None, share: float = 1.0) -> list[RunResult]:
        out = []
        for i in range(runs):
            callback = None if progress is None else (lambda row, i=i: progress(i, row))
            if memetic:
                left = None if deadline is None else max((deadline - time.monotonic()) / (runs - i), MIN_SEARCH_S)
                out.append(
                    memetic_search(
                        objective,
                        [] if first is None else [first],
                        seed + i,
                        budget=None if budget is None else max(int(share * budget), 1),
                        time_limit_s=left,
                        label=f"run {i + 1}",
                        callback=callback,
                    )
                )
            else:
                out.append(
                    optimize(
                        objective, algo, seed + i, polish=polish, label=f"run {i + 1}", options=options, termination=termination, callback=callback, start=first
                    )
                )
        return out

    def identify(objective: Objective, first: np.ndarray | None) -> tuple[Objective, list[RunResult]]:
        results = search(objective, first)
        for _ in range(MAX_WIDENINGS):
            best = min(results, key=lambda r: r.fitness)
            wider, changed = objective.model.widen_at(best.theta)
            if not changed:
                break
            old = dict(zip(objective.model.names, objective.model.bounds.tolist()))
            widened.extend({"param": name, "from": old[name], "to": [float(b) for b in pair]} for name, pair in changed.items())
            spent = sum(r.evaluations for r in results)
            objective = Objective(objective.loops, wider, weights=objective.weights)
            results = search(objective, best.theta, WIDENED_SHARE)
            results[0].evaluations += spent  # what the narrower searches cost counts too
        return objective, results

    def under(reading: str) -> Objective:
        built = build_objective(loops, model, weights=weights, bounds=bounds, fixed=fixed, displacement=reading)
        assert isinstance(built, Objective)  # the closed form (build_objective's default kind)
        return built

    objective, results = identify(objective, first)
    spent = sum(r.evaluations for r in results)
    again = refit_under_other_reading(loops, objective.model, min(results, key=lambda r: r.fitness).theta, motion, under, identify)
    if again is not None:  # the runs repeated under the reading the fitted model prefers, what the first ones spent counting too
        motion, (objective, results) = again
        results[0].evaluations += spent
    settings = {
        "algo": "memetic islands" if memetic else algo,
        "runs": runs,
        "seeds": list(range(seed, seed + runs)),
        "polish": polish,
        "weights": objective.weights,
        "wall_s": time.perf_counter() - began,
        "displacement": motion.displacement,
        "displacement_model": motion.as_dict(),
        "model": objective.model.spec,
        "options": dict(options or {}),
        "bounds_from_dataset": sorted(n for n in (loops.meta.get("bounds") or {}) if n in objective.model.names),
        "bounds_from_data": sorted(p.name for p in objective.model.parameters if p.soft),
        "bounds_widened": widened,
        "start": "linear estimate of the survey" if start else None,
    }
    if termination is not None:
        settings["termination"] = termination.as_dict()
    return FitResult.from_runs(objective, results, settings)
