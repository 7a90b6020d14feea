"""The campaign database (SQLite): what a coordinator must not lose.

One file holds any number of campaigns. Tables: ``campaigns`` (configuration
message with the loop set, status, stop reason, final result), ``members``
(join / leave / lost / back events), ``history`` (the islands' convergence
rows, keyed by island, run and iteration so that a row sent twice is stored
once), ``thinned`` (the stretches of a run's history whose rows the coordinator
did not keep, over capacity, and how many: :mod:`coordinator.thinning`),
``islands`` (each island run's algorithm, evaluations and migration
counters), ``migrations`` (every migrant message handled), ``superseded``
(per island, migrant messages a newer one replaced before they were handled),
``unfollowed`` (when, with how many islands alive, the coordinator stopped
following migrant messages: :data:`coordinator.state.FOLLOWS_MIGRANTS_UP_TO`),
``rejected`` (every message that failed validation, with the reason) and
``best`` (the global best, as re-evaluated by the coordinator).

History rows, island records and thinned stretches are written in batches
(:meth:`Store.queue_history` and its siblings, one ``executemany`` each at
:meth:`Store.flush`), the rest as it comes. The journal is WAL with
``synchronous=NORMAL``; the coordinator commits (flushing first) at least every
half second, so a crash (or kill) of the coordinator process loses nothing it
has committed and ``--resume`` carries on from the file (only a power loss of
the machine may drop the last commits).
"""

from __future__ import annotations

import functools
import json
import os
import sqlite3
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from hysid_model.errors import HysidInputError
from island.share import Move

T = TypeVar("T")
Span = tuple[int, int]
"""Iterations ``first..last`` of an island run (both included)."""

