"""The island node: one ask/tell optimizer, cooperating with other islands through a transport.

The node holds no optimizer logic. It drives :func:`island.run.run` (ask ->
evaluate -> tell) and uses its hooks:

* it joins the campaign first: the coordinator issues its run id and keys
  (:class:`island.sealing.Credentials`), and every message it sends is sealed
  with them;
* after every iteration the history row goes to the coordinator (in batches,
  every ``history_every_s``; iteration, best fitness, evaluations, wall time),
  and at once at every migration: the coordinator counts a mixed campaign's
  rounds in migration intervals (:mod:`island.share`), so what it decides at
  the end of one does not wait for a timer;
* every ``migration.interval`` iterations (the *epoch*) it publishes its ``k``
  best candidates and takes what its in-neighbours (:mod:`island.migration`)
  sent. Each message is validated as it arrives (:mod:`island.protocol`:
  form, the signature of its sender's run with the public key the roster
  lists for it, then replays: nobody can sign as another island, nor move
  another's replay window), rejects are counted, and of each sender only the
  newest message is kept: an epoch takes at most ``k`` migrants from each
  in-neighbour, so a flood cannot starve the evolution. A message from a run
  the roster does not list yet waits (up to :data:`JOIN_GRACE_S`, the newest of
  each sender) for it; one that waited in vain (its run never listed, a newer one of its sender
  came, or the island ended first) counts as rejected.
  Every migrant's fitness is **re-evaluated locally** (the claimed value is
  never used), and the optimizer's migrant policy decides what to replace;
* who is a member, and the stop order, come from the coordinator's signed
  ``control`` messages (a liveliness token alone makes nobody a member); the
  ring follows the roster's order of joining, and skips a member that sent no
  migrants for the transport's ``silent_s``, so that a silent member cannot
  starve the island after it;
* a late joiner takes the coordinator's current global best the same way;
* on a model with memory (Bouc-Wen, one a single run cannot be trusted on) it is a memetic
  island (:class:`island.memetic.Island`), as ``hysid fit``'s are: its optimizer searches in the
  coordinates of :mod:`island.space` (migrants and its best are converted at the node's edges,
  so nothing on the wire or in the database changes), refines its best every few iterations,
  starts from the campaign's ``start`` and the points the model's terms read off the loops, and
  restarts once it has stalled unless it holds the campaign's best as far as it knows
  (:meth:`IslandNode._leads`); the refinements count with its evaluations. On memoryless models
  (the thesis', Coulomb friction's in the mixed-islands bench) it searches as the thesis' islands do;
* when the roster assigns its run another algorithm (a mixed campaign's
  staged or adaptive share, :mod:`island.share`), it carries its search on with that
  algorithm from the next iteration;
* it stops at the coordinator's stop order or when its own budget is spent,
  then waits (bounded) until the coordinator confirms it has committed every
  history row, serving the rows it asks for again (e.g. after a restart).

A :class:`Transport` carries the bytes (:mod:`island.transports`: over
Zenoh, one process per island, or in memory, islands as threads of one
process).
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict
from typing import Protocol

import numpy as np

from hysid_model.objective import Objective
from hysid_model.thesis_port import ThesisObjective
from island.algorithms import make_optimizer, switch_algorithm
from island.config import CampaignConfig
from island.memetic import IMPROVED, Island, starting_points
from island.migration import in_neighbours
from island.population import PopulationOptimizer
from island.protocol import (
    STAT_NAMES,
    Best,
    History,
    Migrants,
    decode_best,
    encode_history,
    encode_migrants,
    migrants_of,
)
from island.run import HistoryRow, run
from island.sealing import Counter, Credentials, Envelope, ReplayGuard, check_replay, envelope, open_envelope
from island.space import SpaceObjective
from island.wire import MessageRejected, check_name

START_TIMEOUT_S = 60.0
"""Longest wait for ``min_islands`` members before an island starts anyway."""
HISTORY_CHUNK = 20_000
"""History rows per message (well under :data:`island.protocol.MAX_ROWS`)."""
MAX_SENDERS = 1024
"""Senders whose newest migrant message an island keeps between two epochs."""
JOIN_GRACE_S = 5.0
"""How long migrants from a sender that is not (yet) a member wait for the roster to list it.

