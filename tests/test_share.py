"""The shares of a mixed campaign (island/share.py): credit, moves (staged and adaptive), and a search carried on by another algorithm."""

from __future__ import annotations

import re
import threading

import numpy as np
import pytest

from coordinator.launch import island_specs, run_campaign
from coordinator.links import MemoryLink
from coordinator.loop import pump
from coordinator.state import Coordinator, resume
from coordinator.store import Store
from hysid.campaigns import CampaignResult
from hysid_model.errors import HysidInputError
from hysid_model.synth import TRUE_PARAMS, synth_loops
from island.algorithms import ALGORITHMS, ROLES, make_optimizer, switch_algorithm
from island.config import CampaignConfig
from island.coordinator_messages import decode_control
from island.ga import GA
from island.island_messages import History, decode_history, encode_history
from island.memory import MemoryBus
from island.migration import Migration
from island.node import IslandNode
from island.pso import PSO
from island.share import LEADING, WINDOW, Share, Staged, check_share
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


def islands(**algos: str) -> dict[tuple[str, str], str]:
    return {(name, "r"): algo for name, algo in algos.items()}


# --- the policy -------------------------------------------------------------------------------
def test_a_lagging_algorithm_gives_the_leader_one_island_per_round_once_a_window_shows_it():
    share = Share(["ga", "pso"])
    alive = islands(**{"ga-0": "ga", "ga-2": "ga", "pso-1": "pso", "pso-3": "pso"})
    reviews = []
    for e in range(1, WINDOW + 1):
        share.credit("pso", 1.0)
        share.credit("ga", 0.004)  # against PSO's 1 order of magnitude per round
        share.credit("ga", -1.0)  # nothing (a gain never falls; a repeated message adds nothing)
        reviews.append(share.review(1000 * e, 1000, alive, {}))
        assert share.review(1000 * e + 500, 1000, alive, {}) == []  # the round is not over
    *before, (move,) = reviews
    assert before == [[]] * (WINDOW - 1)  # the window fills first
    assert (move.island, move.src, move.dst, move.evaluations) == ("ga-0", "ga", "pso", 1000 * WINDOW)
    assert move.credit == {"ga": pytest.approx(WINDOW * 0.004), "pso": pytest.approx(WINDOW * 1.0)}
    alive[("ga-0", "r")] = "pso"
    share.credit("pso", 1.0)
    assert [(m.island, m.dst) for m in share.review(1000 * (WINDOW + 1), 1000, alive, {})] == [("ga-2", "pso")]  # GA still lags: the next one
    alive[("ga-2", "r")] = "pso"
    for e in range(WINDOW + 2, 3 * WINDOW):  # nobody left to move
        share.credit("pso", 1.0)
        assert share.review(1000 * e, 1000, alive, {}) == []
    assert [m.island for m in share.review(1000 * 3 * WINDOW, 1000, {**alive, ("ga-9", "r"): "ga"}, {})] == ["ga-9"]  # a late GA joiner follows


def test_islands_are_shared_in_proportion_to_the_credit_per_island():
    share = Share(["ga", "pso"])
    alive = islands(**{"ga-0": "ga", "ga-2": "ga", "pso-1": "pso", "pso-3": "pso"})
    for e in range(1, WINDOW + 1):
        share.credit("ga", 1.0)  # half of PSO's credit per island: one island of four is GA's share
        share.credit("pso", 2.0)
        moves = share.review(1000 * e, 1000, alive, {})
    assert [(m.island, m.src, m.dst) for m in moves] == [("ga-0", "ga", "pso")]
    alive[("ga-0", "r")] = "pso"
    for e in range(WINDOW + 1, 4 * WINDOW):
        share.credit("ga", 0.5)  # the GA island left keeps gaining half of what a PSO island gains
        share.credit("pso", 3.0)
        assert share.review(1000 * e, 1000, alive, {}) == []


