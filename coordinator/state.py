"""The campaign coordinator's state and message handling: admits islands, records everything, keeps the best.

All incoming traffic (join requests, island histories and migrants,
membership changes) lands in one bounded, fair inbox (:mod:`coordinator.inbox`)
and is handled (:meth:`Coordinator.handle`) by one thread, the run loop of
:mod:`coordinator.loop`, which owns the SQLite store (:mod:`coordinator.store`).
The coordinator

* serves ``config`` (campaign configuration + loop set) and ``best``;
* holds the campaign's keys (:class:`coordinator.keys.CampaignKeys`: the shared
  admission secret, the members' key and its signing key, made at the start and
  kept in an owner-only key file beside the database, never in it) and signs
  everything it sends with that key;
* admits islands (the join handshake, a challenge-response): only an island
  that proves it holds its member's admission secret, for a challenge this process
  issued within the last :data:`CHALLENGE_S`, gets a run id; the run's public
  key is stored before the island hears of it, and each island id gets at
  most :data:`RUNS_PER_ISLAND` runs. Only an island that joined may speak:
  its history and migrants must carry its run's signature, a replayed message
  is dropped, and counters it could not have reached (more evaluations than its
  algorithm, its iterations and the migrants it may take allow) are rejected
  (:class:`coordinator.histories.HistoryChecks`).
  A liveliness token of an island that never joined makes nobody a member;
* records joins, graceful leaves (a final history, then the token goes) and
  losses (the token goes without a final history: crash, kill, or a frozen
  process whose Zenoh lease expired; or a joined island whose token never
  shows) through :class:`coordinator.members.Membership`;
* stores the history rows (every one while it keeps up; over capacity every
  improvement and a thinned rest, the rows left out counted:
  :class:`coordinator.thinning.HistoryPolicy`), every migrant message it handles
  (when it falls behind, of an island's migrant messages waiting only the newest is
  handled, the others counted as superseded: :mod:`coordinator.inbox`), and every rejected message
  with its reason (a flood as counted summaries);
* follows the migrant messages (checks each one's signature, records it, takes
  its best) only while at most :data:`FOLLOWS_MIGRANTS_UP_TO` islands are alive:
  once more are, it stops for the rest of its run (stored, with how many were
  alive: the report says so) and :meth:`Link.unfollow_migrants` stops their
  delivery. Migration goes from island to island and needs no coordinator; each
  island still counts what it sent, received, took in and rejected in its
  history, which also carries its best. A thousand islands migrating every
  fifth of 50 iterations a second send 10,000 signed messages a second, more
  than one coordinator checks (about 150 µs a signature here) while it also stores
  their history;
* keeps the global best, **re-evaluating** the candidates it receives (a
  claimed fitness is never trusted, neither to take nor to skip one; of
  migrants, those of each island's newest message handled, at each commit:
  an island's best never gets worse) and
  publishes it for late joiners;
* in a mixed campaign (:mod:`island.share`), credits each island's own
  gains to its algorithm and moves islands: with the ``staged`` share each GA
  run, once its histories show it searched its survey (its first migration
  interval), to the PSO; with the ``adaptive`` one, after each round, an
  island of an algorithm above its share to the leading one (stored, and told to the island in the roster of the ``control``
  message; :class:`coordinator.sharing.Sharing`), none once a stop rule
  (:meth:`Coordinator.rule_stop`) holds;
* after a restart (:func:`resume`, ``--resume``) knows every run that joined, takes up again
  the runs that were alive when it died (lost unless their liveliness token
  is heard from within :data:`coordinator.members.STALE_S`), keeps the campaign's stop rules unless
  new ones are given, and asks every live island for the history rows it missed
  (:class:`coordinator.histories.Gaps`).

Committing, the ``control`` message and the stop rules are the run loop's
(:func:`coordinator.loop.serve`). Once it stopped, :meth:`Coordinator.outcome`
re-evaluates every island's best and polishes the global best (section 3.1's
calculus-based refinement): the raw material of the report that
:mod:`hysid.campaigns` builds, the same as ``hysid fit``'s.

:class:`coordinator.links.ZenohLink` wires a coordinator to a Zenoh session;
single-node campaigns feed the same inbox from island threads
(:mod:`coordinator.launch`).
"""

