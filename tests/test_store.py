"""The campaign database (coordinator/store.py) on real SQLite files."""

from __future__ import annotations

import multiprocessing
import os
import signal

import numpy as np
import pytest

from coordinator.store import IslandRecord, Store, StoredBest
from hysid_model.errors import HysidInputError


def record(run: str = "r1", iterations: int = 3, evaluations: int = 300, best: float = 1.0, final: bool = False) -> IslandRecord:
    return IslandRecord("ga-0", run, "ga", 7, iterations, evaluations, best, np.array([0.1, 2.0]) * best, 1, 2, 1, 0, final)


def test_campaign_is_created_once_and_never_overwritten(tmp_path):
    store = Store(tmp_path / "c.sqlite")
    store.create_campaign("c1", "synth", b"config-bytes")
    with pytest.raises(HysidInputError, match="already exists; resume it"):
        store.create_campaign("c1", "other", b"other")
    assert store.campaign("c1") == ("synth", b"config-bytes", "running")
    with pytest.raises(HysidInputError, match="no campaign 'c9' to resume.*c1"):
        store.campaign("c9")


def test_history_rows_are_stored_once_per_island_run_and_iteration(tmp_path):
    store = Store(tmp_path / "c.sqlite")
    rows = np.array([[0, 5.0, 100, 0.1], [1, 4.0, 200, 0.2]])
    assert store.add_history("c1", "ga-0", "r1", rows) == 2
    assert store.add_history("c1", "ga-0", "r1", np.vstack([rows, [[2, 3.0, 300, 0.3]]])) == 1
    assert store.add_history("c1", "ga-0", "r2", rows) == 2
    assert store.handled("c1", "ga-0", "r1") == [(0, 2)]
    assert store.handled("c1", "ga-0", "r3") == []
    assert [r[2] for r in store.history("c1") if r[1] == "r1"] == [0, 1, 2]


def test_the_iterations_handled_are_the_rows_stored_and_the_stretches_thinned(tmp_path):
    store = Store(tmp_path / "c.sqlite")
    row = lambda i: [i, 1.0, 10 * i, 0.1 * i]  # noqa: E731
    store.add_history("c1", "a", "r", np.array([row(i) for i in (1, 2, 3)]))
    assert store.handled("c1", "a", "r") == [(1, 3)]  # iteration 0 missing
    store.add_history("c1", "a", "r", np.array([row(i) for i in (0, 7, 8)]))
    assert store.handled("c1", "a", "r") == [(0, 3), (7, 8)]
    store.queue_history("c1", "a", "r", np.array([row(i) for i in (9, 16, 20)]))  # of 9..20, 9 rows thinned
    store.queue_thinned("c1", "a", "r", (9, 20), 9)
    assert store.handled("c1", "a", "r") == [(0, 3), (7, 8)]  # queued, not written yet
    store.flush()
    assert store.handled("c1", "a", "r") == [(0, 3), (7, 20)] and store.thinned("c1") == {("a", "r"): 9}
    store.add_history("c1", "a", "r", np.array([row(i) for i in (4, 5, 6)]))
    assert store.handled("c1", "a", "r") == [(0, 20)]
    assert store.handled("c1", "a", "other") == []
    store.add_superseded("c1", {"a": 2, "b": 1})
    store.add_superseded("c1", {"a": 3})
    assert store.superseded("c1") == 6


def test_island_counters_only_grow_and_the_best_vector_follows_the_best_fitness(tmp_path):
    store = Store(tmp_path / "c.sqlite")
    store.update_island("c1", record(iterations=5, evaluations=500, best=0.5))
    store.update_island("c1", record(iterations=3, evaluations=300, best=0.9))  # a late, older message
    store.update_island("c1", record(run="r2", evaluations=50))
    (r1, r2) = store.islands("c1")
    assert (r1.iterations, r1.evaluations, r1.best_fitness) == (5, 500, 0.5)
    np.testing.assert_array_equal(r1.best_x, [0.05, 1.0])
    assert store.total_evaluations("c1") == 550 and r2.run == "r2"


def test_everything_committed_survives_a_killed_process(tmp_path):
    """A coordinator killed with SIGKILL right after a commit loses nothing it committed."""
    path = tmp_path / "c.sqlite"

    def writer() -> None:
        store = Store(path)
        store.create_campaign("c1", "synth", b"cfg")
        store.add_history("c1", "ga-0", "r1", np.array([[i, 1.0 / (i + 1), 10 * i, 0.01 * i] for i in range(50)]))
        store.member_event("c1", "ga-0", "join")
        store.add_rejected("c1", "hysid/c1/migrants/x", "oversized", "too big", 10**6)
        store.add_migration("c1", "ga-0", "r1", 5, 2, 0.1, 0.0, 0)
        store.set_best("c1", StoredBest("ga-0", np.array([1.0, 2.0]), 0.02, 490))
        store.commit()
        store.add_history("c1", "ga-0", "r1", np.array([[99, 0.0, 0, 0.0]]))  # not committed
        os.kill(os.getpid(), signal.SIGKILL)

    proc = multiprocessing.get_context("fork").Process(target=writer)
    proc.start()
    proc.join(30)
    assert proc.exitcode == -signal.SIGKILL
    store = Store(path)
    assert store.count("history", "c1") == 50
    assert store.handled("c1", "ga-0", "r1") == [(0, 49)]
    assert store.members("c1")[0][:2] == ("ga-0", "join")
    assert store.rejected_reasons("c1") == {"oversized": 1}
    assert store.count("migrations", "c1") == 1
    best = store.best("c1")
    assert best is not None and best.fitness == 0.02 and best.evaluations == 490
    np.testing.assert_array_equal(best.x, [1.0, 2.0])


def test_status_and_result_are_recorded(tmp_path):
    store = Store(tmp_path / "c.sqlite")
    store.create_campaign("c1", "synth", b"cfg")
    store.set_status("c1", "stopped", "target reached")
    store.set_result("c1", '{"fitness": 1e-09}')
    assert store.stop_reason("c1") == "target reached"
    assert store.campaign("c1")[2] == "stopped"
    assert Store(tmp_path / "c.sqlite").result("c1") == {"fitness": 1e-9}


def test_a_file_that_is_not_a_database_is_a_clear_error(tmp_path):
    bad = tmp_path / "notes.sqlite"
    bad.write_text("these are my notes, not a database\n" * 100)
    with pytest.raises(HysidInputError, match="notes.sqlite: not a usable campaign database"):
        Store(bad)
    assert bad.read_text().startswith("these are my notes")
