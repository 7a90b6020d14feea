"""The coordinator in one process (coordinator/state.py, receiving.py, intake.py, loop.py, inbox.py) on a real SQLite file: who may speak,
what it may claim, replays, re-evaluation, commits under load, stop rules with a backlog, resumed ends.

Messages go in through the same entry points the Zenoh link uses (``receive``, ``member``,
``join_request``); a :class:`MemoryLink` takes what the coordinator sends out.
"""

from __future__ import annotations

import sqlite3
import threading
import time

import numpy as np
import pytest

from coordinator.links import MemoryLink
from coordinator.loop import check_stop, pump, serve
from coordinator.state import Coordinator, resume
from coordinator.store import Store
from hysid_model.synth import TRUE_PARAMS, synth_loops
from island.config import CampaignConfig
from island.coordinator_messages import decode_control
from island.handshake import JoinRequest, decode_challenge, decode_joined, encode_join, encode_prove
from island.island_messages import History, Migrants, encode_history, encode_migrants
from island.migration import Migration
from island.sealing import Credentials, new_key, public_key
from island.termination import Termination

LOOPS = synth_loops(n_points=30)
SIZES = {a: {"population": 10, "initial_population": 20, "iterations": 50} for a in ("ga", "pso")}
STATS = {"sent": 0, "received": 0, "taken": 0, "rejected": 0}


def make(tmp_path, termination: Termination | None = None, min_islands: int = 1, iterations: int = 50) -> Coordinator:
    sizes = {a: {**o, "iterations": iterations} for a, o in SIZES.items()}
    config = CampaignConfig.create(LOOPS, name="c1", options=sizes, migration=Migration(interval=5, k=2), min_islands=min_islands)
    return Coordinator(Store(tmp_path / "c.sqlite"), config, LOOPS, termination)


@pytest.fixture
def link() -> MemoryLink:
    return MemoryLink(threading.Event())


def truth(c: Coordinator) -> np.ndarray:
    return c.objective.model.from_dict(TRUE_PARAMS)


def history(
    c: Credentials, rows, best_x: np.ndarray, best_f: float, *, seq: int = 0, final: bool = False, algo: str = "pso", seed: int = 1, stats: dict | None = None
) -> bytes:
    return encode_history(History("c1", c.island, c.run, algo, seed, np.array(rows, dtype=float).reshape(-1, 4), best_x, best_f, stats or STATS, final, seq), c)


def honest_rows(c: Coordinator, n: int) -> list[list[float]]:
    """Rows a PSO island of SIZES really reports: 20 + 10 iterations x (10 + 15) evaluations."""
    return [[i, 10.0 / (i + 1), 20 + 25 * i, 0.01 * i] for i in range(n)]


def deliver(c: Coordinator, link: MemoryLink, kind: str, sender: str, payload: bytes) -> None:
    assert c.receive(f"hysid/c1/{kind}/{sender}", payload)
    pump(c, link, 5.0)


def reasons(c: Coordinator) -> dict[str, int]:
    return c.store.rejected_reasons("c1")


def test_history_of_an_island_that_never_joined_is_rejected_and_spends_no_budget(tmp_path, link):
    c = make(tmp_path, Termination(budget=100_000))
    ghost = Credentials.issue("ghost", c.secret.coordinator)  # its run never joined
    x = truth(c)
    deliver(c, link, "history", "ghost", history(ghost, [[0, 1.0, 2**52, 0.1]], x, 0.0))
    deliver(c, link, "history", "ghost", history(ghost, [[0, 1.0, 2**52, 0.1]], x, 0.0, final=False, seq=1))
    assert reasons(c) == {"unjoined": 2}
    assert c.evaluations == 0 and check_stop(c) is None and c.best is None and not c.islands


