"""The island node (island/node.py): migration by topology, local re-evaluation, history, Zenoh wiring."""

from __future__ import annotations

import queue
import threading
import time
from dataclasses import replace

import numpy as np
import pytest
import zenoh

from coordinator.histories import check_claim
from coordinator.launch import free_port
from hysid_model.errors import HysidInputError
from hysid_model.synth import TRUE_PARAMS, synth_loops
from island.config import CampaignConfig, decode_config, encode_config
from island.coordinator_messages import Best, Control, HistoryQuery, MemberState, encode_best, encode_control, encode_history_query
from island.ga import GA
from island.handshake import JoinRequest, decode_join_step, encode_challenge, encode_joined, proof_holds
from island.island_messages import Migrants, decode_history, decode_migrants, encode_migrants
from island.joining import fetch_config
from island.memetic import Island
from island.memory import MemoryBus
from island.migration import Migration
from island.node import HISTORY_MESSAGES_PER_S, HISTORY_PERIOD_MAX_S, IslandNode, history_period
from island.protocol import encode_signed_config
from island.pso import PSO
from island.sealing import Credentials, new_key, public_key
from island.secret import CampaignSecret
from island.session import open_session, session_config
from island.transports import ZenohTransport
from support import wait_for

LOOPS = synth_loops(n_points=30)
SIZES = {"ga": {"population": 20, "initial_population": 40, "iterations": 12}, "pso": {"population": 20, "initial_population": 40, "iterations": 12}}


def config(topology: str = "ring", interval: int = 2, k: int = 2, name: str = "c1") -> CampaignConfig:
    return CampaignConfig(name=name, options=SIZES, migration=Migration(interval=interval, k=k, topology=topology), seed=3)


def run_bus(cfg: CampaignConfig, islands: list[tuple[str, str, int]], forger=None, loops=LOOPS) -> tuple[dict[str, IslandNode], list[tuple[str, bytes]]]:
    """Islands (id, algo, seed) as threads on one MemoryBus; ``forger(bus)`` may post as an extra island."""
    delivered: list[tuple[str, bytes]] = []
    stop = threading.Event()
    ids = [i for i, _, _ in islands] + (["forger"] if forger else [])
    bus = MemoryBus(cfg.name, ids, lambda key, data: delivered.append((key, data)), stop)
    nodes = {i: IslandNode(i, algo, seed, cfg, cfg.objective(loops), history_every_s=0.0) for i, algo, seed in islands}

    def work(node: IslandNode) -> None:
        transport = bus.transport(node.island)
        try:
            node.run(transport)
        finally:
            transport.close()

    threads = [threading.Thread(target=work, args=(n,)) for n in nodes.values()]
    if forger:
        credentials = bus.transport("forger", "ga", 0).credentials  # a joined island that misbehaves
        threads.append(threading.Thread(target=lambda: (forger(bus, credentials), bus.leave("forger"))))
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert not any(t.is_alive() for t in threads)
    return nodes, delivered


def test_memory_islands_are_reproducible_and_report_every_iteration():
    islands = [("a", "ga", 1), ("b", "pso", 2), ("c", "ga", 3)]
    first, delivered = run_bus(config(), islands)
    second, _ = run_bus(config(), islands)
    for i in "abc":
        assert [r[:3] for r in first[i].rows] == [r[:3] for r in second[i].rows]  # all but wall time
        assert first[i].stats == second[i].stats
        assert [r[0] for r in first[i].rows] == list(range(13))
    keys = {(n.island, n.run_id): n.credentials.public for n in first.values()}
    histories = [decode_history(d, "c1", first["a"].objective.bounds, key_for=lambda s, r: keys.get((s, r))) for k, d in delivered if "/history/" in k]
    assert {h.island for h in histories} == {"a", "b", "c"}
    assert sum(h.final for h in histories) == 3
    # 12 iterations, migration every 2 -> epochs at 2, 4, ..., 10 (not after the last): 5 per island
    assert all(first[i].stats["sent"] == 5 for i in "abc")
    assert sum("/migrants/" in k for k, _ in delivered) == 15


MEMORY_LOOPS = synth_loops(noise_pct=1.0, n_points=16).subset(np.arange(0, 120, 12))
MEMETIC = {"population": 8, "initial_population": 16, "addpop_level": 1, "iterations": 40}


