"""What the coordinator writes into a campaign database, and how a write that fails is told.

History rows, island records and thinned stretches are written in batches (:meth:`Writes.queue_history` and its
siblings, one ``executemany`` each at :meth:`Writes.flush`), the rest as it comes, in the open transaction that
:meth:`Writes.commit` commits, stamping the coordinator's heartbeat (``commits``: what ``hysid watch`` and
``--resume`` read, :mod:`coordinator.queries`). A write SQLite refuses (locked, full, read-only) or one into a file
deleted or replaced since it was opened is a :class:`StoreError` naming the file: the coordinator stops cleanly on it
(:mod:`coordinator.loop`).
"""

from __future__ import annotations

import functools
import json
import os
import socket
import sqlite3
import time
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

from coordinator.queries import Queries
from coordinator.records import IslandRecord, Span, StoredBest
from hysid_model.errors import HysidInputError
from island.share import Move

T = TypeVar("T")

UPSERT_ISLAND = """INSERT INTO islands (campaign, island, run, algo, seed, iterations, evaluations, best_fitness, best_x, sent, received, taken,
    rejected, final, unlisted) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)
    ON CONFLICT (campaign, island, run) DO UPDATE SET
    algo = CASE WHEN excluded.iterations >= iterations THEN excluded.algo ELSE algo END,
    iterations = max(iterations, excluded.iterations), evaluations = max(evaluations, excluded.evaluations),
    best_x = CASE WHEN excluded.best_fitness < best_fitness THEN excluded.best_x ELSE best_x END,
    best_fitness = min(best_fitness, excluded.best_fitness), sent = max(sent, excluded.sent),
    received = max(received, excluded.received), taken = max(taken, excluded.taken),
    rejected = max(rejected, excluded.rejected), final = max(final, excluded.final), unlisted = max(unlisted, excluded.unlisted)"""
"""An island run's record: counters only grow, the best vector follows the best fitness (messages may come late)."""


def file_identity(path: str) -> tuple[int, int]:
    """The device and inode of the file at ``path``: another file there has another."""
    info = os.stat(path)
    return info.st_dev, info.st_ino


class StoreError(HysidInputError):
    """A campaign database that cannot be written (locked, full, read-only, deleted): one line naming the file."""


def guarded_write(method: Callable[..., T]) -> Callable[..., T]:
    """Turn SQLite's failures of a write into a :class:`StoreError` naming the file."""

    @functools.wraps(method)
    def guarded(self: Writes, *args: Any, **kwargs: Any) -> T:
        try:
            return method(self, *args, **kwargs)
        except sqlite3.Error as exc:
            raise StoreError(f"cannot write the campaign database {self.path}: {exc}") from None

    return guarded


