"""The adaptive share of a mixed campaign (island/share.py): credit, moves, and a search carried on by another algorithm."""

from __future__ import annotations

import numpy as np
import pytest

from coordinator.launch import island_specs, run_campaign
from coordinator.server import Coordinator, resume
from coordinator.store import Store
from hysid.campaigns import CampaignResult
from hysid_model.errors import HysidInputError
from hysid_model.synth import synth_loops
from island.algorithms import make_optimizer, switch_algorithm
from island.config import CampaignConfig
from island.ga import GA
from island.migration import Migration
from island.pso import PSO
from island.share import LAGGING, PERSIST, WINDOW, Share, check_share
from island.termination import Termination

BOUNDS = np.array([[-5.0, 5.0]] * 4)
SIZES = {"population": 10, "initial_population": 20, "iterations": 1000}


def sphere(x: np.ndarray) -> np.ndarray:
    return np.sum((np.atleast_2d(x) - 1.0) ** 2, axis=1)


def iterate(opt, n: int) -> None:
    target = opt.iteration + n
    while opt.iteration < target or not opt.history:
        x = opt.ask()
        opt.tell(x, sphere(x))


def islands(**algos_best: tuple[str, float]) -> dict[tuple[str, str], tuple[str, float]]:
    return {(name, "r"): v for name, v in algos_best.items()}


# --- the policy -------------------------------------------------------------------------------
def test_a_lagging_algorithm_gives_its_worst_island_to_the_leader_after_persisting_reviews():
    share = Share(["ga", "pso"])
    alive = islands(**{"ga-0": ("ga", 1e-2), "ga-2": ("ga", 5e-2), "pso-1": ("pso", 1e-3), "pso-3": ("pso", 1e-3)})
    reviews = []
    for e in range(1, WINDOW + PERSIST):
        share.credit("pso", 1.0)
        share.credit("ga", 0.004)  # against PSO's 1 order of magnitude per round
        share.credit("ga", -1.0)  # nothing (a gain never falls; a repeated message adds nothing)
        reviews.append(share.review(1000 * e, 1000, alive))
        assert share.review(1000 * e + 500, 1000, alive) == []  # the round is not over
    *before, (move,) = reviews
    assert before == [[]] * (WINDOW + PERSIST - 2)  # a window to fill, then PERSIST lagging reviews
    assert (move.island, move.src, move.dst, move.evaluations) == ("ga-2", "ga", "pso", 1000 * (WINDOW + PERSIST - 1))  # the worse GA island
    assert move.credit == {"ga": pytest.approx(WINDOW * 0.004), "pso": pytest.approx(WINDOW * 1.0)}
    alive[("ga-2", "r")] = ("pso", 1e-3)
    later = []
    for e in range(WINDOW + PERSIST, WINDOW + 2 * PERSIST):
        share.credit("pso", 1.0)
        later.append(share.review(1000 * e, 1000, alive))
    assert later[:-1] == [[]] * (PERSIST - 1) and [(m.island, m.dst) for m in later[-1]] == [("ga-0", "pso")]  # one move at a time


def test_credit_is_per_island():
    share = Share(["ga", "pso"])
    alive = islands(**{"ga-0": ("ga", 1.0), "pso-1": ("pso", 1.0), "pso-2": ("pso", 1.0), "pso-3": ("pso", 1.0)})
    for e in range(1, WINDOW + PERSIST + 2):
        share.credit("pso", 3.0)  # three islands
        share.credit("ga", 1.2 * LAGGING)  # one island: above LAGGING of PSO's credit per island
        assert share.review(1000 * e, 1000, alive) == []