from __future__ import annotations

import secrets
import time
from collections import Counter, OrderedDict
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from coordinator.admission import Admission
from coordinator.histories import Gaps, HistoryChecks, check_claim
from coordinator.inbox import Inbox
from coordinator.keys import CampaignKeys, campaign_keys
from coordinator.link import Link
from coordinator.members import Member, Membership
from coordinator.outcome import CampaignOutcome, campaign_outcome
from coordinator.progress import CampaignProgress, IslandView, island_views
from coordinator.queries import IslandRecord, StoredBest
from coordinator.sharing import Sharing
from coordinator.store import RUN_LOCK_WAIT_S, Store, StoreError
from coordinator.thinning import HistoryPolicy
from hysid_model.loops import LoopSet
from island.config import CampaignConfig, decode_config, encode_config
from island.protocol import (
    Best,
    History,
    HistoryQuery,
    Migrants,
    decode_history,
    decode_migrants,
    encode_best,
    encode_history_query,
    encode_signed_config,
)
from island.sealing import ReplayGuard, check_replay
from island.termination import Termination
from island.joining import key_prefix
from island.wire import MAX_BYTES, NAME_PATTERN, MessageRejected

REJECTED_PER_S, REJECTED_BURST = 200.0, 5000
"""Rejected messages recorded one by one (a token bucket); beyond it they are counted in summaries."""
EVALUATED_CACHE = 4096
FOLLOWS_MIGRANTS_UP_TO = 64
"""A coordinator follows every migrant message while at most this many islands are alive (see the module docstring)."""


class TokenBucket:
    def __init__(self, rate: float, burst: int) -> None:
        self.rate, self.burst = rate, burst
        self.level, self.at = float(burst), time.monotonic()

    def take(self) -> bool:
        now = time.monotonic()
        self.level = min(self.burst, self.level + (now - self.at) * self.rate)
        self.at = now
        if self.level >= 1.0:
            self.level -= 1.0
            return True
        return False


SLIPPED_THROUGH = (ValueError, TypeError, OverflowError, ArithmeticError, IndexError, KeyError)
"""What a message the checks let through may still raise when it is handled: it is rejected, never raised."""


