"""The campaign database (SQLite): what a coordinator must not lose.

One file holds any number of campaigns (its tables: :mod:`coordinator.schema`; what it holds, read:
:mod:`coordinator.queries`). History rows, island records and thinned stretches are written in batches
(:meth:`Store.queue_history` and its siblings, one ``executemany`` each at :meth:`Store.flush`), the rest as
it comes. The journal is WAL with ``synchronous=NORMAL``; the coordinator commits (flushing first) at least
every half second, stamping its heartbeat, so a crash (or kill) of the coordinator process loses nothing it
has committed and ``--resume`` carries on from the file (only a power loss of the machine may drop the last
commits).

The file is created owner-only (mode 0600; SQLite gives its ``-wal`` and ``-shm`` files the database's
mode, and so does the reserve file here): a user who wants others to read the results makes it so with
``chmod``. It holds no key (:mod:`coordinator.keys`).
"""

from __future__ import annotations

import functools
import json
import os
import socket
import sqlite3
import stat
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from coordinator.queries import IslandRecord, Queries, Span, StoredBest
from coordinator.schema import UPSERT_ISLAND, move_keys_out, prepare
from hysid_model.errors import HysidInputError, HysidWarning
from island.share import Move

T = TypeVar("T")

LOCK_WAIT_S = 10.0
"""How long a write waits for another process' lock on the database before it fails (when it opens)."""
RUN_LOCK_WAIT_S = 2.0
"""The same once a campaign runs (:meth:`Store.set_lock_wait`): a database locked by another process
mid-run is a fault found within seconds, not a stall."""
RESERVE_BYTES = 256 << 10
"""Disk space held next to the database (``<db>-reserve``) and given back when the disk is full, so
that the campaign can still be marked interrupted (plus twice its configuration message: SQLite
rewrites the whole campaign row, loop set included, when its status changes)."""


def _create_owner_only(path: str) -> None:
    """Create an empty database file of mode 0600 (SQLite would make it 0644), unless one is there."""
    try:
        os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
    except FileExistsError:
        pass


def _identity(path: str) -> tuple[int, int]:
    info = os.stat(path)
    return info.st_dev, info.st_ino


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


class Store(Queries):
    """A campaign database file (``":memory:"`` for a throw-away one)."""

    def __init__(self, path: Path | str, lock_wait_s: float = LOCK_WAIT_S) -> None:
        """Open (or create) the database and check that it can be written, before any work starts."""
        self.path = str(path)
        try:
            if self.path != ":memory:":
                Path(self.path).parent.mkdir(parents=True, exist_ok=True)
                _create_owner_only(self.path)
            self.db = sqlite3.connect(self.path, check_same_thread=False, timeout=lock_wait_s)
            self.db.execute("PRAGMA journal_mode=WAL")
            self.db.execute("PRAGMA synchronous=NORMAL")
            prepare(self.db)
            if self.path != ":memory:":
                move_keys_out(self.db, self.path)
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
        """Hold :data:`RESERVE_BYTES` plus twice ``row_bytes`` of disk space in the reserve file (of the database's mode)."""
        if self.reserve is not None:
            with os.fdopen(os.open(self.reserve, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600), "wb") as f:
                os.fchmod(f.fileno(), stat.S_IMODE(os.stat(self.path).st_mode))
                f.write(bytes(RESERVE_BYTES + 2 * row_bytes))
                f.flush()
                os.fsync(f.fileno())

    @classmethod
    def read_only(cls, path: Path | str) -> "Store":
        """A campaign database opened for reading only (never written, never created), also while a
        coordinator writes it: WAL lets readers see every committed batch without blocking the writer. Without
        a -wal file no writer has it open, and it opens as immutable (a WAL reader would create -wal and -shm)."""
        path = Path(path)
        if not path.is_file():
            raise HysidInputError(f"{path}: no such campaign database")
        settled = "" if Path(f"{path}-wal").exists() else "&immutable=1"
        try:
            db = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro{settled}", uri=True, check_same_thread=False, timeout=10.0)
            db.execute("SELECT count(*) FROM campaigns").fetchone()
        except sqlite3.DatabaseError as exc:
            raise HysidInputError(f"{path}: not a campaign database ({exc})") from None
        store = cls.__new__(cls)
        store.path, store.db, store.reserve, store.identity = str(path), db, None, None
        store._pending()
        if store._has("secrets"):
            warnings.warn(HysidWarning(
                f"{path} still holds campaign keys (an earlier hysid kept them there): anyone who can read it can join its campaigns "
                "and sign as their coordinator; open it once with this hysid for writing (hysid coordinator --resume) to move them "
                "to owner-only key files"), stacklevel=2)
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
        """Commit (what is queued first); with ``campaign``, stamp the coordinator's heartbeat first: the time, this
        process and host, and the campaign's elapsed seconds in ``commits`` (how old the last commit is tells what a
        kill right now would lose, and a reader whether the coordinator is still there: :meth:`gone_since`; the
        elapsed time is where ``--resume`` carries the time rule on). A file deleted meanwhile is a :class:`StoreError`."""
        self.check_file()
        self.flush()
        if campaign is not None:
            self.db.execute("INSERT OR REPLACE INTO commits (campaign, t, elapsed_s, pid, host) VALUES (?, ?, ?, ?, ?)",
                            (campaign, time.time(), elapsed_s, os.getpid(), socket.gethostname()))
        self.db.commit()

    def rollback(self) -> None:
        """Drop what was not committed (after a failed write), queued or written."""
        self._pending()
        try:
            self.db.rollback()
        except sqlite3.Error:
            pass

    def check_new(self, name: str) -> None:
        """A :class:`HysidInputError` if the database holds campaign ``name`` already."""
        if self.has_campaign(name):
            raise HysidInputError(f"{self.path}: campaign {name!r} already exists; resume it, or choose another campaign name or database")

    @_writes
    def create_campaign(self, name: str, dataset: str, config: bytes) -> None:
        """Register a new campaign; an existing one is never overwritten."""
        self.check_new(name)
        self.db.execute(
            "INSERT INTO campaigns (name, dataset, config, created, status) VALUES (?, ?, ?, ?, 'running')",
            (name, dataset, config, time.time()),
        )
        self.db.commit()

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
                              np.asarray(r.best_x, dtype="<f8").tobytes(), r.sent, r.received, r.taken, r.rejected, int(r.final), r.unlisted))

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

    @_writes
    def add_run(self, campaign: str, island: str, run: str, key: bytes, algo: str, seed: int, joined: float, member: str = "") -> None:
        """A run admitted, with the public key it signs with, when it joined (Unix time) and the member it joined for."""
        self.db.execute("INSERT INTO runs (campaign, island, run, key, algo, seed, joined, member) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                        (campaign, island, run, key, algo, seed, joined, member))

    @_writes
    def add_move(self, campaign: str, move: Move) -> None:
        """An island run the share of a mixed campaign moved to another algorithm (:mod:`island.share`)."""
        self.db.execute(
            "INSERT INTO moves (campaign, island, run, src, dst, evaluations, credit, t) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
            (campaign, move.island, move.run, move.src, move.dst, move.evaluations, json.dumps(move.credit), time.time()),
        )

    @_writes
    def set_best(self, campaign: str, best: StoredBest) -> None:
        self.db.execute(
            "INSERT OR REPLACE INTO best VALUES (?, ?, ?, ?, ?, ?)",
            (campaign, best.island, np.asarray(best.x, dtype="<f8").tobytes(), best.fitness, best.evaluations, time.time()),
        )
