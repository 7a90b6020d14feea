"""hysid bench search's machinery on a tiny instance, and the memetic islands it measures.

The bench itself (30 seeds, seven problems) is ``hysid bench search``; here each
piece runs on one problem with small budgets: the problems' data, the peers'
shared evaluation count, the statistics and the verdict, the search space and
the memetic search that ``hysid fit`` runs on memory models.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import hysid
from hysid.bench import search
from hysid.bench.search import judge, run_method, summarize
from hysid.bench.search_peers import PEERS, BudgetSpent, Tracker
from hysid.bench.search_problems import build
from hysid_model.errors import HysidInputError
from hysid_model.problem import build_objective, starting_point
from hysid_model.synth import synth_loops
from island.memetic import QUIET, REFINE_EVERY, REFINE_NFEV, STALL, Island, memetic_search, needs_islands, starting_points
from island.run import run
from island.space import SearchSpace, SpaceObjective


@pytest.fixture(scope="module")
def problem():
    return build("friction_bouc_wen")


@pytest.fixture()
def objective(problem):
    return build_objective(problem.loops, problem.model, bounds=problem.bounds)


def test_problem_is_a_memory_model_with_its_optimum_inside_the_box(problem, objective):
    assert problem.memory and needs_islands(objective.model)
    assert problem.loops.n_loops == 9
    truth = np.array([problem.truth[n] for n in objective.model.names])
    assert np.all((truth > objective.bounds[:, 0]) & (truth < objective.bounds[:, 1]))


def test_tracker_counts_every_evaluation_and_stops_at_the_budget(objective):
    tracker = Tracker(objective, 5)
    theta = starting_point(objective.loops, objective.model)
    tracker.residuals(theta)
    tracker.fitness(np.vstack([theta, theta]))
    assert tracker.evaluations == 3
    tracker.fitness(np.vstack([theta, theta]))
    with pytest.raises(BudgetSpent):
        tracker.residuals(theta)
    assert tracker.trace[0][0] == 1 and len(tracker.trace) <= 2  # the same point again differs by rounding at most
    assert tracker.best == pytest.approx(float(objective(theta[None, :])[0]), rel=1e-12)


@pytest.mark.parametrize("peer", ["least_squares", "differential_evolution", "cma_es"])
def test_peers_spend_the_same_budget(objective, peer):
    out = PEERS[peer](objective, 600, 0)
    assert 0 < out["evaluations"] <= 600 + 15 * objective.dim  # a vectorized peer's last batch may be counted whole
    assert out["trace"] and out["trace"][-1][2] == out["fitness"]
    assert np.all(np.diff([f for _, _, f in out["trace"]]) < 0)


def test_summary_and_verdict_follow_the_paired_rule():
    runs = lambda *fs: [{"fitness": f, "evaluations": 10, "wall_s": 1.0, "trace": [(5, 0.5, f)]} for f in fs]
    good, bad = [1.0] * 30, [1.0] * 10 + [2.0] * 20
    hard = summarize({"campaign_4_processes": runs(*good), "least_squares": runs(*bad)})
    assert hard["methods"]["campaign_4_processes"]["success_rate"] == 1.0
    assert hard["methods"]["least_squares"]["success_rate"] == pytest.approx(1 / 3)
    assert hard["methods"]["least_squares"]["median_evaluations_to_success"] == 5.0
    easy = summarize({"campaign_4_processes": runs(*good), "least_squares": runs(*good)})
    verdict = judge({"hard": hard, "easy": easy}, ["least_squares"])
    assert verdict["hardest"] == ["hard"] and verdict["ok"]
    worse = summarize({"campaign_4_processes": runs(*bad), "least_squares": runs(*good)})
    assert not judge({"hard": hard, "worse": worse}, ["least_squares"])["non_inferior"]


def test_an_unknown_method_or_problem_is_one_clear_error_before_anything_runs():
    with pytest.raises(HysidInputError, match="unknown method; choose from fit, "):
        search.run(methods=("fit", "simplex"))
    with pytest.raises(HysidInputError, match="unknown problem"):
        search.run(problems=("mr_damper_9v",))


def test_search_space_logs_the_wide_positive_scales_and_keeps_the_rest(objective):
    space = SearchSpace.of(objective.model)
    logged = dict(zip(objective.model.names, space.logged))
    assert logged["bw_zy"] and logged["bw_k"] and logged["meq"] and not logged["bw_r"]
    theta = starting_point(objective.loops, objective.model)
    span = objective.bounds[:, 1] - objective.bounds[:, 0]
    assert np.allclose(space.to_theta(space.to_u(theta)), theta, rtol=1e-12, atol=1e-12 * span.min())
    assert np.all(np.abs(space.to_theta(space.bounds.T) - objective.bounds.T) <= 1e-12 * span)


def test_space_objective_has_the_objective_contract_and_a_chain_ruled_jacobian(objective):
    space = SpaceObjective(objective)
    theta = starting_point(objective.loops, objective.model)
    theta[-3:] = [1e5, 3e-4, 0.3]
    u = space.space.to_u(theta)
    r = space.weighted_residuals(u)
    assert float(r @ r) == pytest.approx(float(space(u[None, :])[0]), rel=1e-12)
    jac = space.jacobian(u)
    step = 1e-7 * np.maximum(np.abs(u), 1.0)
    column = (space.weighted_residuals(u + step * np.eye(u.size)[4]) - r) / step[4]
    assert np.allclose(jac[:, 4], column, rtol=1e-3, atol=1e-6 * np.abs(column).max())
    assert space.evaluations == 1 + 1 + 2 * u.size + 1


@pytest.mark.slow  # over 3 s (fast lane, 2 cores, 2026-11-29)
def test_memetic_search_spends_its_budget_and_never_ends_above_its_starting_point(objective):
    start = starting_point(objective.loops, objective.model)
    result = memetic_search(objective, [start], 0, budget=800)
    assert result.fitness <= float(objective(start[None, :])[0])
    refinement = REFINE_NFEV * (1 + 2 * objective.dim)  # one refinement's residual calls and Jacobian probes at most
    assert 800 <= result.evaluations <= 800 + refinement + 2 * 32 + result.polish["evaluations"] + 1
    assert [r["round"] if "round" in r else r["iteration"] for r in result.history] == list(range(1, len(result.history) + 1))
    again = memetic_search(objective, [start], 0, budget=800)
    assert again.fitness == result.fitness  # one seed, one answer


def test_an_island_s_counts_and_best_so_far_run_on_across_a_restart_and_its_fresh_search_keeps_quiet(objective):
    space = SpaceObjective(objective)
    rows = starting_points(objective, starting_point(objective.loops, objective.model))
    assert rows.shape[0] == 3 and np.all(rows >= objective.bounds[:, 0]) and np.all(rows <= objective.bounds[:, 1])  # the linear estimate, 2 Bouc-Wen reads
    island = Island(
        space, "pso", 5, {"population": 6, "initial_population": 12, "synchronous": True, "addpop_level": 1, "iterations": 10**6}, starts=space.space.to_u(rows)
    )
    island.step()
    assert island.fitness <= float(objective(rows).min()) and island.evaluations == 12 + 3  # the starts joined the first population
    for _ in range(REFINE_EVERY * STALL):
        island.step()
        island.refine()
    assert island.history == sorted(island.history, reverse=True) and island.restarts == 0
    before = (island.iteration, island.evaluations, island.history[-1], island.best(1)[0][0].copy())
    island.stalled = STALL  # as if its best had not moved for STALL refinements
    assert island.stale
    island.restart()
    island.step()
    assert island.restarts == 1 and island.iteration == before[0] + 1 and island.evaluations == before[1] + 12
    assert island.history[-1] == before[2] <= island.fitness  # the best so far stays; the fresh search starts above it
    assert not np.array_equal(island.best(1)[0][0], before[3]) and not island.stale
    x, f = before[3][None, :], space(before[3][None, :])
    assert island.quiet and island.inject(x, f) == 0
    while island.quiet:
        island.step()
    assert island.iteration == before[0] + 1 + QUIET and island.inject(x, f) == 1 and island.fitness == f[0]


def test_an_island_is_an_ask_tell_optimizer_that_restarts_once_it_has_stalled():
    space = SpaceObjective(build_objective(synth_loops(noise_pct=1.0, n_points=16).subset(np.arange(0, 120, 12)), "thesis"))
    options = {"population": 6, "initial_population": 12, "synchronous": True, "addpop_level": 1, "iterations": 40}
    island = Island(space, "pso", 3, options)
    x = island.ask()
    assert np.array_equal(island.ask(), x)  # asked again before tell: the same candidates
    with pytest.raises(ValueError):
        island.tell(x[:1], space(x[:1]))
    island.tell(x, space(x))
    assert (island.iteration, island.evaluations, island.history) == (0, 12, [island.fitness])
    island.refine()
    while not island.stale:  # the refinement reaches the valley's bottom: no progress after it
        island.step()
        island.refine()
    assert island.restarts == 0 and island.iteration <= REFINE_EVERY * (STALL + 2)
    held, best = island.fitness, island.best(1)[0][0].copy()
    island.restart()
    assert np.array_equal(island.best(1)[0][0], best)  # until its next iteration it migrates what it has
    island.step()
    assert island.restarts == 1 and not island.stale and island.fitness > held == island.history[-1]

    def drive(optimizer: Island) -> None:  # a campaign node's hook: refine, restart when stalled
        optimizer.refine()
        if optimizer.stale:
            optimizer.restart()

    own = SpaceObjective(space.objective)
    twin = Island(own, "pso", 3, options)
    rows = run(twin, own, migrate=drive)
    assert twin.done and [r.iteration for r in rows] == list(range(41)) and twin.restarts >= 2
    assert [r.best_fitness for r in rows] == twin.history == sorted(twin.history, reverse=True)
    assert np.all(np.diff([r.evaluations for r in rows]) > 0) and twin.evaluations == own.evaluations  # its refinements included
    assert twin.history[: len(island.history)] == island.history  # stepped or driven by run(): one search
    alone, pair = (memetic_search(space.objective, [], 0, budget=600, islands=n, population=6) for n in (1, 2))
    assert alone.polish["restarts"] == 0 < pair.polish["restarts"]  # the island holding the best never restarts


@pytest.mark.slow  # over 3 s (fast lane, 2 cores, 2026-11-29)
def test_fit_runs_memetic_islands_on_memory_models_and_the_thesis_run_elsewhere(problem):
    fitted = hysid.fit(problem.loops, problem.model, bounds=problem.bounds, termination=hysid.Termination(budget=1500))
    assert fitted.settings["algo"] == "memetic islands" and fitted.runs[0].algo == "memetic"
    easy = build_objective(problem.loops, "baseline", bounds={k: v for k, v in problem.bounds.items() if k in ("xi0", "w0", "meq")})
    assert not needs_islands(easy.model)


def test_run_method_runs_a_peer_on_a_problem(problem):
    out = run_method(problem, "least_squares", 0, 300)
    assert out["evaluations"] == 300 and np.isfinite(out["fitness"])


def test_memetic_search_takes_the_diagnosis_objective(problem, objective):
    """The diagnosis' refits call it on the harmonic objective (same contract as the Objective)."""
    from hysid_model.harmonics import HarmonicObjective, Harmonics

    harmonic = HarmonicObjective(Harmonics.from_loops(problem.loops), objective.model)
    start = starting_point(problem.loops, objective.model)
    result = memetic_search(harmonic, [start], 1, budget=400)
    assert result.fitness <= float(harmonic(start[None, :])[0]) and np.all(np.isfinite(result.theta))
    assert np.all((result.theta >= harmonic.bounds[:, 0]) & (result.theta <= harmonic.bounds[:, 1]))


@pytest.mark.slow  # over 3 s
def test_the_validation_bench_judges_a_case_against_its_truth_and_writes_the_table(tmp_path, capsys):
    """``hysid bench validation``: the sensor-distortion case is read as the sensor's and matches its truth; the
    Markdown table names it with its verdict."""
    from hysid.cli import main

    table = tmp_path / "VALIDATION.md"
    assert main(["bench", "validation", "--cases", "sensor_distortion", "--markdown", str(table), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    (row,) = result["cases"]
    assert row["reading"] == "fundamental" and row["named"] == [] and row["matches"]
    assert row["nrmse_pct"] <= 1.1 * row["truth_nrmse_pct"]
    text = table.read_text()
    assert "| `sensor_distortion` |" in text and "1 of 1 cases match" in text
    assert main(["bench", "validation", "--cases", "nonsense"]) == 2
    assert "unknown case 'nonsense'" in capsys.readouterr().err