SCHEMA = """
CREATE TABLE IF NOT EXISTS campaigns (
    name TEXT PRIMARY KEY, dataset TEXT NOT NULL, config BLOB NOT NULL, created REAL NOT NULL,
    status TEXT NOT NULL, stop_reason TEXT, ended REAL, result TEXT);
CREATE TABLE IF NOT EXISTS members (
    id INTEGER PRIMARY KEY, campaign TEXT NOT NULL, island TEXT NOT NULL, event TEXT NOT NULL, t REAL NOT NULL);
CREATE TABLE IF NOT EXISTS history (
    campaign TEXT NOT NULL, island TEXT NOT NULL, run TEXT NOT NULL, iteration INTEGER NOT NULL,
    best_fitness REAL NOT NULL, evaluations INTEGER NOT NULL, wall_s REAL NOT NULL, t REAL NOT NULL,
    PRIMARY KEY (campaign, island, run, iteration));
CREATE TABLE IF NOT EXISTS islands (
    campaign TEXT NOT NULL, island TEXT NOT NULL, run TEXT NOT NULL, algo TEXT NOT NULL, seed INTEGER NOT NULL,
    iterations INTEGER NOT NULL, evaluations INTEGER NOT NULL, best_fitness REAL NOT NULL, best_x BLOB NOT NULL,
    sent INTEGER NOT NULL, received INTEGER NOT NULL, taken INTEGER NOT NULL, rejected INTEGER NOT NULL,
    final INTEGER NOT NULL, PRIMARY KEY (campaign, island, run));
CREATE TABLE IF NOT EXISTS migrations (
    id INTEGER PRIMARY KEY, campaign TEXT NOT NULL, island TEXT NOT NULL, run TEXT NOT NULL,
    iteration INTEGER NOT NULL, n INTEGER NOT NULL, best_claimed REAL NOT NULL, sent_at REAL NOT NULL, t REAL NOT NULL,
    seq INTEGER);
CREATE TABLE IF NOT EXISTS rejected (
    id INTEGER PRIMARY KEY, campaign TEXT NOT NULL, key TEXT NOT NULL, reason TEXT NOT NULL,
    detail TEXT NOT NULL, size INTEGER NOT NULL, t REAL NOT NULL, n INTEGER NOT NULL DEFAULT 1);
CREATE TABLE IF NOT EXISTS best (
    campaign TEXT PRIMARY KEY, island TEXT NOT NULL, x BLOB NOT NULL, fitness REAL NOT NULL,
    evaluations INTEGER NOT NULL, t REAL NOT NULL);
CREATE TABLE IF NOT EXISTS runs (
    campaign TEXT NOT NULL, island TEXT NOT NULL, run TEXT NOT NULL, key BLOB NOT NULL, algo TEXT NOT NULL,
    seed INTEGER NOT NULL, joined REAL NOT NULL, PRIMARY KEY (campaign, island, run));
CREATE TABLE IF NOT EXISTS moves (
    id INTEGER PRIMARY KEY, campaign TEXT NOT NULL, island TEXT NOT NULL, run TEXT NOT NULL, src TEXT NOT NULL,
    dst TEXT NOT NULL, evaluations INTEGER NOT NULL, credit TEXT NOT NULL, t REAL NOT NULL);
CREATE TABLE IF NOT EXISTS secrets (campaign TEXT PRIMARY KEY, campaign_key BLOB NOT NULL, admission BLOB, signing BLOB);
CREATE TABLE IF NOT EXISTS commits (campaign TEXT PRIMARY KEY, t REAL NOT NULL, elapsed_s REAL NOT NULL DEFAULT 0);
CREATE TABLE IF NOT EXISTS thinned (
    campaign TEXT NOT NULL, island TEXT NOT NULL, run TEXT NOT NULL, first INTEGER NOT NULL, last INTEGER NOT NULL,
    rows INTEGER NOT NULL, t REAL NOT NULL);
CREATE TABLE IF NOT EXISTS superseded (
    campaign TEXT NOT NULL, island TEXT NOT NULL, messages INTEGER NOT NULL, PRIMARY KEY (campaign, island));
CREATE TABLE IF NOT EXISTS unfollowed (campaign TEXT PRIMARY KEY, islands INTEGER NOT NULL, up_to INTEGER NOT NULL, t REAL NOT NULL);
"""
UPGRADES = (
    ("migrations", "seq", "ALTER TABLE migrations ADD COLUMN seq INTEGER"),
    ("rejected", "n", "ALTER TABLE rejected ADD COLUMN n INTEGER NOT NULL DEFAULT 1"),
    ("secrets", "admission", "ALTER TABLE secrets ADD COLUMN admission BLOB"),
    ("secrets", "signing", "ALTER TABLE secrets ADD COLUMN signing BLOB"),
    ("commits", "elapsed_s", "ALTER TABLE commits ADD COLUMN elapsed_s REAL NOT NULL DEFAULT 0"),
)
"""Columns added since the first schema: a database written by an earlier hysid gets them on open."""
INDEXES = """
CREATE UNIQUE INDEX IF NOT EXISTS migration_once ON migrations (campaign, island, run, seq);
CREATE INDEX IF NOT EXISTS thinned_runs ON thinned (campaign, island, run, first);
"""
"""A migrant message (sender run and number) is stored once, also when it is replayed after a restart; a run's
thinned stretches are found in order."""
LOCK_WAIT_S = 10.0
"""How long a write waits for another process' lock on the database before it fails (when it opens)."""
RUN_LOCK_WAIT_S = 2.0
"""The same once a campaign runs (:meth:`Store.set_lock_wait`): a database locked by another process
mid-run is a fault found within seconds, not a stall."""
COORDINATOR_LEASE_S = 10.0
"""A campaign not stopped whose coordinator committed nothing for this long has lost its coordinator: a running one
commits at least every :data:`coordinator.loop.COMMIT_EVERY_S` (stamping ``commits``) and waits at most
:data:`RUN_LOCK_WAIT_S` for a lock (as long as Zenoh's lease of a silent peer)."""
RESERVE_BYTES = 256 << 10
"""Disk space held next to the database (``<db>-reserve``) and given back when the disk is full, so
that the campaign can still be marked interrupted (plus twice its configuration message: SQLite
rewrites the whole campaign row, loop set included, when its status changes)."""