def test_a_joined_island_cannot_claim_what_it_could_not_have_done(tmp_path, link):
    c = make(tmp_path, Termination(budget=100_000))
    island = c.join("pso-1", "pso", 1)
    x = c.objective.bounds.mean(axis=1)
    f = float(c.objective(x[None, :])[0])
    most = int(c.checks.evaluation_bound("pso", np.array([3.0]))[0])  # (20 + 3 x 25) x (1 + 100 redraws) + the global best
    bad = [
        history(island, [[3, f, 2**52, 0.1]], x, f, seq=1),  # 2**52 evaluations after 3 iterations
        history(island, [[3, f, most + 1, 0.1]], x, f, seq=2),
        history(island, [[51, f, 100, 0.1]], x, f, seq=3),  # beyond its budget of 50 iterations
        history(island, [[3, f, 50, 0.1]], x, f, seq=4, algo="ga"),  # joined as pso
        history(island, [[3, f, 50, 0.1]], x, f / 2, seq=5),  # a best better than its vector's
        history(island, [[3, f, 50, 0.1]], x, f, seq=6, stats={"sent": 9, "received": 0, "taken": 0, "rejected": 0}),
        history(island, [[2, f, 45, 0.1], [3, f / 2, 50, 0.1]], x, f, seq=9),  # a row's best better than the vector's
        history(island, [[3, f, 50, 0.1]], x, f, seq=10, stats={"sent": 1, "received": 0, "taken": 1, "rejected": 0}),  # took more than it got
    ]
    for payload in bad:
        deliver(c, link, "history", "pso-1", payload)
    deliver(c, link, "history", "pso-1", history(island, [[3, f, 2.0**62, 0.1]], x, f, seq=8))  # not even a count a float holds exactly
    assert reasons(c) == {"implausible": 8, "schema": 1} and c.evaluations == 0
    assert c.store.count("history", "c1") == 0
    deliver(c, link, "history", "pso-1", history(island, [[i, 2 * f, 20 + 25 * i, 0.0] for i in range(4)], x, f, seq=7))
    assert c.evaluations == 95 and check_stop(c) is None and reasons(c) == {"implausible": 8, "schema": 1}
    deliver(c, link, "history", "pso-1", history(island, [[i, 2 * f, 20 + 25 * i, 0.0] for i in range(4)], x, f, seq=7))
    assert reasons(c)["replay"] == 1


def test_claimed_effort_is_bounded_by_the_time_since_the_join_at_the_rate_measured_here(tmp_path, link):
    """A member claiming 434 million evaluations (within what its iterations would allow) just after it
    joined, or a wall time of 1e300 s, is rejected with its reason: the budget and the stall rule count
    only effort it could have spent."""
    c = make(tmp_path, Termination(budget=200_000_000, stall=1_000_000), iterations=10**6)
    island = c.join("pso-1", "pso", 1)
    x = truth(c)
    f = float(c.objective(x[None, :])[0])
    iterations = 175_000.0
    assert c.checks.evaluation_bound("pso", np.array([iterations]))[0] > 434e6  # what the counters alone allow
    most, _ = c.checks.effort_bound(["pso"], 16.0)
    assert most < 434e6 / 4  # what 16 s allow, measured here, with room for a host many times faster
    deliver(c, link, "history", "pso-1", history(island, [[iterations, f, 434e6, 1.0]], x, f, seq=1))
    deliver(c, link, "history", "pso-1", history(island, [[iterations, f, 100, 1.0]], x, f, seq=2))  # iterations no population makes that fast
    deliver(c, link, "history", "pso-1", history(island, [[0, 2 * f, 20, 1e300]], x, f, seq=3))
    assert reasons(c) == {"implausible": 2, "out_of_range": 1}
    assert c.evaluations == 0 and check_stop(c) is None
    deliver(c, link, "history", "pso-1", history(island, honest_rows(c, 4), x, f, seq=4))
    assert c.evaluations == 95 and check_stop(c) is None


def test_a_liveliness_token_alone_makes_nobody_a_member(tmp_path, link):
    c = make(tmp_path)
    c.member("ghost", True)
    c.member("bad name/with slash", True)
    pump(c, link, 1.0)
    assert c.members == {} and reasons(c) == {"unjoined": 1, "sender": 1}
    island = c.join("pso-1", "pso", 1)
    c.member("pso-1", True)
    x = truth(c)
    deliver(c, link, "history", "pso-1", history(island, honest_rows(c, 3), x, float(c.objective(x[None, :])[0]), final=True))
    c.member("pso-1", False)
    pump(c, link, 1.0)
    assert c.members["pso-1"].status == "left" and check_stop(c) == "every island finished"