Zenoh does not order the coordinator's roster before a joiner's first
publications, so a joiner's first migrants can arrive before the island knows
it is a member."""


class Transport(Protocol):
    """How an island's messages travel (bytes in, bytes out)."""

    credentials: Credentials
    """The island run's identity: issued when it joined."""
    silent_s: float | None
    """A ring member that sent no migrants for this long is skipped (None: every member sends at every epoch)."""

    def exchange(self, epoch: int, payload: bytes) -> list[tuple[str, bytes]]:
        """Publish this island's migrants; return ``(sender, message)`` pairs the node should still
        :meth:`IslandNode.receive` (a transport may hand them over as they arrive instead)."""

    def publish_history(self, payload: bytes) -> None: ...

    def members(self) -> list[str]:
        """Islands currently alive in the campaign, in the order they joined."""

    def key_for(self, island: str, run: str) -> bytes | None:
        """The public key of a member's run (None: the roster does not list it)."""

    def stop_requested(self) -> bool:
        """The coordinator ordered the stop, or (Zenoh) it has been silent for longer than the island waits."""

    def global_best(self) -> list[bytes]:
        """Answers to the question for the coordinator's current best (asked once, when the island starts)."""

    def stop_reason(self) -> str:
        """Why :meth:`stop_requested` holds."""

    def wait_for_members(self, n: int, timeout_s: float) -> None:
        """Return once ``n`` islands have joined (or after ``timeout_s``, or on a stop order)."""

    def confirm(self, iteration: int) -> bool:
        """Wait (bounded) until the coordinator has committed this run's rows up to ``iteration``."""

    def assigned_algo(self) -> str | None:
        """The algorithm the coordinator tells this run to run (None: it has not said)."""


