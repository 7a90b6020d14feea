"""The island node (island/node.py): migration by topology, local re-evaluation, history, Zenoh wiring."""

from __future__ import annotations

import queue
import threading
import time

import numpy as np
import pytest
import zenoh

from coordinator.launch import free_port
from hysid_model.errors import HysidInputError
from hysid_model.synth import TRUE_PARAMS, synth_loops
from island.config import CampaignConfig, decode_config, encode_config
from island.migration import Migration
from island.node import IslandNode, MemoryBus, ZenohTransport, fetch_config
from island.protocol import Migrants, decode_history, encode_migrants, encode_stop
from island.session import open_session, session_config

LOOPS = synth_loops(n_points=30)
SIZES = {"ga": {"population": 20, "initial_population": 40, "iterations": 12}, "pso": {"population": 20, "initial_population": 40, "iterations": 12}}


def config(topology: str = "ring", interval: int = 2, k: int = 2, name: str = "c1") -> CampaignConfig:
    return CampaignConfig(name=name, options=SIZES, migration=Migration(interval=interval, k=k, topology=topology), seed=3)


def run_bus(cfg: CampaignConfig, islands: list[tuple[str, str, int]], forger=None) -> tuple[dict[str, IslandNode], list[tuple[str, bytes]]]:
    """Islands (id, algo, seed) as threads on one MemoryBus; ``forger(bus)`` may post as an extra island."""
    delivered: list[tuple[str, bytes]] = []
    stop = threading.Event()
    ids = [i for i, _, _ in islands] + (["forger"] if forger else [])
    bus = MemoryBus(cfg.name, ids, lambda key, data: delivered.append((key, data)), stop)
    nodes = {i: IslandNode(i, algo, seed, cfg, cfg.objective(LOOPS), history_every_s=0.0) for i, algo, seed in islands}

    def work(node: IslandNode) -> None:
        transport = bus.transport(node.island)
        try:
            node.run(transport)
        finally:
            transport.close()

    threads = [threading.Thread(target=work, args=(n,)) for n in nodes.values()]
    if forger:
        threads.append(threading.Thread(target=lambda: (forger(bus), bus.leave("forger"))))
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
    histories = [decode_history(d, "c1", first["a"].objective.bounds) for k, d in delivered if "/history/" in k]
    assert {h.island for h in histories} == {"a", "b", "c"}
    assert sum(h.final for h in histories) == 3
    # 12 iterations, migration every 2 -> epochs at 2, 4, ..., 10 (not after the last): 5 per island
    assert all(first[i].stats["sent"] == 5 for i in "abc")
    assert sum("/migrants/" in k for k, _ in delivered) == 15


def test_ring_takes_only_from_the_predecessor_and_full_from_everyone():
    islands = [("a", "ga", 1), ("b", "ga", 2), ("c", "ga", 3)]
    ring, _ = run_bus(config("ring", k=2), islands)
    full, _ = run_bus(config("full", k=2), islands)
    assert [ring[i].stats["received"] for i in "abc"] == [10, 10, 10]  # 5 epochs x 2 migrants from one neighbour
    assert [full[i].stats["received"] for i in "abc"] == [20, 20, 20]
    isolated, _ = run_bus(config(interval=0), islands)
    assert all(isolated[i].stats["sent"] == isolated[i].stats["received"] == 0 for i in "abc")


def forger_posting(payload_for_epoch):
    def forger(bus: MemoryBus) -> None:
        for epoch in range(1, 6):
            bus.exchange("forger", epoch, payload_for_epoch(epoch))
    return forger


def forged(x: np.ndarray, claimed: float, epoch: int) -> bytes:
    return encode_migrants(Migrants("c1", "forger", "f", 2 * epoch, np.atleast_2d(x), np.array([claimed]), 0.0))


def test_a_forged_migrant_claiming_fitness_zero_is_re_evaluated_and_refused():
    cfg = config("full", k=1)
    bad = cfg.objective(LOOPS).bounds[:, 1]  # a corner of the search space: a terrible fit
    nodes, _ = run_bus(cfg, [("a", "ga", 1)], forger=forger_posting(lambda e: forged(bad, 0.0, e)))
    a = nodes["a"]
    assert a.stats["received"] == 5 and a.stats["taken"] == 0
    x, f = a.optimizer.best(1)
    assert f[0] > 1e-3 and not np.allclose(x[0], bad)
    assert a.objective(x)[0] == pytest.approx(f[0])


def test_a_migrant_that_is_really_good_enters_with_its_own_fitness_not_the_claim():
    cfg = config("full", k=1)
    objective = cfg.objective(LOOPS)
    truth = objective.model.from_dict(TRUE_PARAMS)
    nodes, _ = run_bus(cfg, [("a", "pso", 1)], forger=forger_posting(lambda e: forged(truth, 1e9, e)))
    x, f = nodes["a"].optimizer.best(1)
    np.testing.assert_allclose(x[0], truth)
    assert f[0] == objective(truth)[0] < 1e-20


def test_malformed_migrants_are_counted_and_skipped():
    junk = [b"not msgpack \xc1", encode_stop("c1", "stop"), forged(np.array([np.nan, 0, 200, 0]), 0.0, 1), b"\x00" * 300_000]
    nodes, _ = run_bus(config("full"), [("a", "ga", 1)], forger=forger_posting(lambda e: junk[(e - 1) % len(junk)]))
    assert nodes["a"].stats["rejected"] == 5 and nodes["a"].stats["received"] == 0
    assert len(nodes["a"].rows) == 13


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
            fetch_config(client, "c1", 0.5)
    finally:
        client.close()