UPSERT_ISLAND = """INSERT INTO islands VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)
    ON CONFLICT (campaign, island, run) DO UPDATE SET
    algo = CASE WHEN excluded.iterations >= iterations THEN excluded.algo ELSE algo END,
    iterations = max(iterations, excluded.iterations), evaluations = max(evaluations, excluded.evaluations),
    best_x = CASE WHEN excluded.best_fitness < best_fitness THEN excluded.best_x ELSE best_x END,
    best_fitness = min(best_fitness, excluded.best_fitness), sent = max(sent, excluded.sent),
    received = max(received, excluded.received), taken = max(taken, excluded.taken),
    rejected = max(rejected, excluded.rejected), final = max(final, excluded.final)"""
"""An island run's record: counters only grow, the best vector follows the best fitness (messages may come late)."""


def _identity(path: str) -> tuple[int, int]:
    info = os.stat(path)
    return info.st_dev, info.st_ino


def prepare(db: sqlite3.Connection) -> None:
    """Create the tables, and add to a database of an earlier hysid the columns it lacks."""
    db.executescript(SCHEMA)
    for table, column, upgrade in UPGRADES:
        if column not in {row[1] for row in db.execute(f"PRAGMA table_info({table})")}:
            db.execute(upgrade)
    db.executescript(INDEXES)


def merged(spans: list[Span]) -> list[Span]:
    """Spans of iterations joined where they overlap or touch, in order."""
    out: list[list[int]] = []
    for first, last in sorted(spans):
        if out and first <= out[-1][1] + 1:
            out[-1][1] = max(out[-1][1], last)
        else:
            out.append([first, last])
    return [(a, b) for a, b in out]


class StoreError(HysidInputError):
    """A campaign database that cannot be written (locked, full, read-only, deleted): one line naming the file."""


def _writes(method: Callable[..., T]) -> Callable[..., T]:
    """Turn SQLite's failures of a write into a :class:`StoreError` naming the file."""

    @functools.wraps(method)
    def guarded(self: "Store", *args: Any, **kwargs: Any) -> T:
        try:
            return method(self, *args, **kwargs)
        except sqlite3.Error as exc:
            raise StoreError(f"cannot write the campaign database {self.path}: {exc}") from None

    return guarded


@dataclass(frozen=True)
class StoredBest:
    island: str
    x: np.ndarray
    fitness: float
    evaluations: int
    """Total campaign evaluations when this best was found (for the stall rule)."""


@dataclass(frozen=True)
class IslandRecord:
    island: str
    run: str
    algo: str
    seed: int
    iterations: int
    evaluations: int
    best_fitness: float
    best_x: np.ndarray
    sent: int
    received: int
    taken: int
    rejected: int
    final: bool

    def as_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__ if k != "best_x"}