class Writes(Queries):
    """The writes of :class:`coordinator.store.Store` (``db``: its connection, ``path``: its file, ``identity``: the
    file's :func:`file_identity` when it was opened, None for a database in memory)."""

    identity: tuple[int, int] | None

    def _pending(self) -> None:
        """Nothing waits for the next :meth:`flush`."""
        self._rows: list[tuple[str, str, str, np.ndarray]] = []
        self._records: list[tuple[Any, ...]] = []
        self._thinned: list[tuple[Any, ...]] = []
        self.pending_rows = 0
        """History rows queued for the next flush."""

    def check_file(self) -> None:
        """:class:`StoreError` if the database file was deleted or replaced since it was opened (SQLite
        would go on writing to the deleted file, and everything would be lost when the process ends)."""
        if self.identity is not None:
            try:
                same = file_identity(self.path) == self.identity
            except FileNotFoundError:
                raise StoreError(f"cannot write the campaign database {self.path}: the file was deleted") from None
            if not same:
                raise StoreError(f"cannot write the campaign database {self.path}: the file was replaced by another")

    @guarded_write
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

    @guarded_write
    def commit(self, campaign: str | None = None, elapsed_s: float = 0.0) -> None:
        """Commit (what is queued first); with ``campaign``, stamp the coordinator's heartbeat first: the time, this
        process and host, and the campaign's elapsed seconds in ``commits`` (how old the last commit is tells what a
        kill right now would lose, and a reader whether the coordinator is still there: :meth:`gone_since`; the
        elapsed time is where ``--resume`` carries the time rule on). A file deleted meanwhile is a :class:`StoreError`."""
        self.check_file()
        self.flush()
        if campaign is not None:
            self.db.execute(
                "INSERT OR REPLACE INTO commits (campaign, t, elapsed_s, pid, host) VALUES (?, ?, ?, ?, ?)",
                (campaign, time.time(), elapsed_s, os.getpid(), socket.gethostname()),
            )
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

    @guarded_write
    def create_campaign(self, name: str, dataset: str, config: bytes) -> None:
        """Register a new campaign; an existing one is never overwritten."""
        self.check_new(name)
        self.db.execute(
            "INSERT INTO campaigns (name, dataset, config, created, status) VALUES (?, ?, ?, ?, 'running')",
            (name, dataset, config, time.time()),
        )
        self.db.commit()

    @guarded_write
    def set_status(self, name: str, status: str, reason: str | None = None) -> None:
        self.check_file()
        self.db.execute(
            "UPDATE campaigns SET status = ?, stop_reason = ?, ended = ? WHERE name = ?",
            (status, reason, time.time() if status != "running" else None, name),
        )
        self.db.commit()

    @guarded_write
    def set_result(self, name: str, result_json: str) -> None:
        """The final result document (the JSON of ``hysid campaign --json``)."""
        self.db.execute("UPDATE campaigns SET result = ? WHERE name = ?", (result_json, name))
        self.db.commit()

    @guarded_write
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
        self._records.append(
            (
                campaign,
                r.island,
                r.run,
                r.algo,
                r.seed,
                r.iterations,
                r.evaluations,
                r.best_fitness,
                np.asarray(r.best_x, dtype="<f8").tobytes(),
                r.sent,
                r.received,
                r.taken,
                r.rejected,
                int(r.final),
                r.unlisted,
            )
        )

    def update_island(self, campaign: str, record: IslandRecord) -> None:
        """:meth:`queue_island`, written now."""
        self.queue_island(campaign, record)
        self.flush()

    @guarded_write
    def add_superseded(self, campaign: str, counts: dict[str, int]) -> None:
        """Migrant messages of each island that a newer one replaced before the coordinator handled them."""
        self.db.executemany(
            "INSERT INTO superseded VALUES (?, ?, ?) ON CONFLICT (campaign, island) DO UPDATE SET messages = messages + excluded.messages",
            [(campaign, island, n) for island, n in counts.items()],
        )

    @guarded_write
    def set_unfollowed(self, campaign: str, islands: int, up_to: int) -> None:
        """The coordinator stopped following migrant messages with ``islands`` alive, following those of at most
        ``up_to`` (the first time is kept)."""
        self.db.execute("INSERT OR IGNORE INTO unfollowed VALUES (?, ?, ?, ?)", (campaign, islands, up_to, time.time()))

    @guarded_write
    def add_migration(self, campaign: str, island: str, run: str, iteration: int, n: int, best_claimed: float, sent_at: float, seq: int) -> bool:
        """Record a migrant message; False if this sender run's message ``seq`` is already stored (a replay)."""
        before = self.db.total_changes
        self.db.execute(
            "INSERT OR IGNORE INTO migrations (campaign, island, run, iteration, n, best_claimed, sent_at, t, seq) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (campaign, island, run, iteration, n, best_claimed, sent_at, time.time(), seq),
        )
        return self.db.total_changes > before

    @guarded_write
    def add_rejected(self, campaign: str, key: str, reason: str, detail: str, size: int, n: int = 1) -> None:
        """Record ``n`` rejected messages (n > 1: a summary of those not recorded one by one)."""
        self.db.execute(
            "INSERT INTO rejected (campaign, key, reason, detail, size, t, n) VALUES (?, ?, ?, ?, ?, ?, ?)",
            (campaign, key[:200], reason, detail[:300], size, time.time(), n),
        )

    @guarded_write
    def add_run(self, campaign: str, island: str, run: str, key: bytes, algo: str, seed: int, joined: float, member: str = "") -> None:
        """A run admitted, with the public key it signs with, when it joined (Unix time) and the member it joined for."""
        self.db.execute(
            "INSERT INTO runs (campaign, island, run, key, algo, seed, joined, member) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
            (campaign, island, run, key, algo, seed, joined, member),
        )

    @guarded_write
    def add_move(self, campaign: str, move: Move) -> None:
        """An island run the share of a mixed campaign moved to another algorithm (:mod:`island.share`)."""
        self.db.execute(
            "INSERT INTO moves (campaign, island, run, src, dst, evaluations, credit, t) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
            (campaign, move.island, move.run, move.src, move.dst, move.evaluations, json.dumps(move.credit), time.time()),
        )

    @guarded_write
    def set_best(self, campaign: str, best: StoredBest) -> None:
        self.db.execute(
            "INSERT OR REPLACE INTO best VALUES (?, ?, ?, ?, ?, ?)",
            (campaign, best.island, np.asarray(best.x, dtype="<f8").tobytes(), best.fitness, best.evaluations, time.time()),
        )