def memory_config() -> CampaignConfig:
    """A memory model on noisy loops, searched from scratch (no ``start``)."""
    cfg = CampaignConfig.create(
        MEMORY_LOOPS,
        name="c1",
        model="thesis+bouc_wen",
        options={"ga": MEMETIC, "pso": {**MEMETIC, "synchronous": True}},
        migration=Migration(interval=3, k=2),
        seed=3,
    )
    return replace(cfg, start=None)


def test_memory_model_islands_are_memetic_and_everything_they_send_is_in_the_model_s_parameters():
    islands = [("a", "pso", 1), ("b", "ga", 2)]
    nodes, delivered = run_bus(memory_config(), islands, loops=MEMORY_LOOPS)
    again, _ = run_bus(memory_config(), islands, loops=MEMORY_LOOPS)
    objective = nodes["a"].objective
    keys = {(n.island, n.run_id): n.credentials.public for n in nodes.values()}
    assert all(isinstance(n.optimizer, Island) for n in nodes.values()) and sum(n.optimizer.restarts for n in nodes.values()) >= 1
    for i in "ab":
        rows = np.array(nodes[i].rows)
        assert list(rows[:, 0]) == list(range(41)) and np.all(np.diff(rows[:, 2]) > 0) and np.all(np.diff(rows[:, 1]) <= 0)  # restarts included
        assert [r[:3] for r in nodes[i].rows] == [r[:3] for r in again[i].rows]
    for key, data in delivered:
        if "/history/" in key:
            h = decode_history(data, "c1", objective.bounds, key_for=lambda s, r: keys.get((s, r)))
            check_claim(h, float(objective(h.best_x[None, :])[0]))  # the coordinator's check: its best is a vector of the model's
        else:
            m = decode_migrants(data, "c1", objective.bounds, key_for=lambda s, r: keys.get((s, r)))
            np.testing.assert_allclose(m.claimed, objective(m.x), rtol=1e-12)
    memoryless = config()
    assert isinstance(IslandNode("a", "pso", 0, memoryless, memoryless.objective(LOOPS)).optimizer, PSO)


def test_a_stalled_memetic_island_keeps_searching_only_while_it_holds_the_best_it_hears_of():
    cfg = memory_config()
    bus = MemoryBus("c1", ["a", "b"], lambda key, data: None, threading.Event())
    node = IslandNode("a", "pso", 1, cfg, cfg.objective(MEMORY_LOOPS))
    node.attach(bus.transport("a"))
    other = bus.transport("b").credentials
    island = node.optimizer
    assert isinstance(island, Island)
    island.step()
    x, f = island.best(1)
    theta = node._theta(x)
    worse = node.objective.bounds[:, 1][None, :]
    for seq, (vector, claimed, ahead, behind, evaluated) in enumerate(
        [
            (theta, f[0], True, False, 1),  # the same best: the member that joined first keeps it
            (worse, float(node.objective(worse)[0]), True, True, 1),
            (worse, 0.0, True, True, 0),  # a claim is re-evaluated, never believed; a point already checked is not evaluated again
        ],
        start=1,
    ):
        before = node.migrant_evaluations
        node.receive("b", encode_migrants(Migrants("c1", "b", other.run, 3, vector, np.array([claimed]), time.time(), seq), other))
        assert node._leads(island, ["a", "b"]) is ahead and node._leads(island, ["b", "a"]) is behind
        assert node.migrant_evaluations - before == evaluated


def test_ring_takes_only_from_the_predecessor_and_full_from_everyone():
    islands = [("a", "ga", 1), ("b", "ga", 2), ("c", "ga", 3)]
    ring, _ = run_bus(config("ring", k=2), islands)
    full, _ = run_bus(config("full", k=2), islands)
    assert [ring[i].stats["received"] for i in "abc"] == [10, 10, 10]  # 5 epochs x 2 migrants from one neighbour
    assert [full[i].stats["received"] for i in "abc"] == [20, 20, 20]
    isolated, _ = run_bus(config(interval=0), islands)
    assert all(isolated[i].stats["sent"] == isolated[i].stats["received"] == 0 for i in "abc")


def forger_posting(payload_for_epoch):
    def forger(bus: MemoryBus, credentials: Credentials) -> None:
        for epoch in range(1, 6):
            bus.exchange("forger", epoch, payload_for_epoch(epoch, credentials))

    return forger


def forged(x: np.ndarray, claimed: float, epoch: int, credentials: Credentials) -> bytes:
    m = Migrants("c1", "forger", credentials.run, 2 * epoch, np.atleast_2d(x), np.array([claimed]), time.time(), seq=epoch)
    return encode_migrants(m, credentials)