class Store:
    """A campaign database file (``":memory:"`` for a throw-away one)."""

    def __init__(self, path: Path | str, lock_wait_s: float = LOCK_WAIT_S) -> None:
        """Open (or create) the database and check that it can be written, before any work starts."""
        self.path = str(path)
        try:
            if self.path != ":memory:":
                Path(self.path).parent.mkdir(parents=True, exist_ok=True)
            self.db = sqlite3.connect(self.path, check_same_thread=False, timeout=lock_wait_s)
            self.db.execute("PRAGMA journal_mode=WAL")
            self.db.execute("PRAGMA synchronous=NORMAL")
            prepare(self.db)
            self.db.execute("BEGIN IMMEDIATE")  # the write lock: fails now if the file cannot be written
            self.db.execute("ROLLBACK")
            self.reserve = None if self.path == ":memory:" else Path(f"{self.path}-reserve")
            self.hold(0)
            self.identity = None if self.path == ":memory:" else _identity(self.path)
            self._pending()
        except (sqlite3.DatabaseError, OSError) as exc:
            raise HysidInputError(f"{self.path}: not a usable campaign database ({exc})") from None

    def _pending(self) -> None:
        """Nothing waits for the next :meth:`flush`."""
        self._rows: list[tuple[str, str, str, np.ndarray]] = []
        self._records: list[tuple[Any, ...]] = []
        self._thinned: list[tuple[Any, ...]] = []
        self.pending_rows = 0
        """History rows queued for the next flush."""

    def set_lock_wait(self, seconds: float) -> None:
        """How long a write waits for another process' lock from now on."""
        self.db.execute(f"PRAGMA busy_timeout = {int(seconds * 1000)}")

    def check_file(self) -> None:
        """:class:`StoreError` if the database file was deleted or replaced since it was opened (SQLite
        would go on writing to the deleted file, and everything would be lost when the process ends)."""
        if self.identity is not None:
            try:
                same = _identity(self.path) == self.identity
            except FileNotFoundError:
                raise StoreError(f"cannot write the campaign database {self.path}: the file was deleted") from None
            if not same:
                raise StoreError(f"cannot write the campaign database {self.path}: the file was replaced by another")

    def hold(self, row_bytes: int) -> None:
        """Hold :data:`RESERVE_BYTES` plus twice ``row_bytes`` of disk space in the reserve file."""
        if self.reserve is not None:
            with open(self.reserve, "wb") as f:
                f.write(bytes(RESERVE_BYTES + 2 * row_bytes))
                f.flush()
                os.fsync(f.fileno())

    @classmethod
    def read_only(cls, path: Path | str) -> "Store":
        """A campaign database opened for reading only (never written, never created), also while a
        coordinator writes it: WAL lets readers see every committed batch without blocking the writer."""
        path = Path(path)
        if not path.is_file():
            raise HysidInputError(f"{path}: no such campaign database")
        try:
            db = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True, check_same_thread=False, timeout=10.0)
            db.execute("SELECT count(*) FROM campaigns").fetchone()
        except sqlite3.DatabaseError as exc:
            raise HysidInputError(f"{path}: not a campaign database ({exc})") from None
        store = cls.__new__(cls)
        store.path, store.db, store.reserve, store.identity = str(path), db, None, None
        store._pending()
        return store

    @classmethod
    def snapshot(cls, path: Path | str) -> "Store":
        """An in-memory copy of a campaign database, read (only) from the file at one committed moment:
        a stored campaign can be taken up again in it without changing the file."""
        source = cls.read_only(path)
        copy = sqlite3.connect(":memory:", check_same_thread=False)
        try:
            source.db.backup(copy)
        finally:
            source.db.close()
        prepare(copy)  # a database of an earlier hysid gets today's tables, in the copy only
        store = cls.__new__(cls)
        store.path, store.db, store.reserve, store.identity = source.path, copy, None, None
        store._pending()
        return store

    def release_reserve(self) -> None:
        """Give the reserved disk space back (when the disk is full: room for the last status)."""
        if self.reserve is not None:
            self.reserve.unlink(missing_ok=True)

    def close(self) -> None:
        """Commit and close; a commit that fails here is reported, the file keeps what was committed (a
        file deleted meanwhile was reported by the commit that found it)."""
        try:
            self._commit()
        finally:
            self.db.close()
            self.release_reserve()

    @_writes
    def _commit(self) -> None:
        self.flush()
        self.db.commit()

    @_writes
    def flush(self) -> int:
        """Write what is queued (one ``executemany`` for each table), in the open transaction; returns the
        history rows that were new. Each row's ``t`` is now: when it was written."""
        now = time.time()
        before = self.db.total_changes
        if self._rows:
            self.db.executemany(
                "INSERT OR IGNORE INTO history VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                [(c, i, r, int(it), f, int(ev), w, now) for c, i, r, rows in self._rows for it, f, ev, w in rows.tolist()],
            )
        written = self.db.total_changes - before
        if self._records:
            self.db.executemany(UPSERT_ISLAND, self._records)
        if self._thinned:
            self.db.executemany("INSERT INTO thinned VALUES (?, ?, ?, ?, ?, ?, ?)", [(*t, now) for t in self._thinned])
        self._pending()
        return written

    @_writes
    def commit(self, campaign: str | None = None, elapsed_s: float = 0.0) -> None:
        """Commit (what is queued first); with ``campaign``, stamp the time and the campaign's elapsed seconds
        in ``commits`` first (how old the last commit is tells what a kill right now would lose; the elapsed
        time is where ``--resume`` carries the time rule on). A file deleted meanwhile is a :class:`StoreError`."""
        self.check_file()
        self.flush()
        if campaign is not None:
            self.db.execute("INSERT OR REPLACE INTO commits (campaign, t, elapsed_s) VALUES (?, ?, ?)", (campaign, time.time(), elapsed_s))
        self.db.commit()

    def elapsed(self, campaign: str) -> float:
        """Seconds the campaign has run, by its last commit (0 before one)."""
        row = self.db.execute("SELECT elapsed_s FROM commits WHERE campaign = ?", (campaign,)).fetchone()
        return 0.0 if row is None else float(row[0])

    def last_commit(self, campaign: str) -> float | None:
        """Unix time of the campaign's last stamped commit (None before its coordinator's first pass)."""
        try:
            row = self.db.execute("SELECT t FROM commits WHERE campaign = ?", (campaign,)).fetchone()
        except sqlite3.OperationalError:  # no commits table: an earlier hysid's database
            return None
        return None if row is None else float(row[0])

    def gone_since(self, campaign: str, lease_s: float = COORDINATOR_LEASE_S) -> float | None:
        """Unix time of the last sign of life of a campaign's coordinator (its last commit, else the campaign's
        creation) if the campaign did not stop and nothing was committed for ``lease_s``: its coordinator is gone
        (killed, or its machine). None while it commits, once the campaign stopped, and for a database of a hysid
        that stamped no commits."""
        try:
            status, created, last = self.db.execute(
                "SELECT status, created, t FROM campaigns LEFT JOIN commits ON commits.campaign = campaigns.name WHERE name = ?", (campaign,)
            ).fetchone()
        except sqlite3.OperationalError:  # no commits table: an earlier hysid's database
            return None
        seen = created if last is None else last
        return seen if status != "stopped" and time.time() - seen > lease_s else None

    def rollback(self) -> None:
        """Drop what was not committed (after a failed write), queued or written."""
        self._pending()
        try:
            self.db.rollback()
        except sqlite3.Error:
            pass

    # --- campaigns --------------------------------------------------------------
    def has_campaign(self, name: str) -> bool:
        return self.db.execute("SELECT 1 FROM campaigns WHERE name = ?", (name,)).fetchone() is not None

    @_writes
    def create_campaign(self, name: str, dataset: str, config: bytes) -> None:
        """Register a new campaign; an existing one is never overwritten."""
        if self.has_campaign(name):
            raise HysidInputError(f"{self.path}: campaign {name!r} already exists; resume it, or choose another campaign name or database")
        self.db.execute(
            "INSERT INTO campaigns (name, dataset, config, created, status) VALUES (?, ?, ?, ?, 'running')",
            (name, dataset, config, time.time()),
        )
        self.db.commit()

    def campaign(self, name: str) -> tuple[str, bytes, str]:
        """``(dataset, config message, status)`` of a stored campaign."""
        row = self.db.execute("SELECT dataset, config, status FROM campaigns WHERE name = ?", (name,)).fetchone()
        if row is None:
            known = [r[0] for r in self.db.execute("SELECT name FROM campaigns ORDER BY created")]
            raise HysidInputError(f"{self.path}: no campaign {name!r} to resume (stored: {', '.join(known) or 'none'})")
        return row[0], bytes(row[1]), row[2]

    @_writes
    def set_status(self, name: str, status: str, reason: str | None = None) -> None:
        self.check_file()
        self.db.execute(
            "UPDATE campaigns SET status = ?, stop_reason = ?, ended = ? WHERE name = ?",
            (status, reason, time.time() if status != "running" else None, name),
        )
        self.db.commit()

    @_writes
    def set_result(self, name: str, result_json: str) -> None:
        """The final result document (the JSON of ``hysid campaign --json``)."""
        self.db.execute("UPDATE campaigns SET result = ? WHERE name = ?", (result_json, name))
        self.db.commit()

    def result(self, name: str) -> dict[str, Any] | None:
        row = self.db.execute("SELECT result FROM campaigns WHERE name = ?", (name,)).fetchone()
        return None if row is None or row[0] is None else json.loads(row[0])

    def stop_reason(self, name: str) -> str | None:
        row = self.db.execute("SELECT stop_reason FROM campaigns WHERE name = ?", (name,)).fetchone()
        return None if row is None else row[0]

    # --- records as messages arrive (committed by the caller per batch) ------------------
    @_writes
    def member_event(self, campaign: str, island: str, event: str) -> None:
        self.db.execute("INSERT INTO members (campaign, island, event, t) VALUES (?, ?, ?, ?)", (campaign, island, event, time.time()))

    def queue_history(self, campaign: str, island: str, run: str, rows: np.ndarray) -> None:
        """Rows ``[iteration, best_fitness, evaluations, wall_s]`` of an island run, for the next :meth:`flush`
        (a row already stored is stored once)."""
        if rows.size:
            self._rows.append((campaign, island, run, np.asarray(rows, dtype=float).reshape(-1, 4)))
            self.pending_rows += rows.shape[0]

    def add_history(self, campaign: str, island: str, run: str, rows: np.ndarray) -> int:
        """Store rows now (with what else is queued); returns how many were new."""
        self.queue_history(campaign, island, run, rows)
        return self.flush()

    def queue_thinned(self, campaign: str, island: str, run: str, span: Span, rows: int) -> None:
        """``rows`` rows of iterations ``span`` of an island run that the coordinator handled and did not keep."""
        self._thinned.append((campaign, island, run, span[0], span[1], rows))

    def queue_island(self, campaign: str, record: IslandRecord) -> None:
        """Upsert an island run's counters (iterations and evaluations only grow) and its latest algorithm, at the next flush."""
        r = record
        self._records.append((campaign, r.island, r.run, r.algo, r.seed, r.iterations, r.evaluations, r.best_fitness,
                              np.asarray(r.best_x, dtype="<f8").tobytes(), r.sent, r.received, r.taken, r.rejected, int(r.final)))

    def update_island(self, campaign: str, record: IslandRecord) -> None:
        """:meth:`queue_island`, written now."""
        self.queue_island(campaign, record)
        self.flush()

    @_writes
    def add_superseded(self, campaign: str, counts: dict[str, int]) -> None:
        """Migrant messages of each island that a newer one replaced before the coordinator handled them."""
        self.db.executemany(
            "INSERT INTO superseded VALUES (?, ?, ?) ON CONFLICT (campaign, island) DO UPDATE SET messages = messages + excluded.messages",
            [(campaign, island, n) for island, n in counts.items()],
        )

    @_writes
    def set_unfollowed(self, campaign: str, islands: int, up_to: int) -> None:
        """The coordinator stopped following migrant messages with ``islands`` alive, following those of at most
        ``up_to`` (the first time is kept)."""
        self.db.execute("INSERT OR IGNORE INTO unfollowed VALUES (?, ?, ?, ?)", (campaign, islands, up_to, time.time()))

    @_writes
    def add_migration(
        self, campaign: str, island: str, run: str, iteration: int, n: int, best_claimed: float, sent_at: float, seq: int
    ) -> bool:
        """Record a migrant message; False if this sender run's message ``seq`` is already stored (a replay)."""
        before = self.db.total_changes
        self.db.execute(
            "INSERT OR IGNORE INTO migrations (campaign, island, run, iteration, n, best_claimed, sent_at, t, seq) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (campaign, island, run, iteration, n, best_claimed, sent_at, time.time(), seq),
        )
        return self.db.total_changes > before

    @_writes
    def add_rejected(self, campaign: str, key: str, reason: str, detail: str, size: int, n: int = 1) -> None:
        """Record ``n`` rejected messages (n > 1: a summary of those not recorded one by one)."""
        self.db.execute(
            "INSERT INTO rejected (campaign, key, reason, detail, size, t, n) VALUES (?, ?, ?, ?, ?, ?, ?)",
            (campaign, key[:200], reason, detail[:300], size, time.time(), n),
        )

    # --- who joined ---------------------------------------------------------------------
    @_writes
    def campaign_secrets(self, campaign: str, admission: bytes, signing: bytes) -> tuple[bytes, bytes]:
        """The campaign's admission secret and the coordinator's private signing key: stored once (the
        given ones the first time; a campaign of an earlier hysid gets them on its first resume)."""
        self.db.execute("INSERT OR IGNORE INTO secrets (campaign, campaign_key) VALUES (?, x'')", (campaign,))
        self.db.execute("UPDATE secrets SET admission = coalesce(admission, ?), signing = coalesce(signing, ?) WHERE campaign = ?",
                        (admission, signing, campaign))
        row = self.db.execute("SELECT admission, signing FROM secrets WHERE campaign = ?", (campaign,)).fetchone()
        return bytes(row[0]), bytes(row[1])

    @_writes
    def add_run(self, campaign: str, island: str, run: str, key: bytes, algo: str, seed: int, joined: float) -> None:
        """A run admitted, with the public key it signs with and when it joined (Unix time)."""
        self.db.execute("INSERT INTO runs VALUES (?, ?, ?, ?, ?, ?, ?)", (campaign, island, run, key, algo, seed, joined))

    @_writes
    def add_move(self, campaign: str, move: Move) -> None:
        """An island run the share of a mixed campaign moved to another algorithm (:mod:`island.share`)."""
        self.db.execute(
            "INSERT INTO moves (campaign, island, run, src, dst, evaluations, credit, t) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
            (campaign, move.island, move.run, move.src, move.dst, move.evaluations, json.dumps(move.credit), time.time()),
        )

    def moves(self, campaign: str) -> list[Move]:
        """The moves of the campaign in the order they were made."""
        rows = self.db.execute("SELECT island, run, src, dst, evaluations, credit FROM moves WHERE campaign = ? ORDER BY id", (campaign,))
        return [Move(i, r, a, b, int(e), json.loads(c)) for i, r, a, b, e, c in rows]

    def runs(self, campaign: str) -> list[tuple[str, str, bytes, str, int, float]]:
        """Every run that joined: ``(island, run, public key, algo, seed, joined)`` in the order they joined."""
        rows = self.db.execute("SELECT island, run, key, algo, seed, joined FROM runs WHERE campaign = ? ORDER BY joined", (campaign,))
        return [(i, r, bytes(k), a, s, float(j)) for i, r, k, a, s, j in rows]

    @_writes
    def set_best(self, campaign: str, best: StoredBest) -> None:
        self.db.execute(
            "INSERT OR REPLACE INTO best VALUES (?, ?, ?, ?, ?, ?)",
            (campaign, best.island, np.asarray(best.x, dtype="<f8").tobytes(), best.fitness, best.evaluations, time.time()),
        )

    # --- queries -------------------------------------------------------------------
    def best(self, campaign: str) -> StoredBest | None:
        row = self.db.execute("SELECT island, x, fitness, evaluations FROM best WHERE campaign = ?", (campaign,)).fetchone()
        if row is None:
            return None
        return StoredBest(row[0], np.frombuffer(row[1], dtype="<f8").copy(), float(row[2]), int(row[3]))

    def islands(self, campaign: str) -> list[IslandRecord]:
        rows = self.db.execute(
            "SELECT island, run, algo, seed, iterations, evaluations, best_fitness, best_x, sent, received, taken, rejected, final "
            "FROM islands WHERE campaign = ? ORDER BY island, run", (campaign,),
        )
        return [
            IslandRecord(*r[:7], np.frombuffer(r[7], dtype="<f8").copy(), *r[8:12], bool(r[12]))
            for r in rows
        ]

    def total_evaluations(self, campaign: str) -> int:
        return int(self.db.execute("SELECT coalesce(sum(evaluations), 0) FROM islands WHERE campaign = ?", (campaign,)).fetchone()[0])

    def handled(self, campaign: str, island: str, run: str) -> list[Span]:
        """The iterations of an island run the coordinator handled, stored or thinned, as disjoint sorted spans."""
        where = "campaign = ? AND island = ? AND run = ?"
        key = (campaign, island, run)
        starts = self.db.execute(f"""SELECT iteration FROM history h WHERE {where} AND NOT EXISTS (SELECT 1 FROM history g WHERE
            g.campaign = h.campaign AND g.island = h.island AND g.run = h.run AND g.iteration = h.iteration - 1) ORDER BY iteration""", key)
        ends = self.db.execute(f"""SELECT iteration FROM history h WHERE {where} AND NOT EXISTS (SELECT 1 FROM history g WHERE
            g.campaign = h.campaign AND g.island = h.island AND g.run = h.run AND g.iteration = h.iteration + 1) ORDER BY iteration""", key)
        spans = list(zip((s for (s,) in starts.fetchall()), (e for (e,) in ends.fetchall())))
        if self._has("thinned"):
            spans += self.db.execute(f"SELECT first, last FROM thinned WHERE {where}", key).fetchall()
        return merged(spans)

    def thinned(self, campaign: str) -> dict[tuple[str, str], int]:
        """History rows the coordinator did not keep, per island run."""
        if not self._has("thinned"):
            return {}
        rows = self.db.execute("SELECT island, run, sum(rows) FROM thinned WHERE campaign = ? GROUP BY island, run", (campaign,))
        return {(i, r): int(n) for i, r, n in rows}

    def superseded(self, campaign: str) -> int:
        """Migrant messages a newer one of the same island replaced before the coordinator handled them."""
        if not self._has("superseded"):
            return 0
        return int(self.db.execute("SELECT coalesce(sum(messages), 0) FROM superseded WHERE campaign = ?", (campaign,)).fetchone()[0])

    def unfollowed(self, campaign: str) -> dict[str, Any] | None:
        """When the coordinator stopped following migrant messages: ``islands`` alive then, the rule's ``up_to``
        and the Unix time ``t`` (None: it never did)."""
        if not self._has("unfollowed"):
            return None
        row = self.db.execute("SELECT islands, up_to, t FROM unfollowed WHERE campaign = ?", (campaign,)).fetchone()
        return None if row is None else {"islands": int(row[0]), "up_to": int(row[1]), "t": float(row[2])}

    def _has(self, table: str) -> bool:
        """Whether the file has ``table`` (a file of an earlier hysid opened read-only may lack it)."""
        return self.db.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", (table,)).fetchone() is not None

    def history(self, campaign: str) -> list[tuple[str, str, int, float, int, float]]:
        """All rows ``(island, run, iteration, best_fitness, evaluations, wall_s)``."""
        return self.db.execute(
            "SELECT island, run, iteration, best_fitness, evaluations, wall_s FROM history WHERE campaign = ? ORDER BY island, run, iteration",
            (campaign,),
        ).fetchall()

    def members(self, campaign: str) -> list[tuple[str, str, float]]:
        """Membership events ``(island, event, unix time)`` in order."""
        return self.db.execute("SELECT island, event, t FROM members WHERE campaign = ? ORDER BY id", (campaign,)).fetchall()

    def campaign_list(self) -> list[dict[str, Any]]:
        """Every stored campaign, oldest first: name, dataset, status, stop reason, created and ended (unix time)."""
        rows = self.db.execute("SELECT name, dataset, status, stop_reason, created, ended FROM campaigns ORDER BY created")
        return [dict(zip(("name", "dataset", "status", "stop_reason", "created", "ended"), r)) for r in rows]

    def migrations_by_island(self, campaign: str) -> dict[str, int]:
        """Migrant messages the coordinator saw from each island."""
        rows = self.db.execute("SELECT island, count(*) FROM migrations WHERE campaign = ? GROUP BY island", (campaign,))
        return {island: int(n) for island, n in rows}

    def count(self, table: str, campaign: str) -> int:
        """Rows of a table (for ``rejected``: messages, summaries counting ``n``)."""
        if table not in ("migrations", "rejected", "history", "members"):
            raise ValueError(f"no countable table {table!r}")
        what = "coalesce(sum(n), 0)" if table == "rejected" and self._counted_rejects() else "count(*)"
        return int(self.db.execute(f"SELECT {what} FROM {table} WHERE campaign = ?", (campaign,)).fetchone()[0])

    def _counted_rejects(self) -> bool:
        """Whether ``rejected`` has its ``n`` column (a file of an earlier hysid opened read-only has not)."""
        return "n" in {row[1] for row in self.db.execute("PRAGMA table_info(rejected)")}

    def rejected_reasons(self, campaign: str) -> dict[str, int]:
        n = "sum(n)" if self._counted_rejects() else "count(*)"
        rows = self.db.execute(f"SELECT reason, {n} FROM rejected WHERE campaign = ? GROUP BY reason", (campaign,))
        return {r: int(n) for r, n in rows}