class IslandNode:
    """One island of a campaign (see the module docstring)."""

    def __init__(
        self,
        island: str,
        algo: str,
        seed: int,
        config: CampaignConfig,
        objective: Objective | ThesisObjective,
        *,
        history_every_s: float = 0.25,
    ) -> None:
        self.island = check_name("island", island)
        self.space = SpaceObjective(objective) if isinstance(objective, Objective) and objective.model.has_memory else None
        """The objective in the coordinates of :mod:`island.space` where the island is memetic (module docstring)."""
        self.optimizer: PopulationOptimizer | Island = make_optimizer(algo, objective.bounds, seed, config.island_options(algo)) if self.space is None else Island(
            self.space, algo, seed, config.island_options(algo), starts=self._u(starting_points(objective, config.start)))
        self.algo = algo
        self.seed = seed
        self.config = config
        self.objective = objective
        self.credentials: Credentials | None = None
        self.history_every_s = history_every_s
        self.stats = dict.fromkeys(STAT_NAMES, 0)
        self.rows: list[tuple[int, float, int, float]] = []
        self.migrant_evaluations = 0
        self.moves: list[tuple[int, str, str]] = []
        """``(iteration, from, to)`` each time the coordinator moved this island to another algorithm
        (the new one runs from the next iteration on)."""
        self.stop_reason = ""
        self.finished = False
        """The run is over (its last history message says so)."""
        self.confirmed: bool | None = None
        """Whether the coordinator confirmed every row at the end (None: not asked)."""
        self._published = 0
        self._last_flush = 0.0
        self._snapshot: tuple[np.ndarray, float] = (objective.bounds.mean(axis=1), np.inf)
        self._best_in: Best | None = None
        self._transport: Transport | None = None
        self._seq = Counter()
        self._lock = threading.Lock()
        self._replays = ReplayGuard()
        self._latest: OrderedDict[str, tuple[float, Migrants]] = OrderedDict()
        """Each sender's newest valid migrant message and when it arrived (see :data:`JOIN_GRACE_S`)."""
        self._pending: OrderedDict[str, tuple[float, Envelope]] = OrderedDict()
        """Each sender's newest message from a run the roster does not list yet (checked once it does)."""
        self._taken: dict[str, tuple[str, int]] = {}
        """Per sender, the (run, seq) of the message last taken in."""

    @property
    def run_id(self) -> str:
        return "" if self.credentials is None else self.credentials.run

    def _attached(self) -> tuple[Transport, Credentials]:
        """The transport and the run's credentials; a :class:`RuntimeError` before :meth:`attach` (the
        node used before it joined: a caller's mistake, not bad input)."""
        if self._transport is None or self.credentials is None:
            raise RuntimeError(f"island {self.island!r} has not joined: attach a transport (IslandNode.attach or run) first")
        return self._transport, self.credentials

    def count_rejected(self) -> None:
        with self._lock:
            self.stats["rejected"] += 1

    # --- the loop ---------------------------------------------------------------
    def attach(self, transport: Transport) -> None:
        """Take messages through ``transport`` from now on (its credentials are the island's)."""
        self._transport = transport
        self.credentials = transport.credentials

    def run(self, transport: Transport) -> list[tuple[int, float, int, float]]:
        """Optimize until done or stopped; returns the rows ``(iteration, best, evaluations, wall s)``."""
        self.attach(transport)
        transport.wait_for_members(self.config.min_islands, START_TIMEOUT_S)
        self._best_in = next((b for b in map(self._decode_best, transport.global_best()) if b is not None), None)
        try:
            run(self.optimizer, self.space or self.objective, callback=self._record, should_stop=transport.stop_requested, migrate=self._migrate)
            self.stop_reason = transport.stop_reason() if transport.stop_requested() else "own budget spent"
        finally:
            self.finished = True
            with self._lock:  # what still waits for its run to join has waited in vain
                self.stats["rejected"] += len(self._pending)
                self._pending.clear()
            self._flush(final=True)
        self.confirmed = transport.confirm(self.rows[-1][0] if self.rows else -1)
        return list(self.rows)

    def _record(self, row: HistoryRow) -> None:
        self.rows.append((row.iteration, row.best_fitness, row.evaluations + self.migrant_evaluations, row.wall_s))
        x, f = self.optimizer.best(1)
        if not f[0] > self._snapshot[1]:  # the best so far: a memetic island's fresh search after a restart starts above it
            self._snapshot = (self._theta(x[0]), float(f[0]))
        interval = self.config.migration.interval
        if time.monotonic() - self._last_flush >= self.history_every_s or (interval and row.iteration and row.iteration % interval == 0):
            self._flush()

    # --- migrants -----------------------------------------------------------------
    def receive(self, sender: str, data: bytes) -> None:
        """A migrant message as it arrives (from any thread): checked against the public key of its
        sender's run and for replays, counted if rejected, else kept as ``sender``'s newest; a run the
        roster does not list yet waits for it (:meth:`_listed`)."""
        transport, _ = self._attached()
        if sender == self.island:
            return  # our own publication, back through the subscription to every island's migrants
        try:
            env = envelope(data, "migrants", self.config.name, sender)
        except MessageRejected:
            self.count_rejected()
            return
        key = transport.key_for(env.sender, env.run)
        if key is None:
            with self._lock:
                waited = int(self._pending.pop(env.sender, None) is not None)  # a newer one of a joiner: the older waited in vain
                self._pending[env.sender] = (time.monotonic(), env)
                while len(self._pending) > MAX_SENDERS:
                    self._pending.popitem(last=False)
                    waited += 1
                self.stats["rejected"] += waited
            return
        self._open(env, key)

    def _open(self, env: Envelope, key: bytes) -> None:
        try:
            m = migrants_of(open_envelope(env, key), self.config.name, self.objective.bounds, time.time())
            check_replay(self._replays, "migrants", m.island, m.run, m.seq)
        except MessageRejected:
            self.count_rejected()
            return
        members = set(self._transport.members()) if self._transport is not None else set()
        with self._lock:
            if m.island not in self._latest and len(self._latest) >= MAX_SENDERS:
                strangers = [s for s in self._latest if s not in members]
                if not strangers and m.island not in members:
                    return  # no room for yet another stranger
                del self._latest[strangers[0] if strangers else next(iter(self._latest))]
            self._latest.pop(m.island, None)
            self._latest[m.island] = (time.monotonic(), m)

    def _listed(self) -> None:
        """Check the waiting messages whose run the roster lists by now; those older than :data:`JOIN_GRACE_S`
        are rejected (their run never joined)."""
        transport, _ = self._attached()
        now = time.monotonic()
        with self._lock:
            waiting = list(self._pending.items())
        for sender, (at, env) in waiting:
            key = transport.key_for(env.sender, env.run)
            if key is not None or now - at >= JOIN_GRACE_S:
                with self._lock:
                    if self._pending.get(sender, (None, None))[1] is env:
                        del self._pending[sender]
                if key is not None:
                    self._open(env, key)
                else:
                    self.count_rejected()

    def _follow_assignment(self) -> PopulationOptimizer:
        """The optimizer to go on with: this one, or its search carried on by the algorithm the
        coordinator now assigns this run (a mixed campaign's staged or adaptive share, :mod:`island.share`)."""
        transport, _ = self._attached()
        algo = transport.assigned_algo()
        if algo is not None and algo != self.algo and algo in self.config.algos:
            options = self.config.island_options(algo)
            self.optimizer = self.optimizer.switch(algo, options) if isinstance(self.optimizer, Island) else switch_algorithm(self.optimizer, algo, options)
            self.moves.append((self.optimizer.iteration, self.algo, algo))
            self.algo = algo
        return self.optimizer

    def _migrate(self, optimizer: PopulationOptimizer) -> PopulationOptimizer:
        """After an iteration: follow a new assignment, take the starting point and the global best
        in once, and migrate every ``migration.interval`` iterations; returns the optimizer to go on with."""
        transport, credentials = self._attached()
        optimizer = self._follow_assignment()
        if isinstance(optimizer, Island):
            optimizer.refine()
            if optimizer.stale and not self._leads(optimizer, transport.members()):
                optimizer.restart()  # at its next iteration: it migrates what it has first
        elif optimizer.iteration == 0 and self.config.start is not None:  # the campaign's starting point joins first
            x = np.array(self.config.start, dtype=float)[None, :]
            self.migrant_evaluations += 1
            optimizer.inject(x, self.objective(x))
        if self._best_in is not None:
            self._take([self._best_in.x[None, :]])
            self._best_in = None
        mig = self.config.migration
        if mig.interval == 0 or optimizer.iteration == 0 or optimizer.iteration % mig.interval:
            return optimizer
        epoch = optimizer.iteration // mig.interval
        x, f = optimizer.best(mig.k)
        outgoing = encode_migrants(
            Migrants(self.config.name, self.island, self.run_id, optimizer.iteration, self._theta(x), f, time.time(), self._seq()), credentials
        )
        for sender, data in transport.exchange(epoch, outgoing):
            self.receive(sender, data)
        with self._lock:
            self.stats["sent"] += 1
        self._listed()
        roster = transport.members()
        senders = in_neighbours(mig.topology, self._sending(roster), self.island, epoch=epoch, seed=self.config.seed, random_k=mig.random_k)
        self._take(self._intake(senders, set(roster), mig.k))
        return optimizer

    def _sending(self, members: list[str]) -> list[str]:
        """The members (in the order they joined) that sent migrants within the transport's ``silent_s``,
        and this island: a member that sends nothing is no ring neighbour."""
        silent_s = self._transport.silent_s if self._transport is not None else None
        if silent_s is None:
            return members
        now = time.monotonic()
        with self._lock:
            heard = {sender for sender, (at, _) in self._latest.items() if now - at <= silent_s}
        return [m for m in members if m == self.island or m in heard]

    def _intake(self, senders: set[str], members: set[str], k: int) -> list[np.ndarray]:
        """The newest untaken message of each in-neighbour (at most ``k`` migrants from each); migrants
        of non-members older than :data:`JOIN_GRACE_S` are forgotten."""
        now = time.monotonic()
        batches = []
        with self._lock:
            for sender, (at, m) in list(self._latest.items()):
                if sender in senders:
                    if self._taken.get(sender) != (m.run, m.seq):
                        batches.append(m.x[:k])
                        self._taken[sender] = (m.run, m.seq)
                elif sender not in members and now - at >= JOIN_GRACE_S:
                    del self._latest[sender]
        return batches

    def _take(self, batches: list[np.ndarray]) -> None:
        """Re-evaluate migrants here (never trusting their claimed fitness) and offer them to the optimizer."""
        if not batches:
            return
        x = self._u(np.vstack(batches))
        f = (self.space or self.objective)(x)
        self.migrant_evaluations += x.shape[0]
        taken = self.optimizer.inject(x, f)
        with self._lock:
            self.stats["received"] += x.shape[0]
            self.stats["taken"] += taken

    def _leads(self, island: Island, roster: list[str]) -> bool:
        """Whether this memetic ``island`` holds the campaign's best as far as it knows: the newest migrants
        of every other member of ``roster`` (each island hears them all) show no better best, nor an equal one
        of a member that joined before it; the lowest claim among them is re-evaluated here (a claim is never
        trusted)."""
        with self._lock:
            claims = [(float(m.claimed.min()), roster.index(s), m.x[int(np.argmin(m.claimed))]) for s, (_, m) in self._latest.items()
                      if s in roster and s != self.island]
        if not claims:
            return True
        _, rank, x = min(claims, key=lambda c: c[:2])
        theirs, mine = float(self.objective(x[None, :])[0]), island.fitness
        self.migrant_evaluations += 1
        earlier = self.island in roster and roster.index(self.island) < rank
        return theirs > mine * (1 + IMPROVED) or (theirs >= mine * (1 - IMPROVED) and earlier)

    def _u(self, x: np.ndarray) -> np.ndarray:
        """Parameter vectors in the optimizer's coordinates (the memetic island's, :mod:`island.space`)."""
        return x if self.space is None else self.space.space.to_u(x)

    def _theta(self, x: np.ndarray) -> np.ndarray:
        """The optimizer's vectors in the model's parameters, as they travel and are stored."""
        return x.copy() if self.space is None else self.space.space.to_theta(x)

    def _decode_best(self, data: bytes) -> Best | None:
        _, credentials = self._attached()
        try:
            return decode_best(data, self.config.name, self.objective.bounds, credentials.coordinator)
        except MessageRejected:
            self.count_rejected()
            return None

    # --- history ---------------------------------------------------------------------
    def history_messages(self, since: int = -1, final: bool = False) -> list[bytes]:
        """This island's rows after iteration ``since`` (in chunks of :data:`HISTORY_CHUNK`), each
        with its best so far and its counters; ``final`` marks the last one as its goodbye."""
        _, credentials = self._attached()
        rows = np.array([r for r in list(self.rows) if r[0] > since], dtype=float).reshape(-1, 4)
        x, f = self._snapshot
        with self._lock:
            stats = dict(self.stats)
        chunks = [rows[i : i + HISTORY_CHUNK] for i in range(0, rows.shape[0], HISTORY_CHUNK)] or [rows]
        return [
            encode_history(History(
                self.config.name, self.island, self.run_id, self.algo, self.seed, chunk, x, f, stats,
                final and i == len(chunks) - 1, self._seq(), self.optimizer.gain,
            ), credentials)
            for i, chunk in enumerate(chunks)
        ]

    def heartbeat(self) -> bytes:
        """A history message without rows (from any thread): the island is alive while it has no new row."""
        _, credentials = self._attached()
        x, f = self._snapshot
        with self._lock:
            stats = dict(self.stats)
        return encode_history(History(
            self.config.name, self.island, self.run_id, self.algo, self.seed, np.zeros((0, 4)), x, f, stats, False, self._seq(), self.optimizer.gain,
        ), credentials)

    def _flush(self, final: bool = False) -> None:
        transport, _ = self._attached()
        published = self._published
        if published == len(self.rows):
            if not final:
                return
            published = max(published - 1, 0)  # the goodbye carries the last row again
        last = self.rows[published - 1][0] if published else -1
        for message in self.history_messages(since=last, final=final):
            transport.publish_history(message)
        self._published = len(self.rows)
        self._last_flush = time.monotonic()