def test_no_move_without_credit_or_when_the_other_algorithm_keeps_up():
    alive = islands(**{"ga-0": ("ga", 1.0), "pso-1": ("pso", 1.0)})
    idle = Share(["ga", "pso"])
    assert [idle.review(e, 1000, alive) for e in range(1000, 8000, 1000)] == [[]] * 7  # nobody improved: nothing to follow
    close = Share(["ga", "pso"])
    for e in range(1000, 8000, 1000):
        close.credit("pso", 1.0)
        close.credit("ga", 1.01 * LAGGING)
        assert close.review(e, 1000, alive) == []
    flipping = Share(["ga", "pso"])
    for e in range(1, 12):  # each algorithm leads for WINDOW rounds in turn: nobody lags PERSIST reviews in a row
        flipping.credit("ga" if (e // WINDOW) % 2 else "pso", 1.0)
        assert flipping.review(1000 * e, 1000, alive) == []


def test_an_algorithm_keeps_at_least_keep_islands_and_a_single_algorithm_never_moves():
    share = Share(["ga", "pso"], keep=1)
    alive = islands(**{"ga-0": ("ga", 1.0), "pso-1": ("pso", 1e-3)})
    for e in range(1, 2 * (WINDOW + PERSIST)):
        share.credit("pso", 1.0)
        assert share.review(1000 * e, 1000, alive) == []
    only = Share(["pso"])
    only.credit("pso", 1.0)
    assert only.review(1000, 1000, islands(**{"pso-0": ("pso", 0.1)})) == []


def test_share_names_are_checked():
    assert check_share("fixed") == "fixed"
    with pytest.raises(HysidInputError, match="share must be one of adaptive, fixed"):
        check_share("greedy")
    with pytest.raises(HysidInputError, match="share"):
        CampaignConfig(name="c", share="greedy")


def test_only_the_algorithms_own_moves_gain():
    """GA offspring and PSO particle moves count; the additional population and migrants do not."""
    for algo in ("ga", "pso"):
        opt = make_optimizer(algo, BOUNDS, 5, {**SIZES, "addpop_level": 0})
        iterate(opt, 30)
        assert opt.gain == pytest.approx(np.log10(opt.history[0] / opt.history[-1]))  # every improvement was its own
        before = opt.gain
        opt.inject(np.ones((1, 4)), np.zeros(1))  # a migrant at the optimum
        assert opt.gain == before and opt.best(1)[1][0] == 0.0
        with_addpop = make_optimizer(algo, BOUNDS, 5, SIZES)  # the thesis' additional population around the best
        iterate(with_addpop, 30)
        total = np.log10(with_addpop.history[0] / with_addpop.history[-1])
        assert 0 < with_addpop.gain < 0.5 * total  # on the sphere most of the progress is the additional population's


# --- a search carried on by another algorithm -----------------------------------------------------------
@pytest.mark.parametrize("src, dst", [("ga", "pso"), ("pso", "ga")])
def test_a_search_carried_on_by_another_algorithm_keeps_its_counters_history_and_best(src, dst):
    old = make_optimizer(src, BOUNDS, 7, SIZES)
    iterate(old, 5)
    best_x, best_f = old.best(1)
    new = switch_algorithm(old, dst, SIZES)
    assert type(new) is {"ga": GA, "pso": PSO}[dst]
    assert (new.iteration, new.evaluations, new.history) == (old.iteration, old.evaluations, old.history)
    x, f = new.best(1)
    np.testing.assert_array_equal(x, best_x)
    assert f[0] == best_f[0]
    iterate(new, 20)
    assert new.iteration == 25 and new.history[-1] <= best_f[0] and np.all(np.diff(new.history) <= 0)
    again = type(new).from_state(new.state_dict())  # a moved island still checkpoints
    assert again.best(1)[1][0] == new.best(1)[1][0] and again.iteration == new.iteration


def test_a_swarm_larger_than_the_population_it_carries_on_cycles_the_candidates():
    old = make_optimizer("ga", BOUNDS, 3, {**SIZES, "population": 4, "initial_population": 8})
    iterate(old, 2)
    new = switch_algorithm(old, "pso", {**SIZES, "population": 10})
    assert new.P.shape == (10, 4) and new.Pgf == old.best(1)[1][0]
    np.testing.assert_array_equal(new.P[4:8], new.P[0:4])
    assert switch_algorithm(new, "pso", SIZES) is new


def test_a_search_is_carried_on_only_between_two_iterations():
    opt = make_optimizer("pso", BOUNDS, 1, SIZES)
    with pytest.raises(ValueError, match="between two of its iterations"):
        switch_algorithm(opt, "ga", SIZES)  # nothing evaluated yet
    iterate(opt, 1)
    opt.ask()
    with pytest.raises(ValueError, match="between two of its iterations"):
        switch_algorithm(opt, "ga", SIZES)  # a batch is pending


# --- in a campaign --------------------------------------------------------------------------------
STALLED_GA = {"mutation_rate": 0.0, "alpha_blx": 0.0, "addpop_level": 0}
"""A GA that only recombines genes its parents already have: it stops improving within a few iterations."""


def mixed_campaign(tmp_path, share: str, budget: int = 12_000):
    loops = synth_loops()
    sizes = {"population": 20, "initial_population": 40}
    config = CampaignConfig.create(
        loops, name=f"mixed-{share}", model="thesis", algos=["ga", "pso"], options={"ga": {**sizes, **STALLED_GA}, "pso": sizes},
        migration=Migration(interval=5, k=2), seed=4, min_islands=4, until_stopped=True, share=share,
    )
    config.start = None  # from scratch
    db = tmp_path / f"{share}.sqlite"
    coordinator = Coordinator(Store(db), config, loops, Termination(budget=budget))
    outcome = run_campaign(coordinator, island_specs(4, ["ga", "pso"], 40), single_node=True, polish=False)
    coordinator.store.close()
    return coordinator, outcome, db


def test_a_stalled_algorithm_gives_its_islands_to_the_one_that_improves(tmp_path):
    coordinator, outcome, db = mixed_campaign(tmp_path, "adaptive")
    moves = outcome.settings["moves"]
    assert moves and all((m["src"], m["dst"]) == ("ga", "pso") for m in moves), moves
    assert all(m["credit"]["pso"] > m["credit"]["ga"] / LAGGING for m in moves)
    moved = {m["island"] for m in moves}
    records = {r["island"]: r for r in outcome.islands}
    assert all(records[i]["algo"] == "pso" for i in moved)  # the island's own history says it went on as PSO
    store = Store(db)
    try:
        for island, run, *_ in store.runs(coordinator.name):
            assert store.contiguous_iterations(coordinator.name, island, run) == records[island]["iterations"]  # no row missing across the move
        taken_up = resume(store, coordinator.name)
        assert {k: v for k, v in taken_up.assigned.items() if k[0] in moved} == {(m["island"], m["run"]): "pso" for m in moves}
    finally:
        store.close()
    summary = CampaignResult.from_database(db).summary()
    assert f"share: adaptive, {len(moves)} island move(s)" in summary and "GA -> PSO after" in summary


def test_a_fixed_share_moves_nobody(tmp_path):
    _, outcome, _ = mixed_campaign(tmp_path, "fixed", budget=4_000)
    assert outcome.settings["moves"] == [] and {r["algo"] for r in outcome.islands} == {"ga", "pso"}
