"""No member outweighs the campaign (coordinator/admission.py, island/secret.py's member secrets): a join binds its run
to the member whose secret it proves; a member holds at most its share of the run slots; while more than one member is
alive a member's effort counts no further than the others' together, so that a budget is spent only with the effort of
more than one member. The attack: a holder of a member's secret with 16 runs, each claiming the most its run can
plausibly have done, against honest islands over Zenoh on loopback, with a late honest island joining after it.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from coordinator.loop import check_stop, pump
from hysid_model.errors import HysidInputError
from island.node import IslandNode
from island.handshake import JoinRequest, decode_joined
from island.protocol import encode_history, History
from island.secret import CampaignSecret, member_admission
from island.sealing import new_key, public_key
from island.session import open_session, session_config
from island.termination import Termination
from island.joining import join
from island.transports import ZenohTransport
from support import query, wait_for
from test_coordinator import STATS, handshake, history, link, make, reasons, truth  # noqa: F401  (link: the fixture)
from test_host import LOOPS, Campaign, config


def test_a_member_secret_admits_only_that_members_islands_and_its_runs_are_bound_to_it(tmp_path, link):
    c = make(tmp_path)
    theirs = c.secret.for_member("lab2")
    assert CampaignSecret.parse(theirs.text(), "x") == theirs and theirs.admission == member_admission(c.secret.admission, "lab2")
    with pytest.raises(HysidInputError, match="makes no other member's"):
        theirs.for_member("lab3")
    key = new_key()
    ok = JoinRequest("c1", "lab2-0", "pso", 1, b"a" * 16, public_key(key), "lab2")
    run = decode_joined(handshake(c, link, ok, key, admission=theirs.admission)[0], "c1", "lab2-0", ok.nonce, c.secret.coordinator)
    assert c.runs[("lab2-0", run)].member == "lab2" and c.store.runs("c1")[0][-1] == "lab2"
    other_id = JoinRequest("c1", "pso-7", "pso", 1, b"b" * 16, public_key(key), "lab2")  # not one of lab2's names
    other_member = JoinRequest("c1", "lab3-0", "pso", 1, b"c" * 16, public_key(key), "lab3")  # lab2's secret, lab3's join
    assert handshake(c, link, other_id, key, admission=theirs.admission) == []
    assert handshake(c, link, other_member, key, admission=theirs.admission) == []
    assert reasons(c) == {"sender": 1, "forged": 1} and len(c.runs) == 1
    own = JoinRequest("c1", "lab3-0", "pso", 1, b"d" * 16, public_key(key), "lab3")  # the campaign's secret joins for any member
    decode_joined(handshake(c, link, own, key, admission=c.secret.admission_for("lab3"))[0], "c1", "lab3-0", own.nonce, c.secret.coordinator)


def test_a_member_holds_at_most_its_share_of_the_run_slots(tmp_path, link, monkeypatch):
    monkeypatch.setattr("coordinator.admission.MEMBER_RUNS", 3)
    c = make(tmp_path)
    for k in range(3):
        c.join(f"m-{k}", "pso", k, member="m")
    with pytest.raises(HysidInputError, match="member 'm' holds 3 runs, its share of the campaign's 4,096"):
        c.join("m-3", "pso", 3, member="m")
    assert c.join("late", "pso", 9).run in {r for _, r in c.runs}  # another member still finds room


def test_a_members_effort_counts_no_further_than_the_others_while_they_are_alive(tmp_path, link, monkeypatch):
    """A member alone counts in full; once another is alive, of what each adds only as much as the others add counts:
    a budget the attacker's claims alone would spend is spent when the honest member has done half of it."""
    monkeypatch.setattr("coordinator.histories.SPEEDUP", 1e9)  # every claim here is plausible: what counts is at stake
    c = make(tmp_path, Termination(budget=1_000_000), iterations=10**6)
    x = truth(c)
    f = float(c.objective(x[None, :])[0])
    claim = lambda e: [[e // 10, f, e, 0.0]]  # noqa: E731  (iterations of a swarm of 10 that many evaluations take)
    honest = c.join("a", "pso", 1)
    c.receive("hysid/c1/history/a", history(honest, claim(100_000), x, f, seq=0))
    pump(c, link, 2.0)
    assert c.countable() == 100_000  # alone: in full
    thief = c.join("m-0", "pso", 2, member="m")
    c.receive("hysid/c1/history/m-0", history(thief, claim(5_000_000), x, f, seq=0, seed=2))
    pump(c, link, 2.0)
    assert c.evaluations == 5_100_000 and c.countable() == 100_000 and check_stop(c) is None  # claimed 5 budgets, counts nothing yet
    for seq, done in enumerate((300_000, 500_000), start=1):
        c.receive("hysid/c1/history/a", history(honest, claim(done), x, f, seq=seq))
        pump(c, link, 2.0)
    assert c.countable() == 100_000 + 2 * 400_000 and check_stop(c) is None  # the honest 400,000 since, and as much of the thief's
    c.receive("hysid/c1/history/a", history(honest, claim(550_000), x, f, seq=3))
    pump(c, link, 2.0)
    assert c.countable() == 1_000_000 and check_stop(c) == "budget of 1,000,000 evaluations spent"


@pytest.mark.slow
def test_a_member_with_16_runs_claiming_the_most_it_can_neither_ends_the_campaign_nor_keeps_a_late_island_out(tmp_path):
    """Two honest islands search (the campaign's own secret) toward a budget of 4 million evaluations; a holder of a
    member's secret joins 16 runs over Zenoh and sends histories claiming 95 % of the most each run can have done, as
    the coordinator measures it: the claims are taken as plausible (together many times the budget), yet the campaign
    does not stop, and a late honest island joins and reports."""
    cfg = config("mb", interval=2, min_islands=1, iterations=10**6)
    campaign = Campaign(tmp_path, cfg, Termination(budget=4_000_000))
    db = tmp_path / "mb.sqlite"
    c = campaign.c
    theirs = c.secret.for_member("mallory")
    thief = open_session(session_config("client", connect=[campaign.endpoint]), campaign.endpoint)
    nodes = [IslandNode(name, "pso", seed, cfg, cfg.objective(LOOPS), history_every_s=0.05) for name, seed in (("a", 1), ("b", 2), ("late", 3))]
    threads = [threading.Thread(target=lambda n=n: n.run(ZenohTransport(campaign.client, n, c.secret, wait_s=20.0))) for n in nodes]
    try:
        for t in threads[:2]:
            t.start()
        wait_for(lambda: all(n.rows for n in nodes[:2]), 60, "the honest islands to search")
        runs = [join(thief, "mb", f"mallory-{k}", "pso", 100 + k, theirs, 20.0) for k in range(16)]
        assert {c.runs[(r.island, r.run)].member for r in runs} == {"mallory"}
        publisher = {r.island: thief.declare_publisher(f"hysid/mb/history/{r.island}") for r in runs}
        x = c.objective.bounds.mean(axis=1)
        f = float(c.objective(x[None, :])[0])
        deadline, seq = time.monotonic() + 8.0, 0
        while time.monotonic() < deadline:
            for r in runs:
                most, iterations = c.checks.effort_bound(["pso"], time.time() - c.runs[(r.island, r.run)].joined)
                it = int(0.95 * iterations)
                row = [[it, f, int(min(0.95 * most, c.checks.evaluation_bound("pso", np.array([float(it)]))[0])), 0.0]]
                publisher[r.island].put(encode_history(History("mb", r.island, r.run, "pso", c.runs[(r.island, r.run)].seed, np.array(row, dtype=float),
                                                               x, f, STATS, seq=seq), r))
            seq += 1
            time.sleep(0.5)
            assert c.stop_reason is None, c.stop_reason
        claimed = sum(e for (island, _), e in c.run_evaluations.items() if island.startswith("mallory-"))
        assert claimed > 3 * 4_000_000 and c.countable() < 4_000_000  # plausible claims of 3 budgets and more, counted no further
        threads[2].start()
        wait_for(lambda: query(db, "SELECT count(*) FROM history WHERE island = 'late'")[0][0] > 10, 60, "the late island's history")
        assert c.stop_reason is None and not query(db, "SELECT 1 FROM rejected WHERE reason = 'implausible'")
    finally:
        campaign._done.set()
        for t in threads:
            if t.is_alive() or t.ident is not None:
                t.join(60)
        thief.close()
        campaign.end()