def test_a_token_counts_only_as_far_as_the_runs_signed_messages_bear_it_out(tmp_path, link, monkeypatch):
    """Anyone may declare a liveliness token under any name: a run that sent its final history has left
    whatever token stays, and a lost run is back only once a message signed by it arrives."""
    monkeypatch.setattr("coordinator.members.LEAVE_GRACE_S", 0.0)
    c = make(tmp_path)
    x = truth(c)
    f = float(c.objective(x[None, :])[0])
    a, b = c.join("a", "pso", 1), c.join("b", "pso", 2)
    for island in "ab":
        c.member(island, True)
    deliver(c, link, "history", "a", history(a, honest_rows(c, 3), x, f, final=True))
    assert c.members["a"].status == "left"  # its goodbye, while a token (its own, or a stranger's) is still there
    c.member("a", False)
    c.member("a", True)  # a stranger declares the token of the finished island
    deliver(c, link, "history", "b", history(b, honest_rows(c, 3), x, f, seed=2))
    c.member("b", False)  # b crashes
    pump(c, link, 0.1)
    assert c.members["b"].status == "lost"
    c.member("b", True)  # a stranger holds b's token
    pump(c, link, 0.1)
    assert (c.members["a"].status, c.members["b"].status) == ("left", "lost") and not c.membership.any_alive()
    deliver(c, link, "history", "b", history(b, honest_rows(c, 5), x, f, seq=1, seed=2))  # b itself, thawed: signed
    assert c.members["b"].status == "alive"
    assert [e for i, e, _ in c.store.members("c1") if i == "b"] == ["join", "lost", "back"]
    assert [e for i, e, _ in c.store.members("c1") if i == "a"] == ["join", "left"]


def alive_with_rows(c: Coordinator, link: MemoryLink, island: str, seed: int) -> tuple[Credentials, np.ndarray, float]:
    """A PSO island joined (seed ``seed``), its token seen, its first 3 rows handled; its credentials and best."""
    x = truth(c)
    f = float(c.objective(x[None, :])[0])
    cred = c.join(island, "pso", seed)
    c.member(island, True)
    deliver(c, link, "history", island, history(cred, honest_rows(c, 3), x, f, seed=seed))
    return cred, x, f


def test_a_message_that_waited_in_the_inbox_while_its_run_was_found_lost_does_not_bring_it_back(tmp_path, link, monkeypatch):
    """A coordinator that is behind handles messages after they arrived: one that arrived before its run
    was found lost is no sign the run is back (a site cut off while its rows still waited); the next
    message that arrives after the loss is."""
    monkeypatch.setattr("coordinator.members.LEAVE_GRACE_S", 0.0)
    c = make(tmp_path)
    b, x, f = alive_with_rows(c, link, "b", 2)
    assert c.receive("hysid/c1/history/b", history(b, honest_rows(c, 5), x, f, seq=1, seed=2))
    waited = c.inbox.get()  # arrived, not yet handled
    c.member("b", False)  # then its site is cut off: its token goes
    pump(c, link, 0.1)
    assert c.members["b"].status == "lost"
    c.handle(link, waited)
    assert c.members["b"].status == "lost" and c.islands[("b", b.run)].iteration == 4  # its rows stored, but not back
    deliver(c, link, "history", "b", history(b, honest_rows(c, 7), x, f, seq=2, seed=2))  # after the restore
    assert c.members["b"].status == "alive"
    assert [e for i, e, _ in c.store.members("c1") if i == "b"] == ["join", "lost", "back"]