def test_zenoh_island_fetches_config_reports_history_backfills_and_stops(router):
    endpoint, rsession = router
    cfg = CampaignConfig(name="c1", options={"pso": {"population": 10, "initial_population": 10, "iterations": 100_000}}, migration=Migration(interval=0))
    arrived: queue.Queue = queue.Queue()
    members: list[tuple[str, bool]] = []
    config_message = encode_config(cfg, LOOPS)
    entities = [
        rsession.declare_queryable("hysid/c1/config", lambda q: q.reply(q.key_expr, config_message)),
        rsession.declare_subscriber("hysid/c1/history/*", lambda s: arrived.put(s.payload.to_bytes())),
        rsession.liveliness().declare_subscriber("hysid/c1/members/*", lambda s: members.append((str(s.key_expr), s.kind == zenoh.SampleKind.PUT))),
    ]
    client = open_session(session_config("client", connect=[endpoint]), endpoint)
    _, loops = decode_config(fetch_config(client, "c1", 5.0), "c1")
    node = IslandNode("pso-9", "pso", 5, cfg, cfg.objective(loops), history_every_s=0.05)
    transport = ZenohTransport(client, node)
    worker = threading.Thread(target=lambda: (node.run(transport), transport.close()))
    worker.start()
    try:
        first = decode_history(arrived.get(timeout=20), "c1", node.objective.bounds)
        assert first.island == "pso-9" and first.rows[0, 0] == 0
        deadline = time.monotonic() + 20
        while len(node.rows) < 30 and time.monotonic() < deadline:
            time.sleep(0.05)
        replies = [r.ok.payload.to_bytes() for r in rsession.get(f"hysid/c1/history/pso-9?run={node.run_id};since=20", timeout=5)]
        backfill = decode_history(replies[0], "c1", node.objective.bounds)
        assert backfill.rows[0, 0] == 21 and np.all(np.diff(backfill.rows[:, 0]) == 1)
        rsession.put("hysid/c1/control", encode_stop("c1", "enough"))
        worker.join(20)
        assert not worker.is_alive() and node.stop_reason == "stopped by the coordinator"
        last = None
        while last is None or not last.final:  # the goodbye may still be on its way
            last = decode_history(arrived.get(timeout=10), "c1", node.objective.bounds)
        assert last.rows[-1, 0] == node.rows[-1][0]
        deadline = time.monotonic() + 5
        while ("hysid/c1/members/pso-9", False) not in members and time.monotonic() < deadline:
            time.sleep(0.05)
        assert members[0] == ("hysid/c1/members/pso-9", True) and members[-1] == ("hysid/c1/members/pso-9", False)
    finally:
        for e in entities:
            e.undeclare()
        client.close()


def test_migrants_sent_before_the_senders_token_arrives_wait_for_it_and_strangers_are_never_taken(router):
    """Zenoh does not order a joiner's liveliness token before its first puts (the race CI once hit)."""
    endpoint, rsession = router
    cfg = CampaignConfig(name="c1", options={"pso": {"population": 10, "initial_population": 10, "iterations": 100_000}},
                         migration=Migration(interval=1, k=1, topology="full"))
    config_message = encode_config(cfg, LOOPS)
    queryable = rsession.declare_queryable("hysid/c1/config", lambda q: q.reply(q.key_expr, config_message))
    client = open_session(session_config("client", connect=[endpoint]), endpoint)
    _, loops = decode_config(fetch_config(client, "c1", 5.0), "c1")
    node = IslandNode("pso-1", "pso", 5, cfg, cfg.objective(loops), history_every_s=0.05)
    truth = node.objective.model.from_dict(TRUE_PARAMS)
    transport = ZenohTransport(client, node)
    worker = threading.Thread(target=lambda: (node.run(transport), transport.close()))
    worker.start()
    sender = open_session(session_config("client", connect=[endpoint]), endpoint)
    token = None
    try:
        while len(node.rows) < 5:
            time.sleep(0.01)
        stranger = encode_migrants(Migrants("c1", "stranger", "s", 1, truth[None, :], np.array([0.0]), 0.0))
        sender.put("hysid/c1/migrants/stranger", stranger)  # never becomes a member
        late = encode_migrants(Migrants("c1", "late", "l", 1, truth[None, :], np.array([0.0]), 0.0))
        sender.put("hysid/c1/migrants/late", late)
        rows = len(node.rows)
        while len(node.rows) < rows + 20:  # several epochs pass before the token is declared
            time.sleep(0.01)
        assert node.stats["received"] == 0
        token = sender.liveliness().declare_token("hysid/c1/members/late")
        deadline = time.monotonic() + 10
        while node.stats["received"] == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert node.stats["received"] == 1 and node.stats["taken"] == 1
        assert node.optimizer.best(1)[1][0] == node.objective(truth[None, :])[0]
    finally:
        if token is not None:
            token.undeclare()
        rsession.put("hysid/c1/control", encode_stop("c1", "enough"))
        worker.join(20)
        queryable.undeclare()
        sender.close()
        client.close()
    assert node.stats["received"] == 1  # the stranger's migrant expired unused
