"""The campaign database (coordinator/store.py, schema.py, writes.py, queries.py) on real SQLite files."""

from __future__ import annotations

import multiprocessing
import os
import signal
import sqlite3

import numpy as np
import pytest

from coordinator.records import IslandRecord, StoredBest
from coordinator.schema import SCHEMA, UPGRADES, has_table
from coordinator.store import Store
from hysid_model.errors import HysidInputError


def record(run: str = "r1", iterations: int = 3, evaluations: int = 300, best: float = 1.0, final: bool = False) -> IslandRecord:
    return IslandRecord("ga-0", run, "ga", 7, iterations, evaluations, best, np.array([0.1, 2.0]) * best, 1, 2, 1, 0, final)


def test_campaign_is_created_once_and_never_overwritten(tmp_path):
    store = Store(tmp_path / "c.sqlite")
    store.create_campaign("c1", "synth", b"config-bytes")
    with pytest.raises(HysidInputError, match="already exists; resume it"):
        store.create_campaign("c1", "other", b"other")
    assert store.campaign("c1") == ("synth", b"config-bytes", "running")
    with pytest.raises(HysidInputError, match=r"no campaign 'c9' to resume.*c1"):
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
    row = lambda i: [i, 1.0, 10 * i, 0.1 * i]
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
    with pytest.raises(HysidInputError, match=r"notes\.sqlite: not a usable campaign database"):
        Store(bad)
    assert bad.read_text().startswith("these are my notes")


def side_files(db) -> list:
    """The database file and every file SQLite and the store keep beside it."""
    return [p for p in (db.parent / f"{db.name}{s}" for s in ("", "-wal", "-shm", "-reserve")) if p.exists()]


def test_a_new_database_its_side_files_and_its_keys_are_owner_only_and_it_holds_no_key(tmp_path):
    """The database, its WAL, shared memory and reserve are created 0600 (SQLite would make them 0644), the campaign's
    keys go to an owner-only key file that a resumed coordinator reads, and no byte of them is in the database."""
    from coordinator.keys import CampaignKeys, key_path
    from coordinator.state import Coordinator, resume
    from hysid_model.synth import synth_loops
    from island.config import CampaignConfig

    loops = synth_loops(n_points=20)
    db = tmp_path / "c.sqlite"
    c = Coordinator(Store(db), CampaignConfig.create(loops, name="c1"), loops)
    c.store.add_history("c1", "a", "r", np.array([[0, 1.0, 10, 0.1]]))
    c.store.commit("c1", 1.0)
    keys = CampaignKeys.read(key_path(db, "c1"), "c1")
    assert keys == c.keys and keys.secret == c.secret
    files = side_files(db) + [key_path(db, "c1")]
    assert {p.name for p in files} == {"c.sqlite", "c.sqlite-wal", "c.sqlite-shm", "c.sqlite-reserve", "c.sqlite-c1.keys"}
    assert {oct(p.stat().st_mode & 0o777) for p in files} == {"0o600"}
    for p in side_files(db):
        data = p.read_bytes()
        assert all(k not in data and k.hex().encode() not in data for k in (keys.admission, keys.signing, keys.members)), p
    c.store.close()
    again = resume(Store(db), "c1")
    assert again.keys == keys  # --resume signs with the same key: its islands can be taken up
    again.store.close()


def test_a_database_that_still_holds_keys_has_them_moved_out_when_opened_for_writing(tmp_path):
    """A database of an earlier hysid kept the admission secret and the coordinator's private key in its ``secrets``
    table: read-only it warns; opened for writing they move to an owner-only key file, and neither the database nor
    its journal holds a byte of them afterwards (the table dropped, the file vacuumed)."""
    import sqlite3

    from coordinator.keys import CampaignKeys, key_path
    from hysid_model.errors import HysidWarning

    db = tmp_path / "old.sqlite"
    admission, signing = os.urandom(32), os.urandom(32)
    con = sqlite3.connect(db)
    con.execute("PRAGMA journal_mode=WAL")
    con.execute(
        "CREATE TABLE campaigns (name TEXT PRIMARY KEY, dataset TEXT NOT NULL, config BLOB NOT NULL, created REAL NOT NULL, "
        "status TEXT NOT NULL, stop_reason TEXT, ended REAL, result TEXT)"
    )
    con.execute("CREATE TABLE secrets (campaign TEXT PRIMARY KEY, campaign_key BLOB NOT NULL, admission BLOB, signing BLOB)")
    con.execute("INSERT INTO campaigns VALUES ('old', 'synth', x'00', 0, 'stopped', 'budget', 1, NULL)")
    con.execute("INSERT INTO secrets VALUES ('old', ?, ?, ?)", (os.urandom(32), admission, signing))
    con.commit()
    con.close()
    assert admission in db.read_bytes()  # where an earlier hysid left it, for anyone who could read the file
    with pytest.warns(HysidWarning, match="still holds campaign keys"):
        Store.read_only(db).close()
    Store(db).close()
    moved = CampaignKeys.read(key_path(db, "old"), "old")
    assert (moved.admission, moved.signing) == (admission, signing) and len(moved.members) == 32  # and a members' key
    assert oct(key_path(db, "old").stat().st_mode & 0o777) == "0o600"
    for p in side_files(db):
        data = p.read_bytes()
        assert all(k not in data and k.hex().encode() not in data for k in (admission, signing)), p
    reader = Store.read_only(db)  # no warning any more
    assert not has_table(reader.db, "secrets") and reader.campaign_list()[0]["name"] == "old"
    reader.close()