def test_a_final_history_handled_after_the_islands_token_went_records_its_leave(tmp_path, link, monkeypatch):
    """Membership changes jump the queue of history messages (the inbox's urgent lane): an island that sends its
    final history and then drops its token, to a coordinator that is behind, has its token handled first, and
    may be found lost before its final history is handled. That history then records its leave."""
    monkeypatch.setattr("coordinator.members.LEAVE_GRACE_S", 0.0)
    c = make(tmp_path)
    a, x, f = alive_with_rows(c, link, "a", 1)
    assert c.receive("hysid/c1/history/a", history(a, honest_rows(c, 5)[3:], x, f, seq=1, final=True, seed=1))  # waits
    c.member("a", False)
    assert c.inbox.get() == ("member", "a", False)  # urgent: before the history that arrived first
    c.handle(link, ("member", "a", False))
    c.membership.settle()
    assert c.members["a"].status == "lost"
    pump(c, link, 0.1)
    assert c.members["a"].status == "left" and [e for i, e, _ in c.store.members("c1") if i == "a"] == ["join", "lost", "left"]
    b, _, _ = alive_with_rows(c, link, "b", 2)  # once the stop order went out, every island leaves: a loss waits for what waits of it
    c.stop_reason = "time limit of 1 s"
    assert c.receive("hysid/c1/history/b", history(b, honest_rows(c, 5)[3:], x, f, seq=1, final=True, seed=2))
    c.member("b", False)
    assert c.inbox.get() == ("member", "b", False)
    c.handle(link, ("member", "b", False))
    c.membership.settle(c.inbox.holds)  # as the run loop does once stopping
    assert c.members["b"].status == "alive"
    pump(c, link, 0.1)
    assert [e for i, e, _ in c.store.members("c1") if i == "b"] == ["join", "left"]


def test_a_joined_island_never_heard_from_is_lost(tmp_path, link, monkeypatch):
    monkeypatch.setattr("coordinator.members.STALE_S", 0.0)
    c = make(tmp_path)
    c.join("pso-1", "pso", 1)
    pump(c, link, 0.1)
    assert c.members["pso-1"].status == "lost" and c.store.members("c1")[-1][:2] == ("pso-1", "lost")


def test_migrants_under_another_islands_id_are_rejected(tmp_path, link):
    c = make(tmp_path)
    a, b = c.join("a", "pso", 1), c.join("b", "pso", 2)
    x = truth(c)[None, :]
    as_a_with_b_keys = Credentials("a", a.run, b.key, b.coordinator)
    deliver(c, link, "migrants", "a", encode_migrants(Migrants("c1", "a", a.run, 5, x, np.zeros(1), time.time()), as_a_with_b_keys))
    deliver(c, link, "migrants", "b", encode_migrants(Migrants("c1", "a", a.run, 5, x, np.zeros(1), time.time()), as_a_with_b_keys))
    deliver(
        c, link, "migrants", "b", encode_migrants(Migrants("c1", "b", a.run, 5, x, np.zeros(1), time.time()), Credentials("b", a.run, b.key, b.coordinator))
    )
    assert reasons(c) == {"forged": 1, "sender": 1, "unjoined": 1}
    assert c.migrations == 0 and c.best is None


def test_a_replayed_migrant_message_is_stored_once_also_after_a_restart(tmp_path, link):
    c = make(tmp_path)
    a = c.join("a", "pso", 1)
    message = encode_migrants(Migrants("c1", "a", a.run, 5, truth(c)[None, :], np.zeros(1), time.time(), seq=3), a)
    deliver(c, link, "migrants", "a", message)
    deliver(c, link, "migrants", "a", message)
    assert c.migrations == 1 and reasons(c) == {"replay": 1}
    c.store.close()
    again = resume(Store(tmp_path / "c.sqlite"), "c1")
    deliver(again, link, "migrants", "a", message)  # the resumed coordinator still knows the run's key
    assert again.store.count("migrations", "c1") == 1 and reasons(again) == {"replay": 2}


def test_the_coordinator_re_evaluates_every_candidate_whatever_it_claims(tmp_path, link):
    c = make(tmp_path)
    a = c.join("a", "pso", 1)
    x = truth(c)
    bad = c.objective.bounds[:, 1]
    deliver(c, link, "migrants", "a", encode_migrants(Migrants("c1", "a", a.run, 5, bad[None, :], np.zeros(1), time.time(), seq=0), a))
    assert c.best is not None and c.best.fitness == c.objective(bad[None, :])[0]  # its own fitness, not the claimed 0
    deliver(c, link, "migrants", "a", encode_migrants(Migrants("c1", "a", a.run, 10, x[None, :], np.array([1e9]), time.time(), seq=1), a))
    assert c.best.fitness == c.objective(x[None, :])[0] < 1e-20  # better than it claimed: still taken
    np.testing.assert_array_equal(c.best.x, x)


