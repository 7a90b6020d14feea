"""More than 10,000 generated hostile messages (tests/hostile.py) against a running campaign in one process:
the coordinator's receive paths (publications under every key, liveliness tokens, join requests) and the
islands' migrant path. Nothing raises, every message is rejected and counted, and the campaign ends as it
would have without them (the single-node campaign is reproducible, so "the right answer" is the same answer).
"""

from __future__ import annotations

import threading

import numpy as np
import pytest

from coordinator.launch import island_specs, run_single_node
from coordinator.state import Coordinator
from coordinator.store import Store
from hostile import Hostile, stream
from hysid_model.synth import TRUE_PARAMS, synth_loops
from island.config import CampaignConfig
from island.handshake import JoinRequest, decode_challenge, decode_joined, encode_join, encode_prove
from island.memory import MemoryBus
from island.migration import Migration
from island.node import IslandNode
from island.sealing import Counter, Credentials, new_key, public_key

pytestmark = pytest.mark.slow  # a few seconds of messages

LOOPS = synth_loops(n_points=30)
SIZES = {a: {"population": 20, "initial_population": 40, "iterations": 150} for a in ("ga", "pso")}
COORDINATOR_MESSAGES = 8000
ISLAND_MESSAGES = 2500


def config() -> CampaignConfig:
    """Islands keep their algorithm (``share="fixed"``): a move lands at whichever iteration the island
    hears of it, so only a fixed share makes two campaigns the same search, message for message."""
    return CampaignConfig.create(LOOPS, name="fz", options=SIZES, migration=Migration(interval=5, k=2, topology="ring"), seed=4, min_islands=3, share="fixed")


def campaign(tmp_path, name: str, fuzz=None) -> Coordinator:
    c = Coordinator(Store(tmp_path / f"{name}.sqlite"), config(), LOOPS)
    fuzzer = threading.Thread(target=fuzz, args=(c,)) if fuzz else None
    if fuzzer:
        fuzzer.start()
    run_single_node(c, island_specs(3, ["ga", "pso"], 4))
    if fuzzer:
        fuzzer.join(60)
    return c


def joined(c: Coordinator, island: str, algo: str, seed: int) -> Credentials:
    """The join handshake through the coordinator's inbox, as an island over Zenoh goes through it."""
    key = new_key()
    request = JoinRequest(c.name, island, algo, seed, b"b" * 16, public_key(key))
    answers: list[bytes] = []

    def answer(payload: bytes) -> bytes:
        c.join_request(island, payload, answers.append, wait_s=None)
        while not answers:
            threading.Event().wait(0.01)
        return answers.pop()

    challenge = decode_challenge(answer(encode_join(request)), c.name, island, request.nonce, c.secret.coordinator)
    run = decode_joined(answer(encode_prove(request, challenge, c.secret.admission, key)), c.name, island, request.nonce, c.secret.coordinator)
    return Credentials(island, run, key, c.secret.coordinator)