def test_a_forged_migrant_claiming_fitness_zero_is_re_evaluated_and_refused():
    cfg = config("full", k=1)
    bad = cfg.objective(LOOPS).bounds[:, 1]  # a corner of the search space: a terrible fit
    nodes, _ = run_bus(cfg, [("a", "ga", 1)], forger=forger_posting(lambda e, c: forged(bad, 0.0, e, c)))
    a = nodes["a"]
    assert a.stats["received"] == 5 and a.stats["taken"] == 0
    x, f = a.optimizer.best(1)
    assert f[0] > 1e-3 and not np.allclose(x[0], bad)
    assert a.objective(x)[0] == pytest.approx(f[0])


def test_a_migrant_that_is_really_good_enters_with_its_own_fitness_not_the_claim():
    cfg = config("full", k=1)
    objective = cfg.objective(LOOPS)
    truth = objective.model.from_dict(TRUE_PARAMS)
    nodes, _ = run_bus(cfg, [("a", "pso", 1)], forger=forger_posting(lambda e, c: forged(truth, 1e9, e, c)))
    x, f = nodes["a"].optimizer.best(1)
    np.testing.assert_allclose(x[0], truth)
    assert f[0] == objective(truth)[0] < 1e-20


def test_malformed_migrants_are_counted_and_skipped():
    def junk(epoch: int, credentials: Credentials) -> bytes:
        stranger = Credentials("forger", credentials.run, new_key(), credentials.coordinator)  # the forger's name and run, not its key
        return [
            b"not msgpack \xc1",
            encode_best(Best("c1", "forger", np.zeros(4), 0.0), "x", credentials.key),
            forged(np.array([np.nan, 0, 200, 0]), 0.0, 1, credentials),
            b"\x00" * 300_000,
            forged(np.array([0.01, 0, 200, 0]), 0.0, 5, stranger),
        ][(epoch - 1) % 5]

    nodes, _ = run_bus(config("full"), [("a", "ga", 1)], forger=forger_posting(junk))
    assert nodes["a"].stats["rejected"] == 5 and nodes["a"].stats["received"] == 0
    assert len(nodes["a"].rows) == 13


def test_a_replayed_migrant_message_is_rejected_and_never_taken_twice():
    truth_of = lambda cfg: cfg.objective(LOOPS).model.from_dict(TRUE_PARAMS)
    cfg = config("full", k=1)
    first: dict[str, bytes] = {}

    def replaying(epoch: int, credentials: Credentials) -> bytes:
        first.setdefault("m", forged(truth_of(cfg), 0.0, 1, credentials))
        return first["m"]  # the same sealed message at every epoch

    nodes, _ = run_bus(cfg, [("a", "pso", 1)], forger=forger_posting(replaying))
    assert nodes["a"].stats["received"] == 1 and nodes["a"].stats["rejected"] == 4


def test_a_node_used_before_it_joined_raises_also_without_asserts():
    """Runtime checks raise (``python -O`` drops asserts): a node without a transport says so, it does not fail further in."""
    cfg = config()
    node = IslandNode("a", "ga", 0, cfg, cfg.objective(LOOPS))
    for use in (node.heartbeat, node.history_messages, lambda: node.receive("b", b"x"), lambda: node._flush(final=True)):
        with pytest.raises(RuntimeError, match="island 'a' has not joined: attach a transport"):
            use()


def test_an_unknown_algorithm_or_bad_island_name_is_an_input_error():
    cfg = config()
    with pytest.raises(HysidInputError, match="algo='de'"):
        IslandNode("a", "de", 0, cfg, cfg.objective(LOOPS))
    with pytest.raises(HysidInputError, match="island='a/b'"):
        IslandNode("a/b", "ga", 0, cfg, cfg.objective(LOOPS))


# --- real Zenoh on loopback ----------------------------------------------------------
@pytest.fixture
def router():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = open_session(session_config("router", listen=[endpoint]), endpoint)
    yield endpoint, session
    session.close()


def test_fetch_config_names_the_campaign_when_nobody_answers(router):
    endpoint, _ = router
    client = open_session(session_config("client", connect=[endpoint]), endpoint)
    try:
        with pytest.raises(HysidInputError, match=r"no coordinator answered on hysid/c1/config within 0.5 s"):
            fetch_config(client, CampaignSecret.create("c1", public_key(new_key())), 0.5)
    finally:
        client.close()


