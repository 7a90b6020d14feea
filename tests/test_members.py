"""No member outweighs the campaign (coordinator/admission.py, island/secret.py's member secrets): a join binds its run
to the member whose secret it proves; a member holds at most its share of the run slots; while more than one member is
alive a member's effort counts no further than the others' together, so that a budget is spent only with the effort of
more than one member. The attack: a holder of a member's secret with 16 runs, each claiming the most its run can
plausibly have done, against honest islands over Zenoh on loopback, with a late honest island joining after it.
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
import threading
import time

import numpy as np
import pytest

from coordinator.keys import CampaignKeys, key_path
from coordinator.launch import island_environment
from coordinator.loop import check_stop, pump
from coordinator.state import resume
from coordinator.store import Store
from hysid_model.errors import HysidInputError, HysidWarning
from island.handshake import JoinRequest, decode_joined
from island.island_messages import History, encode_history
from island.joining import join
from island.node import IslandNode
from island.sealing import new_key, public_key
from island.secret import CampaignSecret
from island.session import open_session, session_config
from island.termination import Termination
from island.transports import ZenohTransport
from support import query, wait_for
from test_coordinator import STATS, handshake, history, link, make, reasons, truth  # noqa: F401  (link: the fixture)
from test_host import LOOPS, Campaign, config


def test_a_member_secret_admits_only_that_members_islands_and_its_runs_are_bound_to_it(tmp_path, link):
    c = make(tmp_path)
    theirs = c.keys.member_secret("lab2")
    assert CampaignSecret.parse(theirs.text(), "x") == theirs and theirs.member == "lab2"
    key = new_key()
    ok = JoinRequest("c1", "lab2-0", "pso", 1, b"a" * 16, public_key(key), "lab2")
    run = decode_joined(handshake(c, link, ok, key, admission=theirs.admission)[0], "c1", "lab2-0", ok.nonce, c.secret.coordinator)
    assert c.runs[("lab2-0", run)].member == "lab2" and c.store.runs("c1")[0][-1] == "lab2"
    other_id = JoinRequest("c1", "pso-7", "pso", 1, b"b" * 16, public_key(key), "lab2")  # not one of lab2's names
    other_member = JoinRequest("c1", "lab3-0", "pso", 1, b"c" * 16, public_key(key), "lab3")  # lab2's secret, lab3's join
    assert handshake(c, link, other_id, key, admission=theirs.admission) == []
    assert handshake(c, link, other_member, key, admission=theirs.admission) == []
    assert reasons(c) == {"sender": 1, "forged": 1} and len(c.runs) == 1


def test_no_secret_an_island_holds_makes_another_members_secret(tmp_path, link):
    """What an island is handed (the campaign's shared secret in its file, a member's in a launched island's environment)
    holds no byte of the members' key, and no admission secret an attacker can compute from it (the secret itself, an
    HMAC of another member's name under it: what this campaign's hysid derived member secrets by before) admits for
    another member, or for the shared one; the members' own secrets do."""
    c = make(tmp_path)
    shared, lab2 = c.secret, c.keys.member_secret("lab2")
    handed = (shared.text(), lab2.text(), *island_environment(c.keys.member_secret("pso-1"), c.objective.model).values())
    assert not any(k.hex() in text for text in handed for k in (c.keys.members, c.keys.signing))
    assert not any(c.keys.admission.hex() in text for text in handed[1:])  # a member's secret holds not the shared one either

    def derived(secret, member: str) -> bytes:
        return hmac.new(secret.admission, b"hysid member\x00" + member.encode(), hashlib.sha256).digest()

    key, attempts = new_key(), 0
    for member, island in (("lab3", "lab3-0"), ("", "anyone")):
        for admission in {shared.admission, lab2.admission, derived(shared, member), derived(lab2, member), derived(lab2, "lab2")} - {
            c.keys.admission_for(member)
        }:
            request = JoinRequest("c1", island, "pso", 1, secrets.token_bytes(16), public_key(key), member)
            assert handshake(c, link, request, key, admission=admission) == []
            attempts += 1
    assert reasons(c) == {"forged": attempts} and attempts >= 9 and not c.runs
    for secret, island in ((c.keys.member_secret("lab3"), "lab3-0"), (shared, "anyone")):
        request = JoinRequest("c1", island, "pso", 1, secrets.token_bytes(16), public_key(key), secret.member)
        run = decode_joined(handshake(c, link, request, key, admission=secret.admission)[0], "c1", island, request.nonce, c.secret.coordinator)
        assert c.runs[(island, run)].member == secret.member


def test_a_resumed_coordinator_admits_its_members_again_and_an_old_key_file_gets_a_members_key(tmp_path, link):
    """The members' key is in the key file that --resume reads: a member secret written before the restart admits after
    it. A key file of an earlier hysid (format 1, no members' key) gets one when resumed, with one warning naming what
    to do; the shared secret of before still admits."""
    c = make(tmp_path)
    lab2 = c.keys.member_secret("lab2")
    c.store.close()
    again = resume(Store(tmp_path / "c.sqlite"), "c1")
    key = new_key()
    request = JoinRequest("c1", "lab2", "pso", 1, b"a" * 16, public_key(key), "lab2")
    assert decode_joined(handshake(again, link, request, key, admission=lab2.admission)[0], "c1", "lab2", request.nonce, again.secret.coordinator)
    again.store.close()
    path = key_path(tmp_path / "c.sqlite", "c1")
    path.write_text(f"hysid-keys 1 c1 {c.keys.admission.hex()} {c.keys.signing.hex()}\n")  # as an earlier hysid wrote it
    with pytest.warns(HysidWarning, match="without a members' key; one was added .* write them again with --member NAME"):
        old = resume(Store(tmp_path / "c.sqlite"), "c1")
    upgraded = CampaignKeys.read(path, "c1")
    assert upgraded == old.keys and (upgraded.admission, upgraded.signing) == (c.keys.admission, c.keys.signing)
    assert len(upgraded.members) == 32 and path.read_text().startswith("hysid-keys 2 c1 ")
    request = JoinRequest("c1", "pso-9", "pso", 1, b"b" * 16, public_key(key))
    assert decode_joined(handshake(old, link, request, key)[0], "c1", "pso-9", request.nonce, old.secret.coordinator)  # the shared secret
    old.store.close()


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
    claim = lambda e: [[e // 10, f, e, 0.0]]
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
    theirs = c.keys.member_secret("mallory")
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
                publisher[r.island].put(
                    encode_history(History("mb", r.island, r.run, "pso", c.runs[(r.island, r.run)].seed, np.array(row, dtype=float), x, f, STATS, seq=seq), r)
                )
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
