"""The campaign database file (SQLite): what a coordinator must not lose, opened for writing, for reading
only, or copied into memory.

One file holds any number of campaigns (its tables and their upgrades: :mod:`coordinator.schema`; what the
coordinator writes: :mod:`coordinator.writes`; what it holds, read: :mod:`coordinator.queries`). The journal is
WAL with ``synchronous=NORMAL``; the coordinator commits (flushing first) at least every half second, stamping
its heartbeat, so a crash (or kill) of the coordinator process loses nothing it has committed and ``--resume``
carries on from the file (only a power loss of the machine may drop the last commits).

The file is created owner-only (mode 0600; SQLite gives its ``-wal`` and ``-shm`` files the database's
mode, and so does the reserve file here): a user who wants others to read the results makes it so with
``chmod``. It holds no key (:mod:`coordinator.keys`). A file opened for writing is checked to be writable
(the write lock taken once) before any work starts, and disk space is held beside it (:meth:`Store.hold`) so
that a campaign on a full disk can still be marked interrupted.
"""

from __future__ import annotations

import os
import sqlite3
import stat
import warnings
from pathlib import Path

from coordinator.schema import has_table, move_keys_out, prepare
from coordinator.writes import Writes, file_identity, guarded_write
from hysid_model.errors import HysidInputError, HysidWarning

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


class Store(Writes):
    """A campaign database file (``":memory:"`` for a throw-away one): opened, written (:class:`coordinator.writes.Writes`)
    and read (:class:`coordinator.queries.Queries`)."""

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
            self.identity = None if self.path == ":memory:" else file_identity(self.path)
            self._pending()
        except (sqlite3.DatabaseError, OSError) as exc:
            raise HysidInputError(f"{self.path}: not a usable campaign database ({exc})") from None

    def set_lock_wait(self, seconds: float) -> None:
        """How long a write waits for another process' lock from now on."""
        self.db.execute(f"PRAGMA busy_timeout = {int(seconds * 1000)}")

    def hold(self, row_bytes: int) -> None:
        """Hold :data:`RESERVE_BYTES` plus twice ``row_bytes`` of disk space in the reserve file (of the database's mode)."""
        if self.reserve is not None:
            with os.fdopen(os.open(self.reserve, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600), "wb") as f:
                os.fchmod(f.fileno(), stat.S_IMODE(os.stat(self.path).st_mode))
                f.write(bytes(RESERVE_BYTES + 2 * row_bytes))
                f.flush()
                os.fsync(f.fileno())

    @classmethod
    def read_only(cls, path: Path | str) -> Store:
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
        if has_table(db, "secrets"):
            warnings.warn(
                HysidWarning(
                    f"{path} still holds campaign keys (an earlier hysid kept them there): anyone who can read it can join its campaigns "
                    "and sign as their coordinator; open it once with this hysid for writing (hysid coordinator --resume) to move them "
                    "to owner-only key files"
                ),
                stacklevel=2,
            )
        return store

    @classmethod
    def snapshot(cls, path: Path | str) -> Store:
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

    @guarded_write
    def _commit(self) -> None:
        self.flush()
        self.db.commit()
