"""What a campaign database holds, read: the read side of :class:`coordinator.store.Store`, which ``hysid watch``,
``hysid report`` and the outcome read, and ``--resume`` takes a campaign up from (also of a database opened
read-only, or of an earlier hysid that lacks some of today's tables: :func:`coordinator.schema.has_table`).

Besides the campaigns, their runs, islands, history, migrations and rejected messages, it reads the coordinator's
heartbeat: a campaign not stopped whose coordinator is gone (:meth:`Queries.gone_since`) reads ``interrupted``
(:meth:`Queries.state`)."""

from __future__ import annotations

import json
import os
import socket
import sqlite3
import time
from typing import Any

import numpy as np

from coordinator.records import IslandRecord, Span, StoredBest, merged
from coordinator.schema import has_column, has_table
from hysid_model.errors import HysidInputError
from island.share import Move

COORDINATOR_LEASE_S = 10.0
"""A campaign not stopped whose coordinator committed nothing for this long has lost its coordinator: a running one
commits at least every :data:`coordinator.loop.COMMIT_EVERY_S` (stamping its heartbeat in ``commits``) and waits at most
:data:`coordinator.store.RUN_LOCK_WAIT_S` for a lock (as long as Zenoh's lease of a silent peer). On the coordinator's
own host its heartbeat's process tells sooner: one that no longer runs is gone at once."""


