"""The membership rules of coordinator/members.py. After ``--resume`` the coordinator takes up again, as members,
exactly the island runs that were alive when it died; a run that had sent its final history (it left), or whose
last membership event says it left or was lost, is not taken up. A run is alive from its join (or first signed
message), lost when silent for STALE_S or when its token goes without a final history for LEAVE_GRACE_S, back when
heard after that, and gone for good once its final history came (``stopped`` once the user stopped the campaign)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from coordinator.members import LEAVE_GRACE_S, STALE_S, Membership
from coordinator.queries import IslandRecord
from coordinator.store import Store


@pytest.fixture
def store(tmp_path):
    s = Store(tmp_path / "c.sqlite")
    s.create_campaign("c", "rig", b"{}")
    yield s
    s.close()


def record(island: str, run: str, final: bool) -> IslandRecord:
    return IslandRecord(island, run, "pso", 0, 5, 50, 1.0, np.zeros(2), 0, 0, 0, 0, final)


def test_only_runs_alive_at_the_crash_are_taken_up(store):
    """a: joined and sent its final history (stored as final) but the crash came before its leave was recorded;
    b: joined and was searching; c: left; d: was lost. Only b is a member again, alive until heard from or stale."""
    for island in "abcd":
        store.member_event("c", island, "join")
    store.member_event("c", "c", "left")
    store.member_event("c", "d", "lost")
    store.update_island("c", record("a", "r1", True))
    store.update_island("c", record("b", "r2", False))

    def finished(island: str, run: str) -> bool:  # as the coordinator reads it: the run's stored record is final
        return any(r.final for r in store.islands("c") if (r.island, r.run) == (island, run))

    membership = Membership(store, "c", 1, finished)
    membership.take_up({"a": "r1", "b": "r2", "c": "r3", "d": "r4"})
    assert {island: (m.status, m.run, m.resumed) for island, m in membership.members.items()} == {"b": ("alive", "r2", True)}
    assert membership.alive("b", "r2") and not membership.alive("a", "r1")


def events(store: Store) -> list[tuple[str, str]]:
    return [(island, event) for island, event, _ in store.members("c")]


def test_a_run_is_alive_from_its_join_or_first_signed_message_and_only_its_latest_run_counts(store):
    membership = Membership(store, "c", 2, lambda island, run: False)
    membership.joined("a", "r1", b"n")
    assert membership.alive("a", "r1") and not membership.alive("a", "r0") and not membership.alive("b", "r1")
    assert membership.full_at is None  # 2 islands wanted
    membership.heard("b", "r2", time.monotonic())  # joined before this coordinator restarted
    assert membership.alive("b", "r2") and membership.full_at is not None and membership.any_alive()
    membership.heard("b", "r9", time.monotonic())  # not its latest run
    assert membership.members["b"].run == "r2"
    assert events(store) == [("a", "join"), ("b", "join")] and membership.events == 2


def test_a_run_is_lost_when_silent_or_its_token_goes_without_a_leave_and_back_when_heard_after(store):
    membership = Membership(store, "c", 1, lambda island, run: False)
    for island in "abc":
        membership.joined(island, "r", b"n")
    membership.members["a"].heard_at -= STALE_S  # silent for STALE_S
    membership.token("b", "r", False)
    membership.members["b"].gone_at -= LEAVE_GRACE_S  # its token gone that long
    membership.token("c", "r", False)  # just gone: a final history may still come
    membership.settle()
    assert {i: m.status for i, m in membership.members.items()} == {"a": "lost", "b": "lost", "c": "alive"}
    membership.members["c"].gone_at -= LEAVE_GRACE_S
    membership.settle(waiting=lambda island: island == "c")  # its messages wait to be handled
    assert membership.members["c"].status == "alive"
    lost_at = membership.members["a"].lost_at
    membership.heard("a", "r", lost_at)  # sent before it was found lost
    assert membership.members["a"].status == "lost"
    membership.heard("a", "r", lost_at + 1e-6)
    assert membership.members["a"].status == "alive" and membership.members["a"].gone_at is None
    assert events(store)[-3:] == [("a", "lost"), ("b", "lost"), ("a", "back")]


def test_a_final_history_is_a_leave_even_after_a_loss_and_a_stop_by_the_user_records_stopped(store):
    membership = Membership(store, "c", 1, lambda island, run: False)
    for island in "abcd":
        membership.joined(island, "r", b"n")
    membership.final_history("a", "r")
    membership.final_history("b", "other run")
    membership.members["c"].heard_at -= STALE_S
    membership.settle()
    membership.final_history("c", "r")  # handled after the loss: it was sent before
    membership.stopped_by_user()
    membership.final_history("d", "r")
    assert {i: m.status for i, m in membership.members.items()} == {"a": "left", "b": "alive", "c": "left", "d": "stopped"}
    membership.final_history("a", "r")  # once only
    membership.stopped_by_user(give_up=True)
    assert membership.members["b"].status == "stopped" and not membership.any_alive() and membership.idle_since is not None
    assert events(store)[4:] == [("a", "left"), ("c", "lost"), ("c", "left"), ("d", "stopped"), ("b", "stopped")]


def test_a_run_taken_up_after_a_restart_counts_as_joined_when_heard_again(store):
    store.member_event("c", "a", "join")
    membership = Membership(store, "c", 1, lambda island, run: False)
    membership.take_up({"a": "r1"})
    assert membership.members["a"].resumed and events(store) == [("a", "join")]
    membership.heard("a", "r1", time.monotonic())
    assert not membership.members["a"].resumed and events(store) == [("a", "join"), ("a", "join")]
    membership.heard("a", "r1", time.monotonic())
    assert events(store) == [("a", "join"), ("a", "join")]


def test_a_run_counts_as_heard_when_it_joins_is_taken_up_or_sends_a_signed_message(store):
    """Its clock of silence starts then: a settle right after keeps it alive, one after STALE_S of silence does not,
    and a message in between starts the clock again."""
    store.member_event("c", "a", "join")
    membership = Membership(store, "c", 1, lambda island, run: False)
    before = time.monotonic()
    membership.take_up({"a": "r1"})
    membership.heard("b", "r2", time.monotonic())
    membership.joined("c", "r3", b"n")
    after = time.monotonic()
    for island in "abc":
        assert before <= membership.members[island].joined_at <= after and before <= membership.members[island].heard_at <= after
    membership.settle()
    assert membership.any_alive() and all(m.status == "alive" for m in membership.members.values())
    for member in membership.members.values():
        member.heard_at -= STALE_S
    membership.heard("a", "r1", time.monotonic())
    membership.settle()
    assert {i: m.status for i, m in membership.members.items()} == {"a": "alive", "b": "lost", "c": "lost"}