def test_a_wrong_call_is_undone_by_the_islands_left_once_the_moved_island_had_its_window():
    share = Share(["ga", "pso"])
    alive = islands(**{"ga-0": "ga", "pso-1": "pso", "pso-3": "pso"})
    share.credit("ga", 2.0)  # a GA's early lucky offspring
    assert share.review(1000, 1000, alive, {}) == []
    (wrong,) = share.review(2000, 1000, alive, {})
    assert (wrong.island, wrong.dst) == ("pso-1", "ga")
    alive[("pso-1", "r")] = "ga"
    share.credit("pso", 1.0)  # the PSO island left gains, the GA islands do not
    assert [(m.island, m.src, m.dst) for m in share.review(3000, 1000, alive, {})] == [("ga-0", "ga", "pso")]
    alive[("ga-0", "r")] = "pso"
    reviews = []
    for e in range(4, 4 + WINDOW):
        share.credit("pso", 1.0)
        reviews.append(share.review(1000 * e, 1000, alive, {}))
    *waiting, (back,) = reviews
    assert waiting == [[]] * (WINDOW - 1)  # pso-1 stays with the GA for a window
    assert (back.island, back.src, back.dst) == ("pso-1", "ga", "pso")  # and comes back


def test_credit_is_per_island():
    share = Share(["ga", "pso"])
    alive = islands(**{"ga-0": "ga", "pso-1": "pso", "pso-2": "pso", "pso-3": "pso"})
    for e in range(1, 2 * WINDOW + 2):
        share.credit("pso", 3.0)  # three islands
        share.credit("ga", 0.3)  # one island: a tenth of PSO's credit in all, but its share is still one island of four
        assert share.review(1000 * e, 1000, alive, {}) == []


def test_no_move_without_credit_or_when_the_other_algorithm_keeps_up():
    alive = islands(**{"ga-0": "ga", "pso-1": "pso"})
    idle = Share(["ga", "pso"])
    assert [idle.review(e, 1000, alive, {}) for e in range(1000, 8000, 1000)] == [[]] * 7  # nobody improved: nothing to follow
    close = Share(["ga", "pso"])
    for e in range(1000, 8000, 1000):
        close.credit("pso", 1.0)
        close.credit("ga", 0.4)  # its share of two islands: 2 x 0.4 / 1.4, one
        assert close.review(e, 1000, alive, {}) == []
    converged = Share(["ga", "pso"])
    for e in range(1000, 8000, 1000):
        converged.credit("pso", 0.9 * LEADING / WINDOW)  # the last digits of a converged best: nobody to follow
        assert converged.review(e, 1000, alive, {}) == []
    turns = Share(["ga", "pso"])
    for e in range(1, 12):  # the algorithms gain in turns, each within every window
        turns.credit("ga" if e % 2 else "pso", 1.0)
        assert turns.review(1000 * e, 1000, alive, {}) == []
    only = Share(["pso"])
    only.credit("pso", 1.0)
    assert [only.review(e, 1000, islands(**{"pso-0": "pso"}), {}) for e in (1000, 2000, 3000)] == [[]] * 3


def test_the_staged_share_moves_each_ga_run_to_pso_once_it_searched_its_survey():
    staged = Staged(["pso", "ga"], survey=5)
    alive = islands(**{"ga-0": "ga", "ga-2": "ga", "pso-1": "pso", "pso-3": "pso"})
    staged.credit("ga", 2.0)  # the GA gains more: the staged share moves by the algorithms' roles, not by credit
    staged.credit("pso", 0.5)
    early = {k: 4 for k in alive}
    assert staged.review(400, 1000, alive, early) == []  # four iterations each: still exploring
    moves = staged.review(500, 1000, alive, {**early, ("ga-2", "r"): 5})  # each run on its own count
    assert [(m.island, m.src, m.dst, m.evaluations, m.credit) for m in moves] == [("ga-2", "ga", "pso", 500, {"pso": 0.5, "ga": 2.0})]
    after = {**alive, ("ga-2", "r"): "pso"}  # the coordinator's assignment after the move
    assert staged.review(510, 1000, after, {**early, ("ga-2", "r"): 6}) == []
    assert [m.island for m in staged.review(600, 1000, after, {k: 6 for k in alive})] == ["ga-0"]
    assert staged.review(700, 1000, {k: "pso" for k in alive}, {k: 9 for k in alive}) == []  # nobody left to move


