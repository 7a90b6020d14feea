"""The campaign coordinator: serves the loop set, tracks islands, records everything, decides when to stop.

All incoming traffic (island histories and migrants, membership changes)
lands in one queue and is handled by one thread, which owns the SQLite store
(:mod:`coordinator.store`) and commits after every batch. The coordinator

* serves ``config`` (campaign configuration + loop set) and ``best``;
* records joins, graceful leaves (a final history, then the token goes) and
  losses (the token goes without a final history: crash, kill, or a frozen
  process whose Zenoh lease expired);
* stores every history row and migrant message, and every rejected message
  with its reason;
* keeps the global best, **re-evaluating** any candidate that claims to beat
  it (a claimed fitness is never trusted) and publishes it for late joiners;
* after a restart (``--resume``) asks every live island for the history rows
  it missed;
* stops by the rules of :class:`island.termination.Termination` (a total
  evaluation budget, a target fitness, a stall, a time limit) or when every
  island has finished; then re-evaluates every island's best and polishes the
  global best (section 3.1's calculus-based refinement):
  :meth:`Coordinator.outcome` is the raw material of the report that
  :mod:`hysid.campaigns` builds, the same as ``hysid fit``'s.

:class:`coordinator.links.ZenohLink` wires a coordinator to a Zenoh session;
single-node campaigns feed the same queue from island threads
(:mod:`coordinator.launch`).
"""

from __future__ import annotations

import queue
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, Protocol

import numpy as np

from coordinator.store import IslandRecord, Store, StoredBest
from hysid_model.errors import HysidInputError
from hysid_model.loops import LoopSet
from hysid_model.model import MAX_WIDENINGS
from hysid_model.objective import Objective
from island.config import CampaignConfig, decode_config, encode_config
from island.node import key_prefix
from island.protocol import NAME_PATTERN, Best, History, MessageRejected, decode_history, decode_migrants, encode_best, encode_stop
from island.run import RunResult, polish_run
from island.termination import Termination

LEAVE_GRACE_S = 0.3
"""After a token disappears, how long a final history may still arrive to count as a graceful leave."""
STATUS_AFTER = {"join": "alive", "seen": "alive", "back": "alive", "left": "left", "lost": "lost"}
"""A member's status after each recorded membership event."""
STOP_GRACE_S = 10.0
"""After the stop order, how long to wait for islands' final histories."""
BACKFILL_EVERY_S = 2.0
BACKFILL_ATTEMPTS = 5
"""How often, and how many times without progress, to ask an island again for history rows still missing."""


@dataclass
class CampaignOutcome:
    """What a finished campaign leaves: the objective, every island run (best re-evaluated, the global
    best polished), the settings, and the islands, migrations and membership events as stored."""

    objective: Objective
    runs: list[RunResult]
    settings: dict[str, Any]
    islands: list[dict[str, Any]]
    migrations: dict[str, Any]
    members: list[dict[str, Any]]


class Link(Protocol):
    """What the coordinator sends out (Zenoh publications, or in-process for single-node campaigns)."""

    def announce_stop(self, message: bytes) -> None: ...

    def publish_best(self, message: bytes) -> None: ...

    def request_history(self, island: str, run: str, since: int) -> None:
        """Ask an island for its rows after ``since``; the answer arrives in the inbox as a history message."""


@dataclass
class Member:
    status: str = "alive"
    """alive, left (said goodbye), lost (vanished: crash, kill, lease expired)"""
    run: str = ""
    gone_at: float | None = None


@dataclass
class IslandView:
    """What progress shows of one island run."""

    algo: str
    iteration: int = 0
    best: float = np.inf
    final: bool = False


@dataclass
class CampaignProgress:
    """A snapshot of a running campaign, for a live view."""

    elapsed_s: float
    evaluations: int
    best: float
    members: dict[str, str]
    islands: dict[str, IslandView]
    migrations: int
    rejected: int