class Admissions:
    """The coordinator's side of the wire protocol, by hand (so that each step can be watched): serves
    the signed ``config``, answers the join handshake (challenge, then the run for a proof that holds),
    publishes signed ``control`` and history queries."""

    def __init__(self, session: zenoh.Session, cfg: CampaignConfig) -> None:
        self.session, self.campaign = session, cfg.name
        self.key = new_key()
        self.secret = CampaignSecret.create(cfg.name, public_key(self.key))
        self.issued: dict[str, Credentials] = {}
        """island -> its run and (public) key"""
        self.algos: dict[str, str] = {}
        self.seq = 0
        message = encode_signed_config(encode_config(cfg, LOOPS), cfg.name, "test", self.key)
        self.entities = [
            session.declare_queryable(f"hysid/{cfg.name}/config", lambda q: q.reply(q.key_expr, message)),
            session.declare_queryable(f"hysid/{cfg.name}/join/*", self._on_join),
        ]

    def _on_join(self, query: zenoh.Query) -> None:
        step = decode_join_step(query.payload.to_bytes(), self.campaign)
        if isinstance(step, JoinRequest):
            query.reply(query.key_expr, encode_challenge(self.campaign, step.island, step.nonce, b"c" * 16, "test", self.key))
            return
        assert proof_holds(step, self.secret.admission) and step.challenge == b"c" * 16
        r = step.request
        self.issued[r.island] = Credentials(r.island, f"run-{r.island}", r.key, self.secret.coordinator)  # key: the run's public key
        self.algos[r.island] = r.algo
        query.reply(query.key_expr, encode_joined(self.campaign, r.nonce, r.island, f"run-{r.island}", "test", self.key))

    def key_for(self, island: str, run: str) -> bytes | None:
        c = self.issued.get(island)
        return c.key if c is not None and c.run == run else None

    def control(self, stored: dict[str, int] | None = None, stop: str = "", key: bytes | None = None, algos: dict[str, str] | None = None) -> bytes:
        """A roster of every island issued credentials (all alive, running the algorithm it joined with
        unless ``algos`` says otherwise), ``stored`` rows confirmed; signed with ``key`` (the coordinator's by default)."""
        self.seq += 1
        algo = {**self.algos, **(algos or {})}
        members = tuple(MemberState(i, c.run, True, (stored or {}).get(i, -1), algo.get(i, "pso"), c.key) for i, c in self.issued.items())
        return encode_control(Control(self.campaign, members, stop, self.seq), "test", key or self.key)

    def history_query(self, island: str, since: int, run: str | None = None) -> str:
        self.seq += 1
        return f"hysid/{self.campaign}/history/{island}?" + encode_history_query(
            HistoryQuery(self.campaign, island, run or self.issued[island].run, since, self.seq), self.key
        )

    def close(self) -> None:
        for e in self.entities:
            e.undeclare()


def endless(interval: int = 0, k: int = 1, topology: str = "ring") -> CampaignConfig:
    return CampaignConfig(
        name="c1",
        options={"pso": {"population": 10, "initial_population": 10, "iterations": 100_000}},
        migration=Migration(interval=interval, k=k, topology=topology),
    )


def start_island(endpoint: str, cfg: CampaignConfig, secret: CampaignSecret, island: str = "pso-9", wait_s: float = 10.0):
    client = open_session(session_config("client", connect=[endpoint]), endpoint)
    _, loops = decode_config(fetch_config(client, secret, 5.0), "c1")
    node = IslandNode(island, "pso", 5, cfg, cfg.objective(loops), history_every_s=0.05)
    transport = ZenohTransport(client, node, secret, wait_s)
    worker = threading.Thread(target=lambda: (node.run(transport), transport.close()))
    worker.start()
    return client, node, worker


