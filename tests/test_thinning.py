"""The history policy over capacity (coordinator/thinning.py) and the inbox's replaceable migrant slots: every
improvement kept, the rest thinned per island by what it offers, what was left out counted in the database and
the report, nothing thinned asked for again; an island's older migrant message superseded when the coordinator is behind, counted."""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest

from coordinator.inbox import SLOT_EVERY, Inbox
from coordinator.links import MemoryLink
from coordinator.loop import pump
from coordinator.state import Coordinator
from coordinator.store import Store
from coordinator.thinning import HistoryPolicy, water_level
from hysid.campaigns import CampaignResult
from hysid_model.synth import synth_loops
from island.config import CampaignConfig
from island.island_messages import History, Migrants, encode_history, encode_migrants
from island.migration import Migration

LOOPS = synth_loops(n_points=30)
STATS = {"sent": 0, "received": 0, "taken": 0, "rejected": 0}


def rows(first: int, last: int, per_s: float, best: float = 1.0, improves: dict[int, float] | None = None) -> np.ndarray:
    """Rows of iterations first..last of a PSO island of 10 particles iterating ``per_s`` a second: its best
    ``best``, improving to the values ``improves`` names at those iterations."""
    its = np.arange(first, last + 1)
    f = np.full(its.size, best)
    for it, value in sorted((improves or {}).items()):
        f[its >= it] = value
    return np.column_stack([its, f, 20 + 25 * its, its / per_s]).astype(float)


def test_runs_offering_less_than_their_share_keep_every_row_the_others_are_thinned_to_it() -> None:
    assert water_level(np.array([10.0, 100.0, 1000.0]), 2000.0) == np.inf  # everything fits
    assert water_level(np.array([10.0, 100.0, 1000.0]), 300.0) == 190.0  # 10 and 100 kept whole, 190 left for the fastest
    assert water_level(np.array([200.0, 100.0, 1000.0]), 300.0) == 100.0  # 100 whole, 200 shared by the two others

    def measured(seconds: float, busy_s: float, writing_s: float, written: int) -> HistoryPolicy:
        policy = HistoryPolicy()
        for key, per_s in (("slow", 10.0), ("mid", 100.0), ("fast", 1000.0)):
            policy.keep((key, "r"), rows(0, 99, per_s))
            policy.keep((key, "r"), rows(100, 199, per_s))  # the rate, on the island's own clock
        policy.review(seconds, busy_s, writing_s, written)
        return policy

    fits = measured(1.0, busy_s=0.55, writing_s=0.25, written=10_000)  # 25 us a row; the rest took 0.3 s of the 0.8 s to use
    assert fits.holds == pytest.approx(20_000) and [p.stride for p in fits.paces.values()] == [1, 1, 1]
    assert measured(1.0, busy_s=0.8, writing_s=0.01, written=400).holds == np.inf  # too few rows to measure one
    full = measured(1.0, busy_s=0.815, writing_s=0.025, written=1000)  # the rest takes nearly all of it: 0.01 s / 25 us
    assert full.holds == pytest.approx(400)
    assert [full.paces[(k, "r")].stride for k in ("slow", "mid", "fast")] == [1, 1, 4]  # 10 and 100 fit, 1000 gets 290: stride 4


def test_over_capacity_every_improvement_and_each_messages_newest_row_are_kept_and_the_plateau_thinned() -> None:
    policy = HistoryPolicy()
    key = ("a", "r")
    assert policy.keep(key, rows(0, 49, 100.0)).all()  # a run's first message: whole
    assert policy.keep(key, rows(50, 99, 100.0)).all()  # storage not measured yet: whole
    assert policy.paces[key].stride == 1
    policy.review(seconds=1.0, busy_s=1.0, writing_s=1.0, written=1000)  # 1 ms a row: 0.8 s left, 800 rows/s
    assert policy.paces[key].stride == 1
    for _ in range(12):  # then 25 ms left, again and again: 25 rows/s, the estimate follows in steps
        policy.review(seconds=1.0, busy_s=0.775, writing_s=0.0, written=0)
    assert 25 < policy.holds < 50
    assert policy.paces[key].stride == 4  # of the 100 it offers
    batch = rows(100, 149, 100.0, improves={113: 0.5, 127: 0.25})
    kept = batch[policy.keep(key, batch)]
    assert set(kept[:, 0]) == set(range(100, 150, 4)) | {113, 127, 149}  # the grid, both improvements, the newest
    assert policy.thinned == 50 - kept.shape[0]
    assert policy.keep(key, rows(120, 149, 100.0, best=0.25)).all()  # rows asked for again: whole


class RecordingLink(MemoryLink):
    """The coordinator's outputs in one process, with every history query it makes."""

    def __init__(self) -> None:
        super().__init__(threading.Event())
        self.asked: list[tuple[str, str, int]] = []

    def request_history(self, island: str, run: str, since: int) -> None:
        self.asked.append((island, run, since))


