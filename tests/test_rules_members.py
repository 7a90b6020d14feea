"""The restart rule of coordinator/members.py: after ``--resume`` the coordinator takes up again, as members, exactly
the island runs that were alive when it died; a run that had sent its final history (it left), or whose last
membership event says it left or was lost, is not taken up."""

from __future__ import annotations

import numpy as np
import pytest

from coordinator.members import Membership
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