def test_ten_thousand_hostile_messages_leave_coordinator_and_islands_running_with_the_right_answer(tmp_path):
    reference = campaign(tmp_path, "reference")
    sent: dict[str, int] = {}

    def fuzz(c: Coordinator) -> None:
        broken = joined(c, "broken", "pso", 7)  # a joined island that sends nothing but junk
        c.member("broken", True, wait_s=None)
        try:
            hostile = Hostile(np.random.default_rng(12), "fz", c.objective.bounds, broken, Counter())
            implausible = float(c.checks.evaluation_bound("pso", np.array([1.0]))[0] + 1e6)
            for entry, where, payload in stream(hostile, COORDINATOR_MESSAGES, "pso", 7, implausible, ["island-0", "island-1", "island-2", "broken"]):
                if entry == "msg":
                    c.receive(where, payload, wait_s=None)
                elif entry == "member":
                    c.member(where, True, wait_s=None)
                else:
                    c.join_request(where, payload, lambda answer: sent.__setitem__("answered", sent.get("answered", 0) + 1), wait_s=None)
                sent[entry] = sent.get(entry, 0) + 1
            sent["done"] = 1
            while len(c.inbox):  # then it leaves, once its junk was handled
                threading.Event().wait(0.01)
        finally:
            c.member("broken", False, wait_s=None)  # leaves without a goodbye: lost

    fuzzed = campaign(tmp_path, "fuzzed", fuzz)
    assert sent.get("done") == 1 and sum(sent[k] for k in ("msg", "member", "join")) == COORDINATOR_MESSAGES
    assert len(fuzzed.inbox) == 0  # every message was handled before the campaign ended
    assert fuzzed.rejected == COORDINATOR_MESSAGES and "answered" not in sent  # all rejected, no bad join answered
    reasons = fuzzed.store.rejected_reasons("fz")
    assert sum(reasons.values()) == COORDINATOR_MESSAGES
    assert {"undecodable", "schema", "forged", "unjoined", "sender", "shape", "not_finite", "out_of_bounds", "implausible", "oversized"} <= set(reasons), (
        " ".join(f"{k}={v}" for k, v in sorted(reasons.items()))
    )
    assert fuzzed.stop_reason == reference.stop_reason == "every island finished"
    assert fuzzed.best.fitness == pytest.approx(reference.best.fitness, rel=1e-12)  # the same search, message for message
    polished = fuzzed.outcome().runs
    best = min(polished, key=lambda r: r.fitness)
    assert best.fitness < 1e-20  # and the right answer: the truth of the noiseless Synth set
    np.testing.assert_allclose(best.theta, fuzzed.objective.model.from_dict(TRUE_PARAMS), rtol=1e-6)
    got, want = ({r.island: r for r in c.store.islands("fz")} for c in (fuzzed, reference))
    assert {i: (r.iterations, r.evaluations) for i, r in got.items()} == {i: (r.iterations, r.evaluations) for i, r in want.items()}
    for island, r in got.items():  # re-evaluated in batches of other sizes: equal to the last bits or so
        assert r.best_fitness == pytest.approx(want[island].best_fitness, rel=1e-12)


def test_hostile_migrants_on_an_islands_receive_path_change_nothing():
    cfg = config()

    def run(fuzz: bool) -> dict[str, IslandNode]:
        stop = threading.Event()
        bus = MemoryBus("fz", ["a", "b"], lambda key, data: None, stop)
        nodes = {i: IslandNode(i, algo, seed, cfg, cfg.objective(LOOPS)) for i, algo, seed in (("a", "ga", 1), ("b", "pso", 2))}
        transports = {i: bus.transport(i, n.algo, n.seed) for i, n in nodes.items()}
        for i, n in nodes.items():
            n.attach(transports[i])
        threads = [threading.Thread(target=lambda n=n, t=transports[i]: (n.run(t), t.close())) for i, n in nodes.items()]
        if fuzz:
            broken = bus.transport("broken", "pso", 3).credentials  # admitted, so that its signed junk reaches the body checks
            hostile = Hostile(np.random.default_rng(5), "fz", nodes["a"].objective.bounds, broken, Counter())
            for k in range(ISLAND_MESSAGES):
                me, other = ("a", "b") if k % 2 else ("b", "a")
                nodes[me].receive(hostile._pick(["broken", "broken", "ghost", other]), hostile.migrants())
        for t in threads:
            t.start()
        for t in threads:
            t.join(60)
        return nodes

    reference, fuzzed = run(False), run(True)
    assert sum(n.stats["rejected"] for n in fuzzed.values()) == ISLAND_MESSAGES
    for i in "ab":
        assert [r[:3] for r in fuzzed[i].rows] == [r[:3] for r in reference[i].rows]  # all but wall time
        assert fuzzed[i].stats["received"] == reference[i].stats["received"] and fuzzed[i].stats["taken"] == reference[i].stats["taken"]