def test_every_algorithm_has_a_role():
    assert ROLES.keys() == ALGORITHMS.keys() and set(ROLES.values()) == {"explore", "converge"}


def test_share_names_are_checked():
    assert check_share("fixed") == "fixed"
    with pytest.raises(HysidInputError, match="share must be one of staged, adaptive, fixed"):
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


# --- through the coordinator and the islands ---------------------------------------------------------
LOOPS = synth_loops(n_points=30)


def history_sender(c: Coordinator, link: MemoryLink, creds: dict):
    """``send(island, algo, seed, iterations, gain, final)``: that island's honest history of ``iterations`` (rows at the
    Synth truth, 10 + 15 evaluations an iteration), in sequence, taken by the coordinator ``c`` and pumped through ``link``."""
    campaign = c.config.name
    x = c.objective.model.from_dict(TRUE_PARAMS)
    f = float(c.objective(x[None, :])[0])
    seq = dict.fromkeys(creds, 0)

    def send(island: str, algo: str, seed: int, iterations: range, gain: float = 0.0, final: bool = False) -> None:
        rows = np.array([[i, f, 20 + 25 * i, 0.01 * i] for i in iterations], dtype=float)
        counts = {"sent": 0, "received": 0, "taken": 0, "rejected": 0}
        payload = encode_history(History(campaign, island, creds[island].run, algo, seed, rows, x, f, counts, final, seq[island], gain), creds[island])
        seq[island] += 1
        assert c.receive(f"hysid/{campaign}/history/{island}", payload)
        pump(c, link, 5.0)

    return send


def test_the_coordinator_credits_gains_moves_the_lagging_island_and_tells_it_in_the_roster(tmp_path):
    sizes = {"population": 10, "initial_population": 20}
    config = CampaignConfig.create(
        LOOPS, name="c1", algos=["ga", "pso"], options={"ga": sizes, "pso": sizes}, migration=Migration(interval=5, k=2), until_stopped=True, share="adaptive"
    )
    c = Coordinator(Store(tmp_path / "c.sqlite"), config, LOOPS, Termination(budget=10**6))
    link = MemoryLink(threading.Event())
    creds = {"ga-0": c.join("ga-0", "ga", 0), "pso-1": c.join("pso-1", "pso", 1)}
    for island in creds:
        c.member(island, True, wait_s=None)
    send = history_sender(c, link, creds)

    def report(island: str, first: int, gain: float, algo: str) -> None:
        """Five iterations of honest rows and the island's gain so far."""
        send(island, algo, {"ga-0": 0, "pso-1": 1}[island], range(first, first + 5), gain=gain)

    rounds = 0
    while not c.sharing.moves and rounds < 3 * WINDOW:  # one round: both islands' five iterations (2 x 5 x 25 evaluations)
        report("ga-0", 5 * rounds, 0.001 * rounds, "ga")  # a GA that hardly gains
        report("pso-1", 5 * rounds, 1.0 * rounds, "pso")  # a PSO that gains an order of magnitude per round
        rounds += 1
    assert [(m.island, m.src, m.dst) for m in c.sharing.moves] == [("ga-0", "ga", "pso")]
    assert rounds <= WINDOW + 1  # the first history only sets each island's baseline
    assert [(m.island, m.src, m.dst) for m in c.store.moves("c1")] == [("ga-0", "ga", "pso")]
    control = decode_control(c.control_message(), "c1", c.secret.coordinator)
    assert {m.island: m.algo for m in control.members} == {"ga-0": "pso", "pso-1": "pso"}
    report("ga-0", 5 * rounds, 0.001 * rounds, "ga")  # rows sent before the island heard of its move
    report("ga-0", 5 * rounds + 5, 0.3 * rounds, "pso")  # and after
    assert c.store.rejected_reasons("c1") == {}
    report("pso-1", 5 * rounds, 1.0 * rounds, "ga")  # PSO was never moved to GA
    assert c.store.rejected_reasons("c1") == {"implausible": 1}
    taken_up = resume(c.store, "c1")  # a restarted coordinator knows every algorithm each run was told to run
    assert taken_up.sharing.algos == {("ga-0", creds["ga-0"].run): {"ga", "pso"}, ("pso-1", creds["pso-1"].run): {"pso"}}
    c.store.close()