def test_zenoh_island_joins_reports_history_backfills_stops_and_leaves_once_confirmed(router):
    endpoint, rsession = router
    cfg = endless()
    coordinator = Admissions(rsession, cfg)
    arrived: queue.Queue = queue.Queue()
    members: list[tuple[str, bool]] = []
    entities = [
        rsession.declare_subscriber("hysid/c1/history/*", lambda s: arrived.put(s.payload.to_bytes())),
        rsession.liveliness().declare_subscriber("hysid/c1/members/*", lambda s: members.append((str(s.key_expr), s.kind == zenoh.SampleKind.PUT))),
    ]
    client, node, worker = start_island(endpoint, cfg, coordinator.secret)
    decode = lambda data: decode_history(data, "c1", node.objective.bounds, key_for=coordinator.key_for)
    try:
        first = decode(arrived.get(timeout=20))
        assert first.island == "pso-9" and first.rows[0, 0] == 0 and first.run == coordinator.issued["pso-9"].run
        wait_for(lambda: len(node.rows) >= 30, 20, "30 iterations")
        query = coordinator.history_query("pso-9", 20)
        replies = [r.ok.payload.to_bytes() for r in rsession.get(query, timeout=5)]
        backfill = decode(replies[0])
        assert backfill.rows[0, 0] == 21 and np.all(np.diff(backfill.rows[:, 0]) == 1)
        assert [r for r in rsession.get(query, timeout=2) if r.ok is not None] == []  # the same query again: a replay, unanswered
        assert node.stats["rejected"] == 1
        rsession.put("hysid/c1/control", coordinator.control(stop="enough"))
        last = None
        while last is None or not last.final:  # the goodbye may still be on its way
            last = decode(arrived.get(timeout=10))
        assert last.rows[-1, 0] == node.rows[-1][0] and node.stop_reason == "stopped by the coordinator"
        # it waits for the confirmation, serving what the coordinator asks: its goodbye again, its token still there
        waiting = [
            decode(r.ok.payload.to_bytes()) for r in rsession.get(coordinator.history_query("pso-9", int(last.rows[-1, 0]) - 1), timeout=5) if r.ok is not None
        ]
        assert [(h.final, h.rows[-1, 0]) for h in waiting] == [(True, last.rows[-1, 0])]
        assert node.confirmed is None and worker.is_alive() and members[-1] == ("hysid/c1/members/pso-9", True)
        rsession.put("hysid/c1/control", coordinator.control(stored={"pso-9": int(last.rows[-1, 0])}, stop="enough"))
        worker.join(20)
        assert not worker.is_alive() and node.confirmed is True
        wait_for(lambda: ("hysid/c1/members/pso-9", False) in members, 5, "the token to go")
        assert members[0] == ("hysid/c1/members/pso-9", True) and members[-1] == ("hysid/c1/members/pso-9", False)
    finally:
        for e in entities:
            e.undeclare()
        coordinator.close()
        client.close()


def test_zenoh_island_moved_to_another_algorithm_by_the_roster_carries_its_search_on(router):
    endpoint, rsession = router
    cfg = replace(endless(), algos=["ga", "pso"], options={a: {"population": 10, "initial_population": 10, "iterations": 100_000} for a in ("ga", "pso")})
    coordinator = Admissions(rsession, cfg)
    arrived: queue.Queue = queue.Queue()
    sub = rsession.declare_subscriber("hysid/c1/history/*", lambda s: arrived.put(s.payload.to_bytes()))
    client, node, worker = start_island(endpoint, cfg, coordinator.secret)
    decode = lambda data: decode_history(data, "c1", node.objective.bounds, key_for=coordinator.key_for)
    try:
        assert decode(arrived.get(timeout=20)).algo == "pso"
        rsession.put("hysid/c1/control", coordinator.control(algos={"pso-9": "ga"}))
        h = decode(arrived.get(timeout=10))
        while h.algo == "pso":
            h = decode(arrived.get(timeout=10))
        assert h.algo == "ga" and node.moves and node.moves[0][1:] == ("pso", "ga") and isinstance(node.optimizer, GA)
        assert np.all(np.diff(h.rows[:, 0]) == 1)
    finally:
        rsession.put("hysid/c1/control", coordinator.control(stop="enough", algos={"pso-9": "ga"}, stored={"pso-9": 2**52}))
        worker.join(20)
        sub.undeclare()
        coordinator.close()
        client.close()
    assert not worker.is_alive() and [m[1:] for m in node.moves] == [("pso", "ga")]


def test_zenoh_island_ignores_forged_and_replayed_control_and_bad_history_queries(router):
    endpoint, rsession = router
    cfg = endless()
    coordinator = Admissions(rsession, cfg)
    client, node, worker = start_island(endpoint, cfg, coordinator.secret, wait_s=1.0)
    try:
        wait_for(lambda: len(node.rows) > 5, 20, "the island to run")
        genuine = coordinator.control()
        rsession.put("hysid/c1/control", genuine)
        forged_stop = coordinator.control(stop="forged", key=new_key())
        rsession.put("hysid/c1/control", forged_stop)
        rsession.put("hysid/c1/control", genuine)  # a replay
        for selector in ("since=abc", "since=99999999999999999999", "since=-5", "since=1e300", "run=x;since=" + "9" * 17):
            assert rsession.get(f"hysid/c1/history/pso-9?{selector}", timeout=2) is not None
        wait_for(lambda: node.stats["rejected"] >= 7, 10, "every bad control message and query to be counted")
        rows = len(node.rows)
        wait_for(lambda: len(node.rows) > rows + 20, 10, "the island to keep going")
        assert worker.is_alive() and not node.stop_reason
    finally:
        rsession.put("hysid/c1/control", coordinator.control(stop="enough"))
        worker.join(20)
        coordinator.close()
        client.close()
    assert node.stats["rejected"] == 7 and node.confirmed is False  # nobody confirmed its rows within 1 s