class Coordinator:
    """One campaign's coordinator state machine (see the module docstring)."""

    def __init__(
        self, store: Store, config: CampaignConfig, loops: LoopSet, termination: Termination | None = None, *, dataset: str = "", resume: bool = False
    ) -> None:
        self.store = store
        self.config = config
        self.name = config.name
        self.loops = loops
        self.objective = config.objective(loops)
        self.termination = termination or Termination()
        self.config_message = encode_config(config, loops)
        if not resume:
            store.create_campaign(self.name, dataset, self.config_message)
        else:
            store.set_status(self.name, "running")
        self.inbox: queue.Queue[tuple[Any, ...]] = queue.Queue()
        self.members: dict[str, Member] = {}
        self.islands: dict[tuple[str, str], IslandView] = {}
        self.run_evaluations: dict[tuple[str, str], int] = {}
        for rec in store.islands(self.name):
            self.run_evaluations[(rec.island, rec.run)] = rec.evaluations
            self.islands[(rec.island, rec.run)] = IslandView(rec.algo, rec.iterations, rec.best_fitness, rec.final)
        self.best: StoredBest | None = store.best(self.name)
        self.best_message: bytes | None = None if self.best is None else self._best_message()
        self.migrations = store.count("migrations", self.name)
        self.rejected = store.count("rejected", self.name)
        self.started = time.monotonic()
        self.stop_reason: str | None = None
        self.full_at: float | None = None
        """``time.monotonic()`` when ``min_islands`` islands were first alive: the islands start searching."""
        self.best_trace: list[tuple[float, float, int, np.ndarray]] = []
        """``(time.monotonic(), fitness, total evaluations, x)`` at every improvement of the global best."""
        self.member_events = 0
        """Membership events recorded by this process (progress is shown at each)."""
        self.contiguous: dict[tuple[str, str], int] = {}
        """Per island run, the last iteration k with 0..k all stored (rows beyond a gap are asked for again)."""
        self.last_stored: dict[tuple[str, str], int] = {}
        self._backfill: dict[tuple[str, str], tuple[float, int, int]] = {}
        """Per island run: when rows were last asked for, from which iteration, how often without progress."""

    # --- state -------------------------------------------------------------------
    @property
    def evaluations(self) -> int:
        return int(sum(self.run_evaluations.values()))

    def progress(self) -> CampaignProgress:
        return CampaignProgress(
            elapsed_s=time.monotonic() - self.started,
            evaluations=self.evaluations,
            best=np.inf if self.best is None else self.best.fitness,
            members={i: m.status for i, m in self.members.items()},
            islands={f"{i}" if sum(k[0] == i for k in self.islands) == 1 else f"{i}/{r}": v for (i, r), v in self.islands.items()},
            migrations=self.migrations,
            rejected=self.rejected,
        )

    def _best_message(self) -> bytes:
        assert self.best is not None
        return encode_best(Best(self.name, self.best.island, self.best.x, self.best.fitness))

    # --- handling what arrives ----------------------------------------------------------
    def handle(self, link: Link, item: tuple[Any, ...]) -> None:
        """One inbox item: ``("msg", key, payload)`` or ``("member", island, alive)``."""
        if item[0] == "member":
            self._member(link, item[1], item[2])
            return
        _, key, payload = item
        kind, _, sender = key[len(key_prefix(self.name)) + 1 :].partition("/")
        try:
            if kind == "history":
                self._history(link, decode_history(payload, self.name, self.objective.bounds, sender))
            elif kind == "migrants":
                self._migrants(link, payload, sender)
            else:
                raise MessageRejected("schema", f"unexpected key {key[:100]}")
        except MessageRejected as exc:
            self.store.add_rejected(self.name, key, exc.reason, str(exc), len(payload))
            self.rejected += 1

    def _member(self, link: Link, island: str, alive: bool) -> None:
        if not NAME_PATTERN.match(island):
            self.store.add_rejected(self.name, f"members/{island}", "sender", "liveliness token with an invalid island name", 0)
            self.rejected += 1
            return
        member = self.members.get(island)
        if alive:
            event = "join" if member is None else ("back" if member.status != "alive" else "seen")
            run = member.run if member else self._latest_run(island)
            self.members[island] = Member("alive", run)
            self._event(island, event)
            if self.full_at is None and sum(m.status == "alive" for m in self.members.values()) >= self.config.min_islands:
                self.full_at = time.monotonic()
            link.request_history(island, run, self._contiguous((island, run)) if run else -1)
        elif member is not None and member.status == "alive":
            if self.islands.get((island, member.run), IslandView("")).final:
                member.status = "left"
                self._event(island, "left")
            else:
                member.gone_at = time.monotonic()

    def _event(self, island: str, event: str) -> None:
        self.store.member_event(self.name, island, event)
        self.member_events += 1

    def _latest_run(self, island: str) -> str:
        """The island's run with the most iterations on record ("" if none): after a coordinator
        restart, the run that is probably still going."""
        runs = [(view.iteration, run) for (i, run), view in self.islands.items() if i == island]
        return max(runs)[1] if runs else ""

    def _contiguous(self, key: tuple[str, str]) -> int:
        if key not in self.contiguous:
            self.contiguous[key] = self.store.contiguous_iterations(self.name, *key)
            self.last_stored[key] = self.store.last_iteration(self.name, *key)
        return self.contiguous[key]

    def _check_gap(self, link: Link, key: tuple[str, str], first: int, last: int) -> None:
        """Track the stored iterations of an island run after rows ``first..last`` arrived; while
        some are missing (sent while this coordinator was down), ask the island for them again."""
        if key in self.contiguous:
            done, top = self.contiguous[key], self.last_stored[key]
            if first <= done + 1:
                self.contiguous[key] = self.store.contiguous_iterations(self.name, *key) if top > last else max(done, last)
            self.last_stored[key] = max(top, last)
        else:
            self._contiguous(key)
        done, now = self.contiguous[key], time.monotonic()
        asked_at, asked_from, attempts = self._backfill.get(key, (-np.inf, -2, 0))
        if done < self.last_stored[key] and now - asked_at >= BACKFILL_EVERY_S:
            attempts = attempts + 1 if asked_from == done else 1
            if attempts <= BACKFILL_ATTEMPTS:  # an island that cannot fill the gap is not asked forever
                self._backfill[key] = (now, done, attempts)
                link.request_history(key[0], key[1], done)

    def _settle_departures(self) -> None:
        """Tokens gone without a final history for ``LEAVE_GRACE_S``: the island is lost."""
        now = time.monotonic()
        for island, member in self.members.items():
            if member.status == "alive" and member.gone_at is not None and now - member.gone_at >= LEAVE_GRACE_S:
                member.status = "lost"
                self._event(island, "lost")

    def _history(self, link: Link, h: History) -> None:
        key = (h.island, h.run)
        self.store.add_history(self.name, h.island, h.run, h.rows)
        if h.rows.size:
            self._check_gap(link, key, int(h.rows[0, 0]), int(h.rows[-1, 0]))
        iterations = int(h.rows[:, 0].max()) if h.rows.size else 0
        evaluations = int(h.rows[:, 2].max()) if h.rows.size else 0
        self.store.update_island(self.name, IslandRecord(
            h.island, h.run, h.algo, h.seed, iterations, evaluations, h.best_f, h.best_x,
            h.stats["sent"], h.stats["received"], h.stats["taken"], h.stats["rejected"], h.final,
        ))
        self.run_evaluations[key] = max(self.run_evaluations.get(key, 0), evaluations)
        view = self.islands.setdefault(key, IslandView(h.algo))
        view.iteration = max(view.iteration, iterations)
        view.best = min(view.best, h.best_f)
        view.final = view.final or h.final
        member = self.members.get(h.island)
        if member is not None:
            member.run = h.run
            if h.final and member.status == "alive" and member.gone_at is not None:
                member.status = "left"
                self._event(h.island, "left")
        self._consider(link, h.island, h.best_x, h.best_f)

    def _migrants(self, link: Link, payload: bytes, sender: str) -> None:
        m = decode_migrants(payload, self.name, self.objective.bounds, sender)
        self.store.add_migration(self.name, m.island, m.run, m.iteration, m.x.shape[0], float(m.claimed.min()), m.sent_at)
        self.migrations += 1
        i = int(np.argmin(m.claimed))
        self._consider(link, m.island, m.x[i], float(m.claimed[i]))

    def _consider(self, link: Link, island: str, x: np.ndarray, claimed: float) -> None:
        """Re-evaluate a candidate that claims to beat the global best; if it really does, it is the new best."""
        if self.best is not None and not claimed < self.best.fitness:
            return
        f = float(self.objective(x[None, :])[0])
        if not np.isfinite(f) or (self.best is not None and not f < self.best.fitness):
            return
        self.best = StoredBest(island, np.array(x, dtype=float), f, self.evaluations)
        self.best_trace.append((time.monotonic(), f, self.evaluations, self.best.x))
        self.store.set_best(self.name, self.best)
        self.best_message = self._best_message()
        link.publish_best(self.best_message)

    # --- the loop -----------------------------------------------------------------
    def check_stop(self) -> str | None:
        best = self.best
        reason = self.termination.reason(
            evaluations=self.evaluations,
            best=np.inf if best is None else best.fitness,
            best_at=0 if best is None else best.evaluations,
            elapsed_s=time.monotonic() - self.started,
        )
        if reason:
            return reason
        finished = self.islands and all(v.final for v in self.islands.values()) and all(m.status != "alive" for m in self.members.values())
        if finished and len({island for island, _ in self.islands} | set(self.members)) >= self.config.min_islands:
            return "every island finished"
        return None

    def drain(self, link: Link, timeout: float) -> None:
        """Handle what arrived (waiting up to ``timeout`` for the first item) and commit."""
        try:
            item = self.inbox.get(timeout=timeout)
        except queue.Empty:
            self._settle_departures()
            self.store.commit()
            return
        while True:
            self.handle(link, item)
            try:
                item = self.inbox.get_nowait()
            except queue.Empty:
                break
        self._settle_departures()
        self.store.commit()

    def serve(
        self,
        link: Link,
        on_progress: Callable[[CampaignProgress], None] | None = None,
        *,
        extra_stop: Callable[[], str | None] | None = None,
        progress_every_s: float = 1.0,
    ) -> str:
        """Run until a stop rule, ``extra_stop()`` or Ctrl-C; announce the stop, collect final histories; returns the reason."""
        last, shown_events = 0.0, -1
        try:
            while self.stop_reason is None:
                self.drain(link, timeout=0.05)
                self.stop_reason = self.check_stop() or (extra_stop() if extra_stop is not None else None)
                if on_progress is not None and (time.monotonic() - last >= progress_every_s or self.member_events != shown_events):
                    on_progress(self.progress())
                    last, shown_events = time.monotonic(), self.member_events
        except KeyboardInterrupt:  # Ctrl-C (SIGINT) stops the campaign like a stop rule; a second one aborts
            self.stop_reason = "interrupted"
        self.store.set_status(self.name, "stopping", self.stop_reason)
        message = encode_stop(self.name, self.stop_reason)
        deadline = time.monotonic() + STOP_GRACE_S
        while time.monotonic() < deadline and any(m.status == "alive" for m in self.members.values()):
            link.announce_stop(message)
            for _ in range(10):
                self.drain(link, timeout=0.05)
        self.drain(link, timeout=LEAVE_GRACE_S)
        self.store.set_status(self.name, "stopped", self.stop_reason)
        if on_progress is not None:
            on_progress(self.progress())
        return self.stop_reason

    # --- the outcome ----------------------------------------------------------------
    def outcome(self, *, polish_best: bool = True) -> CampaignOutcome:
        """Every island run with its best re-evaluated here, the global best polished (as ``hysid fit`` does)."""
        objective = replace(self.config, objective_kind="closed_form").objective(self.loops)
        records = self.store.islands(self.name)
        history: dict[tuple[str, str], list[dict[str, float]]] = {}
        for island, run, it, f, ev, wall in self.store.history(self.name):
            history.setdefault((island, run), []).append({"iteration": it, "best_fitness": f, "evaluations": ev, "wall_s": wall})
        several = {r.island for r in records if sum(q.island == r.island for q in records) > 1}
        runs = []
        for rec in records:
            f = float(objective(rec.best_x[None, :])[0])
            rows = history.get((rec.island, rec.run), [])
            runs.append(RunResult(
                label=f"{rec.island}/{rec.run}" if rec.island in several else rec.island, algo=rec.algo, seed=rec.seed,
                theta=rec.best_x, fitness=f, evaluations=rec.evaluations, history=rows, search_theta=rec.best_x,
                search_fitness=f, wall_s=rows[-1]["wall_s"] if rows else 0.0,
            ))
        global_best = None if self.best is None else float(objective(self.best.x[None, :])[0])
        if global_best is not None and (not runs or global_best < min(r.fitness for r in runs)):
            runs.append(RunResult(
                label=f"global best (from {self.best.island})", algo=runs[0].algo if runs else self.config.algos[0], seed=self.config.seed,
                theta=self.best.x, fitness=global_best, evaluations=0, history=[], search_theta=self.best.x,
                search_fitness=global_best, wall_s=0.0,
            ))
        if not runs:
            raise HysidInputError(f"campaign {self.name!r}: no island reported any result ({self.stop_reason or 'not run'})")
        best = int(np.argmin([r.fitness for r in runs]))
        widened: list[dict[str, Any]] = []
        if polish_best:
            runs[best] = polish_run(objective, runs[best])
            for _ in range(MAX_WIDENINGS):  # a best on a bound derived from the data: widen it and refit
                wider, changed = objective.model.widen_at(runs[best].theta)
                if not changed:
                    break
                old = dict(zip(objective.model.names, objective.model.bounds.tolist()))
                widened += [{"param": n, "from": old[n], "to": [float(b) for b in pair]} for n, pair in changed.items()]
                objective = Objective(objective.loops, wider, weights=objective.weights)
                runs[best] = polish_run(objective, runs[best])
        settings = {
            "campaign": self.name,
            "algo": "/".join(self.config.algos),
            "polish": polish_best,
            "algos": self.config.algos,
            "options": self.config.options,
            "migration": self.config.migration.as_dict(),
            "seed": self.config.seed,
            "stop_rules": self.termination.as_dict(),
            "stop_reason": self.stop_reason or self.store.stop_reason(self.name),
            "db": self.store.path,
            "bounds_from_data": list(self.config.soft),
            "bounds_widened": widened,
        }
        return CampaignOutcome(
            objective=objective,
            runs=runs,
            settings=settings,
            islands=self.island_summaries(records, runs),
            migrations=self.migration_summary(records),
            members=[{"island": i, "event": e, "t": t} for i, e, t in self.store.members(self.name)],
        )

    def island_summaries(self, records: list[IslandRecord], runs: list[RunResult]) -> list[dict[str, Any]]:
        """Each island run's record with its re-evaluated best and its membership status (as last recorded)."""
        recorded = {island: STATUS_AFTER[event] for island, event, _ in self.store.members(self.name)}
        status = recorded | {i: m.status for i, m in self.members.items()}
        return [
            {**rec.as_dict(), "best_fitness": run.search_fitness, "status": status.get(rec.island, "unknown")}
            for rec, run in zip(records, runs)
        ]

    def migration_summary(self, records: list[IslandRecord]) -> dict[str, Any]:
        return {
            **self.config.migration.as_dict(),
            "messages": self.store.count("migrations", self.name),
            "received": sum(r.received for r in records),
            "taken": sum(r.taken for r in records),
            "rejected": self.store.count("rejected", self.name),
            "rejected_reasons": self.store.rejected_reasons(self.name),
        }


def resume(store: Store, name: str, termination: Termination | None = None) -> Coordinator:
    """The coordinator of a stored campaign, with its history, islands and best as they were."""
    _, message, _ = store.campaign(name)
    config, loops = decode_config(message, name)
    return Coordinator(store, config, loops, termination, resume=True)