class Coordinator(Admission):
    """One campaign's coordinator state machine (see the module docstring; joins, members' shares and the roster:
    :class:`coordinator.admission.Admission`)."""

    def __init__(
        self, store: Store, config: CampaignConfig, loops: LoopSet, termination: Termination | None = None, *, dataset: str = "", resume: bool = False,
        keys: CampaignKeys | None = None,
    ) -> None:
        """``keys``: the campaign's keys (default: its key file's, :func:`coordinator.keys.campaign_keys`; fresh ones,
        written there, for a new campaign)."""
        self.store = store
        self.config = config
        self.name = config.name
        self.prefix = key_prefix(config.name)
        self.loops = loops
        self.objective = config.objective(loops)
        if resume and (termination is None or termination == Termination()):
            termination = Termination(**config.stop_rules)  # the campaign's own rules, unless new ones are given
        self.termination = termination or Termination()
        if not resume:
            config = replace(config, stop_rules=self.termination.as_dict())
            self.config = config
        self.config_message = encode_config(config, loops)
        if not resume:
            store.check_new(self.name)  # before its key file is written: an existing campaign's keys stay
        self.keys = keys or campaign_keys(store.path, self.name, resume)
        """The admission secrets and the private signing key (:mod:`coordinator.keys`: in an owner-only file, never in the database)."""
        if not resume:
            store.create_campaign(self.name, dataset, self.config_message)
        else:
            store.set_status(self.name, "running")
        self.resumed = resume
        try:
            store.hold(len(self.config_message))
        except OSError as exc:
            raise StoreError(f"cannot reserve disk space next to the campaign database {store.path}: {exc.strerror or exc}") from None
        self.signing = self.keys.signing
        self.secret = self.keys.secret
        """The shared secret: islands join with it as the shared member (a member's secret: ``keys.member_secret``)."""
        self.run_id = secrets.token_hex(6)
        """This coordinator process, as the sender run of what it signs."""
        self.config_signed = encode_signed_config(self.config_message, self.name, self.run_id, self.signing)
        """The ``config`` message as served: signed."""
        self.query_seq = 0
        """Number of the last history query (rises across coordinator restarts)."""
        self.inbox = Inbox()
        self._admitted(store.runs(self.name))
        self.checks = HistoryChecks(config, self.objective, self.runs, fresh=lambda: config.objective(loops))
        self.sharing = Sharing(store, config, {key: info.algo for key, info in self.runs.items()}, self.checks.optimizer)
        self.islands: dict[tuple[str, str], IslandView] = {}
        self.run_evaluations: dict[tuple[str, str], int] = {}
        for rec in store.islands(self.name):
            self.run_evaluations[(rec.island, rec.run)] = rec.evaluations
            self.islands[(rec.island, rec.run)] = IslandView(rec.algo, rec.iterations, rec.best_fitness, rec.final)
        self.evaluations = int(sum(self.run_evaluations.values()))
        """Evaluations of every run together (each run's as its histories last said; those that count toward the
        budget and the stall rule: :meth:`countable`)."""
        self.solo_effort = self.evaluations  # before this process: as they came
        self.membership = Membership(store, self.name, config.min_islands, self._finished)
        if resume:
            self.membership.take_up(self.current)
        self.best: StoredBest | None = store.best(self.name)
        self.best_message: bytes | None = None if self.best is None else self._best_message()
        self.migrations = store.count("migrations", self.name)
        self.rejected = store.count("rejected", self.name)
        self.started = time.monotonic()
        self.elapsed_before = store.elapsed(self.name) if resume else 0.0
        """Seconds the campaign ran before this process took it up (``--resume``: the time rule carries on)."""
        store.set_lock_wait(RUN_LOCK_WAIT_S)
        self.stop_reason: str | None = None
        self.membership.idle_since = self.started if self.runs and not self.members else None
        self.best_trace: list[tuple[float, float, int, np.ndarray]] = []
        """``(time.monotonic(), fitness, total evaluations, x)`` at every improvement of the global best."""
        self.gaps = Gaps(store, self.name)
        self.policy = HistoryPolicy()
        self.follows_migrants = store.unfollowed(self.name) is None
        """Whether migrant messages are followed (:data:`FOLLOWS_MIGRANTS_UP_TO`; a resumed campaign that stopped does not start again)."""
        self.superseded = store.superseded(self.name)
        """Migrant messages superseded in the inbox (a newer one of the island replaced them) before they were handled."""
        self._replays = ReplayGuard()
        self._evaluated: OrderedDict[bytes, float] = OrderedDict()
        self._candidates: dict[str, Migrants] = {}
        """Each island's newest migrant message handled since the last commit, not evaluated yet (:meth:`consider_migrants`)."""
        self._rejected_log = TokenBucket(REJECTED_PER_S, REJECTED_BURST)
        # what the run loop (:mod:`coordinator.loop`) reads and resets at each commit
        self.rejected_backlog: Counter[str] = Counter()
        """Rejected messages not yet stored (beyond the log's rate), by reason."""
        self.committed_at = time.monotonic()
        self.commit_s = 0.0
        """How long the last commit took."""
        self.slowest_item_s = 0.0
        """The longest a message took to handle lately (halved at each commit)."""
        self.rows_since_commit = 0
        """History rows stored since the last commit."""
        self.window_at = self.flushed_at = time.monotonic()
        self.busy_s = self.writing_s = 0.0
        self.written = 0
        """Since ``window_at``: seconds the run loop worked, of them writing history rows, and the rows written
        (what :meth:`coordinator.thinning.HistoryPolicy.review` measures storage by)."""
        self.changed = True
        """Whether the roster changed since the control message last went out."""
        self.announced_events = 0
        """Membership events when the control message last went out."""
        self.control_at = -np.inf
        self.control_seq = 0
        """Sequence number of the last control message."""

    # --- state -------------------------------------------------------------------
    @property
    def members(self) -> dict[str, Member]:
        """Each island's latest run as a member (:class:`coordinator.members.Membership`)."""
        return self.membership.members

    @property
    def full_at(self) -> float | None:
        """``time.monotonic()`` when ``min_islands`` islands were first alive: the islands start searching."""
        return self.membership.full_at

    def elapsed(self) -> float:
        """Seconds the campaign has run, across ``--resume`` (the time a coordinator was down not counted)."""
        return self.elapsed_before + time.monotonic() - self.started

    def _finished(self, island: str, run: str) -> bool:
        return self.islands.get((island, run), IslandView("")).final

    def progress(self) -> CampaignProgress:
        return CampaignProgress(
            elapsed_s=self.elapsed(),
            evaluations=self.evaluations,
            best=np.inf if self.best is None else self.best.fitness,
            members={i: m.status for i, m in self.members.items()},
            islands=island_views(self.islands, ((key, info.algo) for key, info in self.runs.items()), self.sharing.moves),
            migrations=self.migrations,
            rejected=self.rejected,
            migrations_followed=self.follows_migrants,
            stopping=self.stop_reason,
        )

    def _best_message(self) -> bytes:
        assert self.best is not None
        return encode_best(Best(self.name, self.best.island, self.best.x, self.best.fitness), self.run_id, self.signing)

    # --- what other threads call: into the inbox ------------------------------------------------
    def _source(self, island: str) -> str:
        """Inbox queue of a sender: its own once it joined, else the one all strangers share."""
        return island if island in self.current else "?"

    def receive(self, key: str, payload: bytes, wait_s: float | None = 1.0) -> bool:
        """A publication (``hysid/<c>/<kind>/<sender>``) for the coordinator's thread; False if dropped. A
        joined island's migrant message may replace its one still waiting (only its newest matters:
        :mod:`coordinator.inbox`), once it proved to be its run's, well formed: what could be rejected
        waits to be, with its reason. Migrant messages are let pass once the coordinator stopped following
        them (:meth:`review_following`)."""
        kind, sender = key.rsplit("/", 2)[-2:] if key.count("/") >= 2 else ("", key)
        if kind == "migrants" and not self.follows_migrants:
            return True  # on its way when the coordinator stopped following them: the islands count it
        source = self._source(sender)
        if len(payload) > MAX_BYTES.get(kind, 0) > 0:  # rejected as it is: its bytes need not wait (a flood of them would fill the inbox)
            return self.inbox.put(source, ("oversized", key, len(payload), MAX_BYTES[kind]), 0, wait_s)
        m = self._authentic(payload, sender) if kind == "migrants" and source != "?" and self.inbox.is_crowded() else None
        if m is not None:
            return self.inbox.put(source, ("migrants", key, m, time.monotonic()), len(payload), wait_s, replace=True)
        return self.inbox.put(source, ("msg", key, payload, time.monotonic()), len(payload), wait_s)

    def _authentic(self, payload: bytes, sender: str) -> Migrants | None:
        """A migrant message, if it is signed by a run of ``sender`` and well formed (None: it is not;
        replays are the coordinator's thread's to check; called from the thread a message arrives on)."""
        try:
            return decode_migrants(payload, self.name, self.objective.bounds, key_for=self._key_for, sender=sender)
        except (MessageRejected, *SLIPPED_THROUGH):
            return None

    def member(self, island: str, alive: bool, wait_s: float | None = 1.0) -> bool:
        """A liveliness token of ``members/<island>`` appeared (``alive``) or went."""
        return self.inbox.put("!" + self._source(island), ("member", island, alive), 0, wait_s, urgent=True)

    def join_request(self, island: str, payload: bytes, reply: Callable[[bytes], None], wait_s: float | None = 1.0) -> bool:
        """A step of the join handshake on ``join/<island>``; ``reply`` sends the answer (called by the coordinator's thread)."""
        return self.inbox.put("!" + self._source(island), ("join", island, payload, reply), len(payload), wait_s, urgent=True)

    # --- handling what arrives ----------------------------------------------------------
    def handle(self, link: Link, item: tuple[Any, ...]) -> None:
        """One inbox item: ``("msg", key, payload, arrived)``, ``("migrants", key, message, arrived)`` (checked
        as it arrived but for replays; ``arrived``: its ``time.monotonic()`` then), ``("oversized", key, size, most)``
        (a publication too large for its kind, its bytes dropped as it came), ``("member", island, alive)``
        or ``("join", island, payload, reply)``.

        Nothing a message holds can raise out of here: a rejected message is
        recorded with its reason; only a database that cannot be written
        (:class:`StoreError`) stops the coordinator.
        """
        key, size = f"{item[0]}/{item[1]}", 0
        try:
            if item[0] == "member":
                key = f"members/{item[1]}"
                self._member(link, item[1], item[2])
            elif item[0] == "join":
                key, size = f"join/{item[1]}", len(item[2])
                self._join(link, item[1], item[2], item[3])
            elif item[0] == "migrants":
                key = item[1]
                self._migrants(link, item[2], item[3])
            elif item[0] == "oversized":
                key, size = item[1], item[2]
                raise MessageRejected("oversized", f"a message of {item[2]} bytes under {key[:100]} exceeds {item[3]}")
            else:
                _, key, payload, arrived = item
                size = len(payload)
                kind, _, sender = key[len(self.prefix) + 1 :].partition("/") if key.startswith(self.prefix + "/") else ("", "", "")
                if kind == "history":
                    self._history(link, decode_history(payload, self.name, self.objective.bounds, key_for=self._key_for, sender=sender), arrived)
                elif kind == "migrants":
                    self._migrants(link, decode_migrants(payload, self.name, self.objective.bounds, key_for=self._key_for, sender=sender), arrived)
                else:
                    raise MessageRejected("schema", f"unexpected key {key[:100]}")
        except MessageRejected as exc:
            self.reject(key, exc.reason, str(exc), size)
        except StoreError:
            raise
        except SLIPPED_THROUGH as exc:
            self.reject(key, "schema", f"could not be handled ({type(exc).__name__}: {exc})", size)

    def reject(self, key: str, reason: str, detail: str, size: int) -> None:
        """Count a rejected message; record it, or (in a flood) count it in the next summary row."""
        self.rejected += 1
        if self._rejected_log.take():
            self.store.add_rejected(self.name, key, reason, detail, size)
        else:
            self.rejected_backlog[reason] += 1

    def _key_for(self, island: str, run: str) -> bytes | None:
        info = self.runs.get((island, run))
        return None if info is None else info.key

    # --- membership --------------------------------------------------------------
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
        (:meth:`Membership.heard`)."""
        if self.current.get(island) == run:
            self.membership.heard(island, run, arrived)

    def _member(self, link: Link, island: str, alive: bool) -> None:
        if not NAME_PATTERN.match(island):
            raise MessageRejected("sender", "liveliness token with an invalid island name")
        run = self.current.get(island)
        if run is None:
            raise MessageRejected("unjoined", f"liveliness token of {island!r}, which never joined")
        self.membership.token(island, run, alive)
        if alive:
            link.request_history(island, run, self.gaps.stored((island, run)))

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
        self.store.queue_island(self.name, IslandRecord(
            h.island, h.run, h.algo, h.seed, iterations, evaluations, f, h.best_x,
            h.stats["sent"], h.stats["received"], h.stats["taken"], h.stats["rejected"], h.final, h.stats["unlisted"],
        ))
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
        join that makes them so (:meth:`admit`, before the island hears it joined: none of its migrants, nor of those
        it makes start, is followed), and then at every commit, where ``link`` stops their delivery."""
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

    # --- the stop rules (checked by the run loop, coordinator.loop) ------------------------
    def rule_stop(self) -> str | None:
        """The stop rule (budget, target, stall, time) that holds now, if any (the budget and the stall rule count the
        evaluations that count: :meth:`countable`)."""
        best = self.best
        return self.termination.reason(
            evaluations=self.countable(),
            best=np.inf if best is None else best.fitness,
            best_at=0 if best is None else best.evaluations,
            elapsed_s=self.elapsed(),
        )

    # --- the outcome ----------------------------------------------------------------
    def outcome(self, *, polish_best: bool = True) -> CampaignOutcome:
        """What the campaign leaves (:func:`coordinator.outcome.campaign_outcome`)."""
        return campaign_outcome(self, polish_best=polish_best)


def resume(store: Store, name: str, termination: Termination | None = None) -> Coordinator:
    """The coordinator of a stored campaign, with its history, islands, runs and best as they were, and its keys
    (:mod:`coordinator.keys`)."""
    _, message, _ = store.campaign(name)
    config, loops = decode_config(message, name)
    return Coordinator(store, config, loops, termination, resume=True)
