"""Replay windows that one message cannot poison (island/sealing.py's ReplayGuard, the coordinator's and the islands'
checks): a message validly signed with a run's own key (stolen, used from another process) but numbered 2**63-1 is
refused as ``ahead`` and counted, the run's window stays where it was, and replays of its real messages are refused;
the victim's history and intake go on intact."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from coordinator.loop import pump
from island.island_messages import History, Migrants, encode_history, encode_migrants
from island.node import IslandNode
from island.sealing import ReplayGuard
from island.session import open_session, session_config
from island.transports import ZenohTransport
from support import query, wait_for
from test_coordinator import STATS, history, link, make, truth  # noqa: F401  (link: the fixture)
from test_host import LOOPS, Campaign, config

KEY = ("history", "victim", "r1")


def test_a_number_further_ahead_than_its_run_can_have_numbered_is_refused_and_the_window_stays():
    guard = ReplayGuard(window=64, rate=100.0, burst=8)
    assert [guard.check(KEY, s, now=0.0) for s in range(5)] == ["fresh"] * 5
    assert guard.check(KEY, 2**63 - 1, now=0.0) == "ahead"  # one validly signed message cannot move the window
    assert guard.check(KEY, 5, now=0.0) == "fresh" and guard.check(KEY, 3, now=0.0) == "replay" and guard.high(KEY) == 5
    assert guard.check(KEY, 5 + 4, now=0.0) == "ahead"  # more than what is left of the burst (8, less the 5 steps taken)
    assert guard.check(KEY, 5 + 3, now=0.0) == "fresh"  # the burst, spent
    assert guard.check(KEY, 8 + 5, now=0.0) == "ahead" and guard.check(KEY, 8 + 5, now=0.05) == "fresh"  # 100 a second refill it
    assert guard.check(KEY, 6, now=0.05) == "fresh"  # a late one inside the window still counts
    assert guard.check(("history", "b", "r"), 2**63 - 1, known=(-1, 10.0)) == "ahead"  # a first message, 10 s after the run joined
    assert guard.check(("history", "b", "r"), 900, known=(-1, 10.0)) == "fresh"
    assert guard.check(("history", "c", "r"), 2**63 - 1) == "fresh"  # nothing known of the run: its first number is taken as it comes


def test_the_coordinator_refuses_a_stolen_keys_message_numbered_2_63_and_its_replays_and_keeps_the_victims_history(tmp_path, link):
    """A second process with the victim's run key sends a history numbered 2**63-1 (claiming a plausible row), then
    replays 200 of the victim's messages: the first is refused as ahead, the replays as replays, and every later
    row of the victim is stored; the victim stays alive."""
    c = make(tmp_path, iterations=10**6)
    victim = c.join("victim", "pso", 1)
    x = truth(c)
    f = float(c.objective(x[None, :])[0])
    sent = []
    for seq in range(200):
        sent.append(history(victim, [[seq, f, 20 + 25 * seq, 0.0]], x, f, seq=seq))
        assert c.receive("hysid/c1/history/victim", sent[-1])
    pump(c, link, 5.0)
    assert c.store.count("history", "c1") == 200
    assert c.receive("hysid/c1/history/victim", history(victim, [[200, f, 20 + 25 * 200, 0.0]], x, f, seq=2**63 - 1))
    for message in sent:
        assert c.receive("hysid/c1/history/victim", message)
    for seq in range(200, 220):
        assert c.receive("hysid/c1/history/victim", history(victim, [[seq, f, 20 + 25 * seq, 0.0]], x, f, seq=seq))
    pump(c, link, 5.0)
    assert c.store.rejected_reasons("c1") == {"ahead": 1, "replay": 200}
    assert [r[2] for r in c.store.history("c1")] == list(range(220)) and c.members["victim"].status == "alive"
    assert c.last_seq("victim", victim.run) == 219


@pytest.mark.slow
def test_a_stolen_run_key_numbering_2_63_cannot_take_a_victims_history_or_migrants_away(tmp_path):
    """Over Zenoh on loopback: two islands search, a third party holding the victim's run key (from another session)
    publishes a history and a migrant message numbered 2**63-1 under the victim's name and key, then replays 200 of
    the victim's real messages: the coordinator refuses and counts each, stores every row the victim sends, never
    finds it lost, and the other island goes on taking the victim's migrants (its window did not move either)."""
    cfg = config("rp", interval=2, min_islands=2, iterations=10**6)
    campaign = Campaign(tmp_path, cfg)
    db = tmp_path / "rp.sqlite"
    captured: list[tuple[str, bytes]] = []
    thief = open_session(session_config("client", connect=[campaign.endpoint]), campaign.endpoint)  # another process' session, as it were
    spies = [
        thief.declare_subscriber(f"hysid/rp/{kind}/victim", lambda s, kind=kind: captured.append((kind, s.payload.to_bytes())))
        for kind in ("history", "migrants")
    ]
    nodes = [IslandNode(name, "pso", seed, cfg, cfg.objective(LOOPS), history_every_s=0.05) for name, seed in (("victim", 1), ("other", 2))]
    transports: list[ZenohTransport] = []
    ready = threading.Barrier(3)

    def island(node: IslandNode) -> None:
        transport = ZenohTransport(campaign.client, node, campaign.c.secret, wait_s=20.0)
        transports.append(transport)
        ready.wait()
        try:
            node.run(transport)
        finally:
            transport.close()

    threads = [threading.Thread(target=island, args=(node,)) for node in nodes]
    for t in threads:
        t.start()
    try:
        ready.wait(30)
        victim, other = nodes
        wait_for(
            lambda: victim.stats["sent"] > 5 and other.stats["received"] > 5 and sum(k == "migrants" for k, _ in captured) > 20, 60, "the islands to migrate"
        )
        replays = captured[:200]  # the victim's own, before the thief publishes (its own messages come back to its subscribers)
        stolen = victim.credentials
        x, f = victim._snapshot
        thief.put(
            "hysid/rp/history/victim", encode_history(History("rp", "victim", stolen.run, "pso", 1, np.zeros((0, 4)), x, f, STATS, seq=2**63 - 1), stolen)
        )
        thief.put("hysid/rp/migrants/victim", encode_migrants(Migrants("rp", "victim", stolen.run, 2, x[None, :], np.zeros(1), time.time(), 2**63 - 1), stolen))
        for kind, payload in replays:
            thief.put(f"hysid/rp/{kind}/victim", payload)
        histories = sum(kind == "history" for kind, _ in replays)  # (a replayed migrant message may be superseded in the inbox instead)
        reasons = lambda: dict(query(db, "SELECT reason, sum(n) FROM rejected GROUP BY reason"))
        wait_for(lambda: reasons().get("replay", 0) >= histories, 60, "the coordinator to refuse the replays")
        assert reasons()["ahead"] == 2
        received, rows = other.stats["received"], victim.rows[-1][0]
        wait_for(lambda: other.stats["received"] > received + 10 and victim.rows[-1][0] > rows + 50, 60, "both islands to go on")
    finally:
        campaign._done.set()
        for t in threads:
            t.join(60)
        for spy in spies:
            spy.undeclare()
        thief.close()
        campaign.end()
    stored = [it for (it,) in query(db, "SELECT iteration FROM history WHERE island = 'victim' ORDER BY iteration")]
    assert stored == list(range(len(victim.rows)))  # every row of the victim, before and after
    assert [e for (e,) in query(db, "SELECT event FROM members WHERE island = 'victim' ORDER BY id")] == ["join", "left"]
    assert other.stats["rejected"] >= 1 and other.stats["unlisted"] == 0  # the ahead migrant message (and replays it heard)