def test_the_coordinator_moves_a_ga_run_once_its_history_reaches_the_survey_if_it_can_still_move(tmp_path):
    sizes = {"population": 10, "initial_population": 20}
    config = CampaignConfig.create(
        LOOPS, name="c2", algos=["ga", "pso"], options={"ga": sizes, "pso": sizes}, migration=Migration(interval=5, k=2), until_stopped=True
    )  # the default share: staged, a survey of 5 iterations
    c = Coordinator(Store(tmp_path / "c.sqlite"), config, LOOPS, Termination(budget=10**6))
    link = MemoryLink(threading.Event())
    seeds = {"ga-0": 0, "pso-1": 1, "ga-2": 2, "ga-4": 4}
    creds = {island: c.join(island, island[:-2], seed) for island, seed in seeds.items()}
    for island in ("ga-0", "pso-1", "ga-2"):
        c.member(island, True, wait_s=None)  # ga-4's liveliness token has not shown yet
    send = history_sender(c, link, creds)

    def report(island: str, first: int, last: int, final: bool = False) -> list[str]:
        """Honest rows of iterations ``first..last``; the runs moved so far."""
        send(island, island[:-2], seeds[island], range(first, last + 1), final=final)
        return [m.island for m in c.sharing.moves]

    assert report("ga-0", 0, 4) == []  # four iterations: still exploring
    assert report("ga-2", 0, 9, final=True) == []  # done before the survey counted: nothing left to move
    assert report("ga-4", 0, 7) == []  # not seen alive yet (after a restart it may never come back)
    assert report("ga-0", 5, 6) == ["ga-0"]
    c.member("ga-4", True, wait_s=None)
    assert report("ga-4", 8, 8) == ["ga-0", "ga-4"]
    assert report("pso-1", 0, 9) == ["ga-0", "ga-4"]  # PSO converges: it stays
    assert {m.island: m.algo for m in decode_control(c.control_message(), "c2", c.secret.coordinator).members}["ga-0"] == "pso"
    taken_up = resume(c.store, "c2")  # a restarted coordinator follows the moves stored, and makes none again
    assert {k[0]: v for k, v in taken_up.sharing.assigned.items()} == {"ga-0": "pso", "pso-1": "pso", "ga-2": "ga", "ga-4": "pso"}
    c.store.close()


def test_an_island_told_another_algorithm_carries_its_search_on_with_it():
    config = CampaignConfig(
        name="c1",
        algos=["ga", "pso"],
        options={a: {"population": 10, "initial_population": 20, "iterations": 40} for a in ("ga", "pso")},
        migration=Migration(interval=5, k=2),
    )
    delivered: list[bytes] = []
    told = {"ga-0": None}
    bus = MemoryBus("c1", ["ga-0"], lambda key, data: delivered.append(data) if "/history/" in key else None, threading.Event(), assigned=told.get)
    node = IslandNode("ga-0", "ga", 3, config, config.objective(LOOPS), history_every_s=0.0)
    transport = bus.transport("ga-0", "ga", 3)

    def tell_at_iteration_12(row) -> None:
        record(row)
        if row.iteration == 12:
            told["ga-0"] = "pso"

    record, node._record = node._record, tell_at_iteration_12
    node.run(transport)
    assert node.moves == [(12, "ga", "pso")] and isinstance(node.optimizer, PSO) and node.algo == "pso"
    assert [r[0] for r in node.rows] == list(range(41))  # one run, no iteration missing or repeated
    assert np.all(np.diff([r[2] for r in node.rows]) > 0) and np.all(np.diff([r[1] for r in node.rows]) <= 0)
    keys = {"run": node.credentials.public}
    algos = [decode_history(d, "c1", node.objective.bounds, key_for=lambda s, r: keys["run"]).algo for d in delivered]
    assert algos[:13] == ["ga"] * 13 and set(algos[13:]) == {"pso"}  # iterations 0..12 as GA, then PSO