def process_runs(pid: int) -> bool:
    """Whether process ``pid`` of this host runs (a zombie, ended but not yet reaped by its parent, does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # another user's
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as f:
            return f.read().rsplit(")", 1)[-1].split()[0] != "Z"
    except (OSError, IndexError):
        return True


class Queries:
    """What a campaign database holds (``db``: its connection; ``path``: its file)."""

    db: sqlite3.Connection
    path: str

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
        """Unix time of the last sign of life of a campaign's coordinator (its heartbeat: its last commit, else the
        campaign's creation) if the campaign did not stop and its coordinator is gone: nothing committed for
        ``lease_s`` (killed, frozen, or its machine), or its process, on this host, no longer runs. None while it
        commits, once the campaign stopped, and for a database of a hysid that stamped no commits."""
        try:
            status, created, last = self.db.execute(
                "SELECT status, created, t FROM campaigns LEFT JOIN commits ON commits.campaign = campaigns.name WHERE name = ?", (campaign,)
            ).fetchone()
        except sqlite3.OperationalError:  # no commits table: an earlier hysid's database
            return None
        seen = created if last is None else last
        if status == "stopped":
            return None
        return seen if time.time() - seen > lease_s or self._process_gone(campaign) else None

    def _process_gone(self, campaign: str) -> bool:
        """Whether the coordinator process that last stamped the campaign's heartbeat ran on this host and runs no more."""
        if not has_column(self.db, "commits", "host"):
            return False  # an earlier hysid's heartbeat: only its age tells
        row = self.db.execute("SELECT pid, host FROM commits WHERE campaign = ?", (campaign,)).fetchone()
        if row is None or row[0] is None or row[1] != socket.gethostname():
            return False
        return not process_runs(int(row[0]))

    def state(self, name: str) -> tuple[str, str | None]:
        """The campaign's status and stop reason as they are: as stored, but a campaign stored ``running`` or
        ``stopping`` whose coordinator is gone (:meth:`gone_since`; one that could not mark it, say on a locked
        database) reads ``interrupted``, and why."""
        status, reason = self.db.execute("SELECT status, stop_reason FROM campaigns WHERE name = ?", (name,)).fetchone()
        gone = self.gone_since(name) if status in ("running", "stopping") else None
        if gone is None:
            return status, reason
        when = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(gone))
        return "interrupted", f"interrupted: its coordinator is gone (last heartbeat {when}) and left the campaign {status}" + (
            f" ({reason})" if reason else ""
        )

    def has_campaign(self, name: str) -> bool:
        return self.db.execute("SELECT 1 FROM campaigns WHERE name = ?", (name,)).fetchone() is not None

    def campaign(self, name: str) -> tuple[str, bytes, str]:
        """``(dataset, config message, status)`` of a stored campaign."""
        row = self.db.execute("SELECT dataset, config, status FROM campaigns WHERE name = ?", (name,)).fetchone()
        if row is None:
            known = [r[0] for r in self.db.execute("SELECT name FROM campaigns ORDER BY created")]
            raise HysidInputError(f"{self.path}: no campaign {name!r} to resume (stored: {', '.join(known) or 'none'})")
        return row[0], bytes(row[1]), row[2]

    def result(self, name: str) -> dict[str, Any] | None:
        row = self.db.execute("SELECT result FROM campaigns WHERE name = ?", (name,)).fetchone()
        return None if row is None or row[0] is None else json.loads(row[0])

    def stop_reason(self, name: str) -> str | None:
        row = self.db.execute("SELECT stop_reason FROM campaigns WHERE name = ?", (name,)).fetchone()
        return None if row is None else row[0]

    def moves(self, campaign: str) -> list[Move]:
        """The moves of the campaign in the order they were made."""
        rows = self.db.execute("SELECT island, run, src, dst, evaluations, credit FROM moves WHERE campaign = ? ORDER BY id", (campaign,))
        return [Move(i, r, a, b, int(e), json.loads(c)) for i, r, a, b, e, c in rows]

    def runs(self, campaign: str) -> list[tuple[str, str, bytes, str, int, float, str]]:
        """Every run that joined: ``(island, run, public key, algo, seed, joined, member)`` in the order they joined."""
        member = "member" if has_column(self.db, "runs", "member") else "''"
        rows = self.db.execute(f"SELECT island, run, key, algo, seed, joined, {member} FROM runs WHERE campaign = ? ORDER BY joined", (campaign,))
        return [(i, r, bytes(k), a, s, float(j), m) for i, r, k, a, s, j, m in rows]

    def best(self, campaign: str) -> StoredBest | None:
        row = self.db.execute("SELECT island, x, fitness, evaluations FROM best WHERE campaign = ?", (campaign,)).fetchone()
        if row is None:
            return None
        return StoredBest(row[0], np.frombuffer(row[1], dtype="<f8").copy(), float(row[2]), int(row[3]))

    def islands(self, campaign: str) -> list[IslandRecord]:
        unlisted = "unlisted" if has_column(self.db, "islands", "unlisted") else "0"
        rows = self.db.execute(
            "SELECT island, run, algo, seed, iterations, evaluations, best_fitness, best_x, sent, received, taken, rejected, final, "
            f"{unlisted} FROM islands WHERE campaign = ? ORDER BY island, run",
            (campaign,),
        )
        return [
            IslandRecord(r[0], r[1], r[2], r[3], r[4], r[5], r[6], np.frombuffer(r[7], dtype="<f8").copy(), r[8], r[9], r[10], r[11], bool(r[12]), int(r[13]))
            for r in rows
        ]

    def total_evaluations(self, campaign: str) -> int:
        return int(self.db.execute("SELECT coalesce(sum(evaluations), 0) FROM islands WHERE campaign = ?", (campaign,)).fetchone()[0])

    def handled(self, campaign: str, island: str, run: str) -> list[Span]:
        """The iterations of an island run the coordinator handled, stored or thinned, as disjoint sorted spans."""
        where = "campaign = ? AND island = ? AND run = ?"
        key = (campaign, island, run)
        starts = self.db.execute(
            f"""SELECT iteration FROM history h WHERE {where} AND NOT EXISTS (SELECT 1 FROM history g WHERE
            g.campaign = h.campaign AND g.island = h.island AND g.run = h.run AND g.iteration = h.iteration - 1) ORDER BY iteration""",
            key,
        )
        ends = self.db.execute(
            f"""SELECT iteration FROM history h WHERE {where} AND NOT EXISTS (SELECT 1 FROM history g WHERE
            g.campaign = h.campaign AND g.island = h.island AND g.run = h.run AND g.iteration = h.iteration + 1) ORDER BY iteration""",
            key,
        )
        spans = list(zip((s for (s,) in starts.fetchall()), (e for (e,) in ends.fetchall())))
        if has_table(self.db, "thinned"):
            spans += self.db.execute(f"SELECT first, last FROM thinned WHERE {where}", key).fetchall()
        return merged(spans)

    def thinned(self, campaign: str) -> dict[tuple[str, str], int]:
        """History rows the coordinator did not keep, per island run."""
        if not has_table(self.db, "thinned"):
            return {}
        rows = self.db.execute("SELECT island, run, sum(rows) FROM thinned WHERE campaign = ? GROUP BY island, run", (campaign,))
        return {(i, r): int(n) for i, r, n in rows}

    def superseded(self, campaign: str) -> int:
        """Migrant messages a newer one of the same island replaced before the coordinator handled them."""
        if not has_table(self.db, "superseded"):
            return 0
        return int(self.db.execute("SELECT coalesce(sum(messages), 0) FROM superseded WHERE campaign = ?", (campaign,)).fetchone()[0])

    def unfollowed(self, campaign: str) -> dict[str, Any] | None:
        """When the coordinator stopped following migrant messages: ``islands`` alive then, the rule's ``up_to``
        and the Unix time ``t`` (None: it never did)."""
        if not has_table(self.db, "unfollowed"):
            return None
        row = self.db.execute("SELECT islands, up_to, t FROM unfollowed WHERE campaign = ?", (campaign,)).fetchone()
        return None if row is None else {"islands": int(row[0]), "up_to": int(row[1]), "t": float(row[2])}

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

    def pick_campaign(self, name: str | None = None) -> str:
        """``name`` if the database holds it, else (None) its latest campaign; a one-line error otherwise."""
        names = [c["name"] for c in self.campaign_list()]
        if name is None:
            if not names:
                raise HysidInputError(f"{self.path}: holds no campaign yet")
            return names[-1]
        if name not in names:
            raise HysidInputError(f"{self.path}: no campaign {name!r} (stored: {', '.join(map(repr, names)) or 'none'})")
        return name

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
        return has_column(self.db, "rejected", "n")

    def rejected_reasons(self, campaign: str) -> dict[str, int]:
        n = "sum(n)" if self._counted_rejects() else "count(*)"
        rows = self.db.execute(f"SELECT reason, {n} FROM rejected WHERE campaign = ? GROUP BY reason", (campaign,))
        return {r: int(n) for r, n in rows}