def handshake(c: Coordinator, link, request: JoinRequest, key: bytes, admission: bytes | None = None) -> list[bytes]:
    """Both steps of the join handshake with ``c``; the answers to the proof (``admission``: the secret it proves)."""
    challenges: list[bytes] = []
    c.join_request(request.island, encode_join(request), challenges.append)
    pump(c, link, 1.0)
    challenge = decode_challenge(challenges[0], "c1", request.island, request.nonce, c.secret.coordinator)
    answers: list[bytes] = []
    c.join_request(request.island, encode_prove(request, challenge, admission or c.secret.admission, key), answers.append)
    pump(c, link, 1.0)
    return answers


def test_joining_is_refused_while_the_id_is_alive_and_a_repeated_request_gets_the_same_run(tmp_path, link):
    c = make(tmp_path)
    key = new_key()
    request = JoinRequest("c1", "pso-1", "pso", 1, b"n" * 16, public_key(key))
    first, second = (decode_joined(handshake(c, link, request, key)[0], "c1", "pso-1", request.nonce, c.secret.coordinator) for _ in range(2))
    assert first == second and len(c.runs) == 1  # the same request again (its answer was lost): the same run
    other = JoinRequest("c1", "pso-1", "pso", 1, b"o" * 16, public_key(key))
    with pytest.raises(Exception, match="taken by a running island"):
        decode_joined(handshake(c, link, other, key)[0], "c1", "pso-1", other.nonce, c.secret.coordinator)
    c.join_request("pso-1", b"\xc1 not a join request", lambda answer: pytest.fail("answered junk"))
    pump(c, link, 1.0)
    assert reasons(c) == {"undecodable": 1}
    control = decode_control(c.control_message(), "c1", c.secret.coordinator)
    assert [(m.island, m.run, m.alive, m.key) for m in control.members] == [("pso-1", first, True, public_key(key))]


def test_only_islands_that_prove_the_secret_are_admitted_and_each_id_has_bounded_runs(tmp_path, link, monkeypatch):
    monkeypatch.setattr("coordinator.admission.RUNS_PER_ISLAND", 3)
    monkeypatch.setattr("coordinator.members.LEAVE_GRACE_S", 0.0)
    c = make(tmp_path)
    key = new_key()
    outsider = JoinRequest("c1", "guess", "pso", 1, b"g" * 16, public_key(key))
    assert handshake(c, link, outsider, key, admission=b"w" * 32) == []  # a wrong secret: no answer, counted
    late = JoinRequest("c1", "late", "pso", 1, b"l" * 16, public_key(key))
    stale: list[bytes] = []
    c.join_request("late", encode_prove(late, b"s" * 16, c.secret.admission, key), stale.append)  # a challenge nobody issued
    pump(c, link, 1.0)
    assert stale == [] and reasons(c) == {"forged": 1, "replay": 1} and not c.runs
    for n in range(4):
        request = JoinRequest("c1", "restarts", "pso", 1, bytes([n]) * 16, public_key(key))
        answer = handshake(c, link, request, key)[0]
        if n < 3:
            decode_joined(answer, "c1", "restarts", request.nonce, c.secret.coordinator)
            c.member("restarts", True)
            c.member("restarts", False)  # it crashes: lost, and joins again
            pump(c, link, 1.0)
            c.membership.settle()
        else:
            with pytest.raises(Exception, match="joined 3 times, its limit"):
                decode_joined(answer, "c1", "restarts", request.nonce, c.secret.coordinator)
    assert len(c.runs) == 3


def test_a_resumed_campaign_whose_islands_all_finished_ends_at_once_with_its_report(tmp_path, link):
    c = make(tmp_path, min_islands=4)  # fewer joined than the islands it once waited for
    x = truth(c)
    for i in range(2):
        cred = c.join(f"pso-{i}", "pso", i)
        deliver(c, link, "history", cred.island, history(cred, honest_rows(c, 5), x, float(c.objective(x[None, :])[0]), final=True, seed=i))
    c.store.close()  # the coordinator died; nobody is left
    again = resume(Store(tmp_path / "c.sqlite"), "c1")
    started = time.monotonic()
    assert serve(again, MemoryLink(threading.Event())) == "every island finished"
    assert time.monotonic() - started < 5.0
    outcome = again.outcome(polish_best=False)
    assert {i["island"] for i in outcome.islands} == {"pso-0", "pso-1"}
    assert again.store.campaign("c1")[2] == "stopped"