def columns(db: sqlite3.Connection) -> dict[str, list[tuple]]:
    """Every table's columns as SQLite declares them: position, name, type, NOT NULL, default, primary key."""
    tables = [t for (t,) in db.execute("SELECT name FROM sqlite_master WHERE type = 'table' ORDER BY name")]
    return {t: db.execute(f"PRAGMA table_info({t})").fetchall() for t in tables}


def test_a_database_of_an_earlier_hysid_gets_the_columns_added_since_as_a_new_one_has_them(tmp_path):
    """A database written before the columns of UPGRADES were added (today's tables without them) gets each, on open,
    with the type, NOT NULL and default a new database declares, and the rows it held keep their values."""
    old = sqlite3.connect(tmp_path / "old.sqlite")
    old.executescript(SCHEMA)
    for table, column in UPGRADES:
        old.execute(f"ALTER TABLE {table} DROP COLUMN {column}")
    old.execute("INSERT INTO commits (campaign, t) VALUES ('old', 5.0)")
    old.commit()
    assert all(column not in {c[1] for c in columns(old)[table]} for table, column in UPGRADES)
    old.close()
    upgraded, new = Store(tmp_path / "old.sqlite"), Store(tmp_path / "new.sqlite")
    assert columns(upgraded.db) == columns(new.db)
    assert upgraded.db.execute("SELECT campaign, t, elapsed_s, pid, host FROM commits").fetchall() == [("old", 5.0, 0.0, None, None)]
    upgraded.close()
    new.close()


def test_a_campaign_left_running_by_a_coordinator_that_is_gone_reads_interrupted(tmp_path):
    """A coordinator that could not mark its campaign interrupted (its database locked) leaves it 'running': as soon as
    its process is gone (on this host), or its heartbeat is older than the lease (elsewhere), the database reads
    interrupted, and why; while its process runs it reads running."""
    import subprocess
    import sys

    from coordinator.queries import COORDINATOR_LEASE_S
    from hysid.cli.campaign import resumed_from

    store = Store(tmp_path / "c.sqlite")
    store.create_campaign("c1", "synth", b"config")
    store.commit("c1", 3.0)  # this process' heartbeat: it runs
    assert store.state("c1") == ("running", None) and store.gone_since("c1") is None
    with pytest.raises(HysidInputError, match=r"campaign 'c1' is running \(its coordinator is alive, its heartbeat 0 s ago\); stop it first"):
        resumed_from(store, "c1")  # --resume: two coordinators of one campaign would each think it theirs
    ended = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True, check=True)
    store.db.execute("UPDATE commits SET pid = ?", (int(ended.stdout),))  # the heartbeat of a coordinator process that ended
    store.db.commit()
    status, reason = store.state("c1")
    assert (
        status == "interrupted"
        and reason.startswith("interrupted: its coordinator is gone (last heartbeat ")
        and reason.endswith("and left the campaign running")
    )
    store.db.execute("UPDATE commits SET pid = ?, host = 'elsewhere', t = t - ?", (os.getpid(), COORDINATOR_LEASE_S + 1))  # another host's, stale
    store.db.commit()
    assert store.state("c1")[0] == "interrupted"
    assert resumed_from(store, "c1").startswith("hysid: resuming campaign 'c1', interrupted (its coordinator is gone (last heartbeat ")
    store.set_status("c1", "stopped", "budget")
    assert store.state("c1") == ("stopped", "budget")