@pytest.mark.slow  # over 3 s (fast lane, 2 cores, 2026-11-29)
def test_migrants_wait_for_the_roster_strangers_are_never_taken_and_a_flood_is_capped(router):
    """Zenoh does not order the coordinator's roster before a joiner's first puts; a sender only the
    roster makes a member, and an epoch takes at most k migrants from each in-neighbour."""
    endpoint, rsession = router
    cfg = endless(interval=1, k=1, topology="full")
    coordinator = Admissions(rsession, cfg)
    client, node, worker = start_island(endpoint, cfg, coordinator.secret, "pso-1")
    truth = node.objective.model.from_dict(TRUE_PARAMS)
    sender = open_session(session_config("client", connect=[endpoint]), endpoint)
    late = Credentials.issue("late", coordinator.secret.coordinator)
    stranger = Credentials.issue("stranger", coordinator.secret.coordinator)  # never on the roster
    try:
        wait_for(lambda: len(node.rows) >= 5, 20, "the island to run")
        rsession.put("hysid/c1/control", coordinator.control())
        sender.put(
            "hysid/c1/migrants/stranger", encode_migrants(Migrants("c1", "stranger", stranger.run, 1, truth[None, :], np.array([0.0]), time.time()), stranger)
        )
        sender.put("hysid/c1/migrants/late", encode_migrants(Migrants("c1", "late", late.run, 1, truth[None, :], np.array([0.0]), time.time()), late))
        rows = len(node.rows)
        wait_for(lambda: len(node.rows) >= rows + 20, 20, "several epochs before the roster lists it")
        assert node.stats["received"] == 0
        coordinator.issued["late"] = Credentials("late", late.run, late.public, late.coordinator)
        rsession.put("hysid/c1/control", coordinator.control())
        wait_for(lambda: node.stats["received"] >= 1, 10, "the late joiner's migrant")
        assert node.stats["received"] == 1 and node.stats["taken"] == 1
        assert node.optimizer.best(1)[1][0] == node.objective(truth[None, :])[0]
        # a flood from the member: thousands of messages, but one per epoch is taken, k = 1 migrant each
        publisher = sender.declare_publisher("hysid/c1/migrants/late", congestion_control=zenoh.CongestionControl.BLOCK)
        first_row, evaluated = len(node.rows), node.migrant_evaluations
        for seq in range(1, 3001):
            publisher.put(encode_migrants(Migrants("c1", "late", late.run, seq, np.tile(truth, (2, 1)), np.zeros(2), time.time(), seq), late))
        epochs = len(node.rows) - first_row + 2
        assert node.migrant_evaluations - evaluated <= epochs  # at most one migrant per epoch from the one in-neighbour
        assert node.stats["rejected"] <= 1  # the stranger's message, once it waited JOIN_GRACE_S for a roster that never listed it
    finally:  # stop, and confirm every row so that the island leaves at once
        rsession.put("hysid/c1/control", coordinator.control(stored={"pso-1": 2**53}, stop="enough"))
        worker.join(20)
        coordinator.close()
        sender.close()
        client.close()
    assert node.stats["received"] <= len(node.rows) + 1  # the stranger's migrant expired unused


def test_islands_of_a_large_campaign_send_their_history_less_often_up_to_a_bound() -> None:
    assert history_period(0.25, 32) == 0.25 and history_period(0.05, 250) == 0.05  # up to 250 islands: as asked
    assert history_period(0.25, 500) == 500 / HISTORY_MESSAGES_PER_S  # together at most HISTORY_MESSAGES_PER_S messages a second
    assert history_period(0.05, 4096) == HISTORY_PERIOD_MAX_S  # never longer than a heartbeat's period
    assert history_period(2.0, 4096) == 2.0  # an island asked for fewer messages sends fewer