def test_a_resumed_campaign_nobody_comes_back_to_ends_after_the_orphan_wait(tmp_path, link, monkeypatch):
    monkeypatch.setattr("coordinator.loop.ORPHAN_S", 0.2)
    monkeypatch.setattr("coordinator.members.STALE_S", 0.5)
    c = make(tmp_path)
    c.join("pso-0", "pso", 0)  # joined, never finished
    c.store.close()
    again = resume(Store(tmp_path / "c.sqlite"), "c1")
    assert again.progress().members == {"pso-0": "alive"}  # alive when the coordinator died: waited for, not forgotten
    assert serve(again, MemoryLink(threading.Event())) == "no island alive for 0.2 s"
    assert [e for i, e, _ in again.store.members("c1")] == ["join", "lost"]  # not listed alive forever


def test_a_resumed_coordinator_keeps_the_stop_rules_of_its_campaign(tmp_path, link):
    c = make(tmp_path, Termination(budget=12_345, stall=999))
    c.store.close()
    again = resume(Store(tmp_path / "c.sqlite"), "c1")
    assert again.termination == Termination(budget=12_345, stall=999)
    again.store.close()
    other = resume(Store(tmp_path / "c.sqlite"), "c1", Termination(time_limit_s=5.0))  # rules given again replace them
    assert other.termination == Termination(time_limit_s=5.0)


def test_a_resumed_campaign_carries_its_elapsed_time_on(tmp_path, link):
    """The elapsed time goes into every commit; a resumed coordinator starts from it, so that a campaign
    that had run past its time limit stops at once instead of running the limit again."""
    c = make(tmp_path, Termination(time_limit_s=60.0))
    c.store.commit("c1", 61.5)  # the last commit of a coordinator killed 61.5 s into its campaign
    c.store.close()
    again = resume(Store(tmp_path / "c.sqlite"), "c1")
    assert again.elapsed() >= 61.5 and again.progress().elapsed_s >= 61.5
    assert again.rule_stop() == again.termination.reason(evaluations=0, best=np.inf, best_at=0, elapsed_s=61.5) is not None
    assert serve(again, MemoryLink(threading.Event())) == again.rule_stop()


def test_a_database_deleted_mid_run_stops_the_campaign_with_one_line(tmp_path, link):
    c = make(tmp_path)
    island = c.join("pso-1", "pso", 1)
    x = truth(c)
    deliver(c, link, "history", "pso-1", history(island, honest_rows(c, 3), x, float(c.objective(x[None, :])[0])))
    for suffix in ("", "-wal", "-shm"):
        (tmp_path / f"c.sqlite{suffix}").unlink(missing_ok=True)
    with pytest.raises(
        Exception,
        match=r"^campaign 'c1' stopped: cannot write the campaign database .*c.sqlite: the file was deleted; "
        r"what it recorded went with the file \(nothing to resume\)$",
    ):
        serve(c, link)
    assert link.stop.is_set()
    assert not c.inbox.put("late", "anything", wait_s=None)  # closed: nothing arriving can block a producer any more


def test_a_database_locked_by_another_process_stops_the_campaign_cleanly(tmp_path, link):
    c = make(tmp_path)
    c.store.db.execute("PRAGMA busy_timeout = 200")
    island = c.join("pso-1", "pso", 1)
    x = truth(c)
    f = float(c.objective(x[None, :])[0])
    deliver(c, link, "history", "pso-1", history(island, honest_rows(c, 3), x, f))
    other = sqlite3.connect(tmp_path / "c.sqlite", isolation_level=None, check_same_thread=False)
    other.execute("BEGIN IMMEDIATE")  # someone holds the write lock
    c.receive("hysid/c1/history/pso-1", history(island, honest_rows(c, 6), x, f, seq=1))
    release = threading.Timer(1.5, lambda: other.execute("COMMIT"))
    release.start()
    with pytest.raises(Exception, match=r"campaign 'c1' stopped: cannot write the campaign database .*database is locked.*it is marked interrupted"):
        serve(c, link)
    release.join()
    assert link.stop.is_set()
    with sqlite3.connect(tmp_path / "c.sqlite") as reader:
        assert reader.execute("SELECT status FROM campaigns").fetchone()[0] == "interrupted"
        assert reader.execute("SELECT count(*) FROM history").fetchone()[0] == 3  # what was committed is kept
