"""The campaign coordinator's state: admits islands, records everything, keeps the best.

All incoming traffic (join requests, island histories and migrants,
membership changes) lands in one bounded, fair inbox (:mod:`coordinator.inbox`)
and is handled (:meth:`coordinator.receiving.Receiving.handle`) by one thread, the run loop of
:mod:`coordinator.loop`, which owns the SQLite store (:mod:`coordinator.store`).
The coordinator

* serves ``config`` (campaign configuration + loop set) and ``best``;
* holds the campaign's keys (:class:`coordinator.keys.CampaignKeys`: the shared
  admission secret, the members' key and its signing key, made at the start and
  kept in an owner-only key file beside the database, never in it) and signs
  everything it sends with that key;
* admits islands (the join handshake, a challenge-response): only an island
  that proves it holds its member's admission secret, for a challenge this process
  issued within the last :data:`coordinator.admission.CHALLENGE_S`, gets a run id; the run's public
  key is stored before the island hears of it, and each island id gets at
  most :data:`coordinator.admission.RUNS_PER_ISLAND` runs. Only an island that joined may speak:
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
  its best) only while at most :data:`coordinator.intake.FOLLOWS_MIGRANTS_UP_TO` islands are alive:
  once more are, it stops for the rest of its run (stored, with how many were
  alive: the report says so) and :meth:`coordinator.link.Link.unfollow_migrants` stops their
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

The :class:`Coordinator` is made of parts, each in a module of its own: the joins, the runs and members' shares
and the roster (:class:`coordinator.admission.Admission`); what arrives, into the inbox and handled or rejected
(:class:`coordinator.receiving.Receiving`); the histories, migrants and global best taken in
(:class:`coordinator.intake.Intake`). This module holds the state they share, made (or taken up again:
:func:`resume`) from the store, the live progress, the stop rule that holds and the outcome.

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
from dataclasses import replace

import numpy as np

from coordinator.admission import Admission
from coordinator.histories import Gaps, HistoryChecks
from coordinator.inbox import Inbox
from coordinator.intake import Intake
from coordinator.keys import CampaignKeys, campaign_keys
from coordinator.members import Member, Membership
from coordinator.outcome import CampaignEnd, CampaignOutcome, campaign_outcome
from coordinator.progress import CampaignProgress, IslandView, island_views
from coordinator.receiving import REJECTED_BURST, REJECTED_PER_S, Receiving, TokenBucket
from coordinator.records import StoredBest
from coordinator.sharing import Sharing
from coordinator.store import RUN_LOCK_WAIT_S, Store
from coordinator.thinning import HistoryPolicy
from coordinator.writes import StoreError
from hysid_model.loops import LoopSet
from island.config import CampaignConfig, decode_config, encode_config
from island.coordinator_messages import Best, encode_best
from island.island_messages import Migrants
from island.joining import key_prefix
from island.protocol import encode_signed_config
from island.sealing import ReplayGuard
from island.termination import Termination


class Coordinator(Admission, Receiving, Intake):
    """One campaign's coordinator state machine (see the module docstring; joins, members' shares and the roster:
    :class:`coordinator.admission.Admission`; what arrives and how it is handled: :class:`coordinator.receiving.Receiving`;
    the histories, migrants and global best: :class:`coordinator.intake.Intake`)."""

    def __init__(
        self,
        store: Store,
        config: CampaignConfig,
        loops: LoopSet,
        termination: Termination | None = None,
        *,
        dataset: str = "",
        resume: bool = False,
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
        budget and the stall rule: :meth:`coordinator.admission.Admission.countable`)."""
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
        """Whether migrant messages are followed (:data:`coordinator.intake.FOLLOWS_MIGRANTS_UP_TO`; a resumed campaign that stopped does not start again)."""
        self.superseded = store.superseded(self.name)
        """Migrant messages superseded in the inbox (a newer one of the island replaced them) before they were handled."""
        self._replays = ReplayGuard()
        self._evaluated: OrderedDict[bytes, float] = OrderedDict()
        self._candidates: dict[str, Migrants] = {}
        """Each island's newest migrant message handled since the last commit, not evaluated yet (:meth:`coordinator.intake.Intake.consider_migrants`)."""
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

    # --- the stop rules (checked by the run loop, coordinator.loop) ------------------------
    def rule_stop(self) -> str | None:
        """The stop rule (budget, target, stall, time) that holds now, if any (the budget and the stall rule count the
        evaluations that count: :meth:`coordinator.admission.Admission.countable`)."""
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
        end = CampaignEnd(
            self.store,
            self.config,
            self.loops,
            self.termination,
            self.best,
            self.stop_reason,
            {i: m.status for i, m in self.members.items()},
            [(key, info.algo) for key, info in self.runs.items()],
            list(self.sharing.moves),
        )
        return campaign_outcome(end, polish_best=polish_best)


def resume(store: Store, name: str, termination: Termination | None = None) -> Coordinator:
    """The coordinator of a stored campaign, with its history, islands, runs and best as they were, and its keys
    (:mod:`coordinator.keys`)."""
    _, message, _ = store.campaign(name)
    config, loops = decode_config(message, name)
    return Coordinator(store, config, loops, termination, resume=True)
