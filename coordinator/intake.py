"""What the islands report, taken in: their history rows, their migrants, and the global best the coordinator
keeps from both, re-evaluated (a claimed fitness is never trusted).

:class:`Intake` (part of :class:`coordinator.state.Coordinator`), on the coordinator's thread:

* a history message (:meth:`Intake._history`) is checked against replays (its run's message numbers,
  :class:`island.sealing.ReplayGuard`) and for plausible counters (:class:`coordinator.histories.HistoryChecks`);
  its best is re-evaluated and must not be claimed better than it is; its rows are stored (over capacity every
  improvement and a thinned rest, the rows left out counted: :class:`coordinator.thinning.HistoryPolicy`), the
  gaps in them asked for again (:class:`coordinator.histories.Gaps`, :meth:`Intake.history_query`), its counters
  upserted, its evaluations counted for its member and its gains credited to its algorithm (the share's moves:
  :class:`coordinator.sharing.Sharing`);
* a migrant message (:meth:`Intake._migrants`) is followed (recorded once, its best taken at the next commit:
  :meth:`Intake.consider_migrants`) only while at most :data:`FOLLOWS_MIGRANTS_UP_TO` islands are alive;
  once more are, the coordinator stops following them for the rest of its run (:meth:`Intake.review_following`,
  stored: the report says so);
* a candidate that beats the global best on the coordinator's own fitness (:meth:`Intake.evaluate`, recently
  seen candidates from a cache of :data:`EVALUATED_CACHE`) becomes it: stored, and published for late joiners.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from coordinator.held import Held
from coordinator.histories import check_claim
from coordinator.link import Link
from coordinator.progress import IslandView
from coordinator.records import IslandRecord, StoredBest
from island.coordinator_messages import HistoryQuery, encode_history_query
from island.island_messages import History, Migrants
from island.sealing import check_replay
from island.wire import MessageRejected

if TYPE_CHECKING:
    from coordinator.members import Member

EVALUATED_CACHE = 4096
"""Candidates whose fitness the coordinator keeps (the most recently seen)."""
FOLLOWS_MIGRANTS_UP_TO = 64
"""A coordinator follows every migrant message while at most this many islands are alive (see the module docstring
and :mod:`coordinator.state`'s)."""


class Intake(Held):
    """The intake part of :class:`coordinator.state.Coordinator` (see the module docstring; the state it uses, the
    store, the checks, the membership and the share among it, is the coordinator's)."""

    if TYPE_CHECKING:  # what the other parts give this one (the state it uses: Held)

        @property
        def members(self) -> dict[str, Member]: ...

        def count_effort(self, key: tuple[str, str], evaluations: int) -> None: ...

        def countable(self) -> int: ...

        def rule_stop(self) -> str | None: ...

        def _best_message(self) -> bytes: ...

    # --- message numbers and history queries --------------------------------------------------
    def history_query(self, island: str, run: str, since: int) -> str:
        """The signed selector parameters asking ``island`` for the rows of ``run`` after ``since``."""
        self.query_seq = max(self.query_seq + 1, time.time_ns() // 1000)  # rises across coordinator restarts
        return encode_history_query(HistoryQuery(self.name, island, run, since, self.query_seq), self.signing)

    def _known(self, key: tuple[str, str]) -> tuple[int, float]:
        """What is known of a run's message numbers before its first message here: it numbers from 0, since it joined."""
        return -1, time.time() - self.runs[key].joined

    def last_seq(self, island: str, run: str) -> int:
        """The last message number of that run accepted here (-1: none; the roster says it)."""
        return max(self._replays.high(("history", island, run)), self._replays.high(("migrants", island, run)))

    def _heard(self, island: str, run: str, arrived: float) -> None:
        """A signed message of that run, arrived at ``arrived`` (``time.monotonic()``): its latest run is alive
        (:meth:`coordinator.members.Membership.heard`)."""
        if self.current.get(island) == run:
            self.membership.heard(island, run, arrived)

    # --- history and migrants --------------------------------------------------------------
    def evaluate(self, x: np.ndarray) -> np.ndarray:
        """The coordinator's own fitness of candidates ``x (k, D)`` (recently seen ones from a cache)."""
        keys = [row.tobytes() for row in np.ascontiguousarray(x, dtype=float)]
        todo = [i for i, k in enumerate(keys) if k not in self._evaluated]
        if todo:
            for i, f in zip(todo, self.objective(x[todo])):
                self._evaluated[keys[i]] = float(f)
        for k in keys:
            self._evaluated.move_to_end(k)
        while len(self._evaluated) > EVALUATED_CACHE:
            self._evaluated.popitem(last=False)
        return np.array([self._evaluated[k] for k in keys])

    def _history(self, link: Link, h: History, arrived: float) -> None:
        key = (h.island, h.run)
        info = self.runs[key]
        check_replay(self._replays, "history", h.island, h.run, h.seq, self._known(key))
        self._heard(h.island, h.run, arrived)
        self.checks.plausible(h, info.algo, info.seed, self.sharing.algos[key], self.islands.get(key, IslandView("")).iteration, time.time() - info.joined)
        if not h.rows.size and not h.final:
            return  # a heartbeat: alive, nothing new to store
        f = float(self.evaluate(h.best_x[None, :])[0])
        check_claim(h, f)
        if h.rows.size:
            kept = h.rows[self.policy.keep(key, h.rows)]
            self.store.queue_history(self.name, h.island, h.run, kept)
            span = (int(h.rows[0, 0]), int(h.rows[-1, 0]))
            if kept.shape[0] < h.rows.shape[0]:
                self.store.queue_thinned(self.name, h.island, h.run, span, h.rows.shape[0] - kept.shape[0])
            self.rows_since_commit += kept.shape[0]
            self.gaps.arrived(key, *span, link.request_history)
        iterations = int(h.rows[:, 0].max()) if h.rows.size else 0
        evaluations = int(h.rows[:, 2].max()) if h.rows.size else 0
        self.store.queue_island(
            self.name,
            IslandRecord(
                h.island,
                h.run,
                h.algo,
                h.seed,
                iterations,
                evaluations,
                f,
                h.best_x,
                h.stats["sent"],
                h.stats["received"],
                h.stats["taken"],
                h.stats["rejected"],
                h.final,
                h.stats["unlisted"],
            ),
        )
        self.count_effort(key, evaluations)
        self.sharing.credit(key, h.algo, h.gain)
        view = self.islands.setdefault(key, IslandView(h.algo))
        view.algo = h.algo
        view.iteration = max(view.iteration, iterations)
        view.best = min(view.best, f)
        view.final = view.final or h.final
        self.changed = True
        if h.final:
            self.membership.final_history(h.island, h.run)
            self.policy.forget(key)
        self._consider(link, h.island, h.best_x, f)
        if self.stop_reason is None and self.rule_stop() is None:  # the share's moves (none once a rule says stop): told with the next control message
            self.sharing.review(self.evaluations, self.members, self.islands, key)

    def _migrants(self, link: Link, m: Migrants, arrived: float) -> None:
        if not self.follows_migrants:
            return  # queued before the coordinator stopped following them: the islands count it
        check_replay(self._replays, "migrants", m.island, m.run, m.seq, self._known((m.island, m.run)))
        self._heard(m.island, m.run, arrived)
        if not self.store.add_migration(self.name, m.island, m.run, m.iteration, m.x.shape[0], float(m.claimed.min()), m.sent_at, m.seq):
            raise MessageRejected("replay", f"migrant message {m.seq} of {m.island!r} run {m.run!r} is stored already")
        self.migrations += 1
        self._candidates[m.island] = m  # of an island's messages only the newest matters: its best never gets worse

    def review_following(self, link: Link | None = None) -> None:
        """Stop following migrant messages once more than :data:`FOLLOWS_MIGRANTS_UP_TO` islands are alive: at the
        join that makes them so (:meth:`coordinator.admission.Admission.admit`, before the island hears it joined:
        none of its migrants, nor of those it makes start, is followed), and then at every commit, where ``link``
        stops their delivery."""
        if self.follows_migrants:
            alive = sum(m.status == "alive" for m in self.members.values())
            if alive > FOLLOWS_MIGRANTS_UP_TO:
                self.follows_migrants = False
                self.store.set_unfollowed(self.name, alive, FOLLOWS_MIGRANTS_UP_TO)
        if not self.follows_migrants and link is not None:
            link.unfollow_migrants()

    def consider_migrants(self, link: Link) -> None:
        """Evaluate the migrants of each island's newest message handled since the last call (the run loop calls
        it at every commit: :func:`coordinator.loop.commit`), and take the best if it beats the global best."""
        if not self._candidates:
            return
        waiting, self._candidates = list(self._candidates.values()), {}
        for m in waiting:  # message by message: a candidate's fitness does not depend on what it was evaluated with
            f = self.evaluate(m.x)
            i = int(np.argmin(f))
            self._consider(link, m.island, m.x[i], float(f[i]))

    def _consider(self, link: Link, island: str, x: np.ndarray, f: float) -> None:
        """A candidate with the coordinator's own fitness ``f``: if it beats the global best, it is the new one."""
        if not np.isfinite(f) or (self.best is not None and not f < self.best.fitness):
            return
        self.best = StoredBest(island, np.array(x, dtype=float), f, self.countable())
        self.best_trace.append((time.monotonic(), f, self.evaluations, self.best.x))
        self.store.set_best(self.name, self.best)
        self.best_message = self._best_message()
        link.publish_best(self.best_message)