# --- in a campaign --------------------------------------------------------------------------------
def mixed_campaign(tmp_path, share: str, budget: int):
    """Four islands, half GA and half PSO, on the thesis model with Coulomb friction from scratch (where
    the thesis' GA stays orders of magnitude behind its PSO)."""
    loops = synth_loops()
    sizes = {"population": 20, "initial_population": 40}
    config = CampaignConfig.create(
        loops,
        name=f"mixed-{share}",
        model="thesis+coulomb_friction",
        algos=["ga", "pso"],
        options={"ga": sizes, "pso": sizes},
        migration=Migration(interval=5, k=2),
        seed=4,
        min_islands=4,
        until_stopped=True,
        share=share,
    )
    config.start = None
    db = tmp_path / f"{share}.sqlite"
    coordinator = Coordinator(Store(db), config, loops, Termination(budget=budget))
    outcome = run_campaign(coordinator, island_specs(4, ["ga", "pso"], 40), single_node=True, polish=False)
    coordinator.store.close()
    return coordinator, outcome, db


@pytest.mark.slow  # over 3 s (fast lane, 2 cores, 2026-11-29)
@pytest.mark.parametrize("share", ["staged", "adaptive"])
def test_a_campaign_s_moves_are_stored_followed_by_the_islands_and_reported(tmp_path, share):
    coordinator, outcome, db = mixed_campaign(tmp_path, share, budget=12_000)
    moves = outcome.settings["moves"]
    assert moves
    last = {m["island"]: m for m in moves}
    records = {r["island"]: r for r in outcome.islands}
    heard = {i: m["dst"] for i, m in last.items() if m["evaluations"] <= 10_000}  # a move ordered in the last round may meet the stop first
    assert all(records[i]["algo"] == algo for i, algo in heard.items())  # each moved island's own history says where it went
    assert all(records[i]["algorithms"] == [records[i]["algo"]] for i in records if i not in last)  # named by index, never by algorithm
    assert all(records[i]["algorithms"][:2] == [m["src"], m["dst"]] for i, m in {m["island"]: m for m in reversed(moves)}.items())
    store = Store(db)
    try:
        for island, run, *_ in store.runs(coordinator.name):
            assert store.handled(coordinator.name, island, run) == [(0, records[island]["iterations"])]  # no row missing across a move
        assert store.rejected_reasons(coordinator.name) == {}
        taken_up = resume(store, coordinator.name)
        assert {k[0]: v for k, v in taken_up.sharing.assigned.items() if k[0] in last} == {i: m["dst"] for i, m in last.items()}
    finally:
        store.close()
    summary = CampaignResult.from_database(db).summary()
    assert f"share: {share}, {len(moves)} island move(s)" in summary
    assert all(f"{m['src'].upper()} -> {m['dst'].upper()} after {m['evaluations']:,} evaluations" in summary for m in moves)