def test_a_coordinator_over_capacity_stores_every_improvement_counts_the_rest_and_asks_for_none_of_it(tmp_path) -> None:
    sizes = {"pso": {"population": 10, "initial_population": 20, "iterations": 10**6}}
    config = CampaignConfig.create(LOOPS, name="c1", algos=["pso"], options=sizes, migration=Migration(interval=0))
    c = Coordinator(Store(tmp_path / "c.sqlite"), config, LOOPS)
    link = RecordingLink()
    x = c.objective.bounds.mean(axis=1)
    f = float(c.objective(x[None, :])[0])
    islands = [c.join(f"pso-{i}", "pso", i) for i in range(2)]
    sent = 0
    for m in range(6):
        for i, cred in enumerate(islands):
            batch = rows(40 * m, 40 * m + 39, 2000.0, best=2 * f if m <= 3 else f, improves={137: f} if m == 3 else None)
            sent += batch.shape[0]
            c.receive(f"hysid/c1/history/{cred.island}", encode_history(History("c1", cred.island, cred.run, "pso", i, batch, x, f, STATS, seq=m), cred))
        if m < 2:
            pump(c, link, 5.0)
            continue
        if m == 2:  # measured: writing a row takes 0.2 ms, the rest of the work leaves 0.1 s a second: 500 rows/s, 250 each
            c.policy.row_s, c.policy.holds = None, math.inf  # (instead of what this machine's commits measured so far)
            c.policy.review(seconds=1.0, busy_s=0.9, writing_s=0.2, written=1000)
            assert [p.stride for p in c.policy.paces.values()] == [8, 8]  # each offers 2000 rows/s
        while (item := c.inbox.get()) is not None:
            c.handle(link, item)  # as the run loop does, without its commits measuring this machine
    c.store.commit()
    stored = c.store.db.execute("SELECT island, iteration FROM history").fetchall()
    thinned = c.store.thinned("c1")
    assert len(stored) + sum(thinned.values()) == sent  # nothing lost: stored or counted
    for cred in islands:
        its = {it for island, it in stored if island == cred.island}
        assert its == set(range(80)) | {it for it in range(80, 240, 8)} | {137} | {119, 159, 199, 239}  # whole first; grid, improvement, newest
        assert thinned[(cred.island, cred.run)] == 160 - len(its - set(range(80)))
        assert c.gaps.stored((cred.island, cred.run)) == 239  # the thinned rows were handled, not lost
    assert link.asked == []  # so nobody is asked for them again
    result = CampaignResult.from_outcome(c.outcome(polish_best=False))
    assert result.stored == {"history_rows": len(stored), "thinned_rows": sum(thinned.values()), "superseded_migrant_messages": 0}
    assert {i["island"]: i["thinned"] for i in result.islands} == {island: n for (island, _), n in thinned.items()}
    assert f"history: {len(stored):,} rows stored; {sum(thinned.values()):,} rows thinned while the islands offered more" in result.summary()
    c.store.close()


def test_an_islands_newer_migrant_message_supersedes_the_one_waiting_when_the_coordinator_is_behind_and_is_counted(tmp_path) -> None:
    keeping_up = Inbox(crowded=2)
    assert keeping_up.put("a", "migrants-1", 10, replace=True) and keeping_up.put("a", "migrants-2", 10, replace=True)
    assert keeping_up.put("a", "history-0", 10) and keeping_up.put("a", "migrants-3", 10, replace=True)  # 2 waiting: behind
    assert keeping_up.put("a", "migrants-4", 10, replace=True)
    assert [keeping_up.get() for _ in range(4)] == ["migrants-1", "migrants-2", "history-0", "migrants-4"]
    assert keeping_up.take_superseded() == {"a": 1} and keeping_up.get() is None and len(keeping_up) == 0
    inbox = Inbox(crowded=0)  # behind from the start
    assert inbox.put("a", "migrants-1", 10, replace=True) and inbox.put("a", "migrants-2", 10, replace=True)
    assert inbox.put("b", "migrants-b", 10, replace=True)
    for k in range(2 * SLOT_EVERY):
        inbox.put("a", f"history-{k}", 10)
    served = [inbox.get() for _ in range(2 * SLOT_EVERY + 2)]
    assert served.count("migrants-2") == 1 and "migrants-1" not in served  # only the newest of a
    assert served.index("migrants-2") == SLOT_EVERY - 1 and served.index("migrants-b") == 2 * SLOT_EVERY - 1  # every SLOT_EVERY th
    assert [s for s in served if s.startswith("history")] == [f"history-{k}" for k in range(2 * SLOT_EVERY)]  # in order, all
    assert inbox.take_superseded() == {"a": 1} and inbox.get() is None
    config = CampaignConfig.create(LOOPS, name="c1", algos=["pso"], options={"pso": {"population": 10, "initial_population": 20}})
    c = Coordinator(Store(tmp_path / "c.sqlite"), config, LOOPS)
    cred = c.join("pso-0", "pso", 0)
    x = c.objective.bounds.mean(axis=1)[None, :]

    def migrants(seqs: range) -> None:
        for seq in seqs:
            c.receive("hysid/c1/migrants/pso-0", encode_migrants(Migrants("c1", "pso-0", cred.run, seq, x, np.array([1.0]), time.time(), seq), cred))
        pump(c, MemoryLink(threading.Event()), 5.0)

    migrants(range(3))  # a coordinator keeping up handles every one
    assert c.migrations == 3 and c.superseded == 0
    c.inbox.crowded = 0  # one that is behind, only the newest
    migrants(range(3, 8))
    assert c.migrations == 4 and c.superseded == 4 and c.store.superseded("c1") == 4
    assert c.store.db.execute("SELECT seq FROM migrations").fetchall() == [(0,), (1,), (2,), (7,)]  # the newest was handled
    c.store.close()