def test_a_staged_campaign_hands_its_ga_islands_over_to_pso_after_their_first_round(tmp_path, monkeypatch):
    """Whenever the islands' timed histories go out: an island's history goes out at every migration, and the
    hand-over is decided from it (not from a timed history, which under load came late: the budget ran out first)."""
    monkeypatch.setattr("coordinator.launch.MEMORY_HISTORY_EVERY_S", 1.0)  # a timed history at most every second: it decides nothing
    coordinator, outcome, db = mixed_campaign(tmp_path, "staged", budget=4_000)
    moves = outcome.settings["moves"]
    store = Store(db)
    seen = (moves, [(r["island"], r["algorithms"], r["iterations"]) for r in outcome.islands], store.rejected_reasons(coordinator.name))  # shown if it fails
    store.close()
    assert sorted((m["island"], m["src"], m["dst"]) for m in moves) == [("island-0", "ga", "pso"), ("island-2", "ga", "pso")], seen
    assert all(m["evaluations"] < 2_000 for m in moves), seen  # one round: every island's first migration interval
    assert {r["island"]: r["algo"] for r in outcome.islands} == dict.fromkeys(["island-0", "island-1", "island-2", "island-3"], "pso"), seen
    assert {r["island"]: r["algorithms"] for r in outcome.islands} == {  # the name never contradicts the algorithm: it is beside it
        "island-0": ["ga", "pso"],
        "island-1": ["pso"],
        "island-2": ["ga", "pso"],
        "island-3": ["pso"],
    }
    summary = CampaignResult.from_database(db).summary()
    assert "share: staged, 2 island move(s) of the exploring algorithm (GA) to the converging one (PSO)" in summary
    assert re.search(r"\n  island-0 +GA -> PSO +seed 40 ", summary) and re.search(r"\n  island-1 +PSO +seed 41 ", summary)


def test_a_fixed_share_moves_nobody(tmp_path):
    _, outcome, _ = mixed_campaign(tmp_path, "fixed", budget=4_000)
    assert outcome.settings["moves"] == [] and {r["algo"] for r in outcome.islands} == {"ga", "pso"}


@pytest.mark.parametrize(
    ("share", "interval", "why"),
    [
        ("staged", 5, "none: no GA island searched its first migration interval (5 iterations) before it ended"),
        ("staged", 0, "none: the islands were isolated (migration interval 0)"),
        ("adaptive", 5, "none: each algorithm held its due share of the islands after every round"),
    ],
)
def test_a_share_that_moved_no_island_says_why(share, interval, why):
    from hysid.report.campaign_text import SHARE_RULES, share_lines

    settings = {"algos": ["ga", "pso"], "share": share, "moves": [], "migration": {"interval": interval, "k": 2}}
    lines = share_lines(settings)
    assert lines[0] == f"share: {share}, 0 island move(s) {SHARE_RULES[share]}" and lines[1].strip().startswith(why)
    assert not any(
        line.strip().startswith("none:")
        for line in share_lines({**settings, "moves": [{"island": "ga-0", "src": "ga", "dst": "pso", "evaluations": 100, "credit": {"ga": 0.1, "pso": 1.0}}]})
    )


def test_a_move_the_island_ended_before_hearing_is_reported_as_not_followed():
    """An island that spent its own iterations before the coordinator's order reached it (island processes, a
    fixed iteration budget) ended with its first algorithm: the summary says the move was ordered, not followed."""
    from hysid.report.campaign_text import share_lines

    move = {"island": "ga-0", "src": "ga", "dst": "pso", "evaluations": 3076, "credit": {"ga": 0.0, "pso": 0.0}}
    settings = {"algos": ["ga", "pso"], "share": "staged", "moves": [move], "migration": {"interval": 5, "k": 2}}
    unheard = share_lines(settings, [{"island": "ga-0", "algo": "ga"}, {"island": "pso-1", "algo": "pso"}])
    assert unheard[1].endswith("; not followed: the island's last history shows GA")
    followed = share_lines(settings, [{"island": "ga-0", "algo": "pso"}, {"island": "pso-1", "algo": "pso"}])
    assert "not followed" not in "\n".join(followed) and followed[1] == unheard[1].split("; not followed")[0]
