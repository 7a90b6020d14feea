"""The island node: one ask/tell optimizer, cooperating with other islands through a transport.

The node holds no optimizer logic. It drives :func:`island.run.run` (ask ->
evaluate -> tell) and uses its hooks:

* it joins the campaign first: the coordinator issues its run id and keys
  (:class:`island.sealing.Credentials`), and every message it sends is sealed
  with them;
* after every iteration the history row goes to the coordinator (in batches,
  every ``history_every_s``, less often in a large campaign: :meth:`IslandNode.history_period`;
  iteration, best fitness, evaluations, wall time), and at once at every migration in a campaign
  of ordinary size: the coordinator counts a mixed campaign's rounds in migration intervals
  (:mod:`island.share`), so what it decides at the end of one does not wait for a timer;
* every ``migration.interval`` iterations (the *epoch*) it publishes its ``k``
  best candidates and takes what its in-neighbours (:mod:`island.migration`)
  sent. Each message is validated as it arrives (:mod:`island.arrivals`, once
  for every island of a process: form, the signature of its sender's run with
  the public key the roster lists for it, then replays), rejects are counted,
  and of each sender only the newest message is kept: an epoch takes at most
  ``k`` migrants from each in-neighbour, so a flood cannot starve the
  evolution. A message from a run the roster does not list yet waits for it;
  one that waited in vain is counted apart (``unlisted``) from those rejected.
  Every migrant's fitness is **re-evaluated locally** (the claimed value is
  never used), and the optimizer's migrant policy decides what to replace;
* who is a member, and the stop order, come from the coordinator's signed
  ``control`` messages (a liveliness token alone makes nobody a member); the
  ring follows the roster's order of joining, and skips a member that sent no
  migrants for the transport's ``silent_s``, so that a silent member cannot
  starve the island after it;
* a late joiner takes the coordinator's current global best the same way
  (unless the islands are isolated, migration interval 0: they take nothing
  from others, so that an island's seed alone decides its search);
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
  algorithm from the next iteration; with the staged share an exploring island waits for that
  order at the end of its first round (:mod:`island.handover`), however far behind the coordinator is;
* it stops at the coordinator's stop order or when its own budget is spent,
  then waits (bounded) until the coordinator confirms it has committed every
  history row, serving the rows it asks for again (e.g. after a restart).

A :class:`island.transport.Transport` carries the bytes (:mod:`island.transports`: over
Zenoh, any number of islands per process, or in memory, islands as threads of
one process).
"""

from __future__ import annotations

import threading
import time

import numpy as np

from hysid_model.objective import Objective
from hysid_model.thesis_port import ThesisObjective
from island.algorithms import make_optimizer, switch_algorithm
from island.arrivals import Arrivals
from island.config import CampaignConfig
from island.coordinator_messages import Best, decode_best
from island.handover import await_handover
from island.island_messages import STAT_NAMES, History, Migrants, encode_history, encode_migrants
from island.memetic import IMPROVED, Island, starting_points
from island.migration import in_neighbours
from island.population import PopulationOptimizer
from island.run import HistoryRow, run
from island.sealing import Counter, Credentials
from island.share import handover_iteration
from island.space import SpaceObjective
from island.transport import Transport
from island.turns import Turns
from island.wire import MessageRejected, check_name

START_TIMEOUT_S = 60.0
"""Longest wait for ``min_islands`` members before an island starts anyway."""
HISTORY_CHUNK = 20_000
"""History rows per message (well under :data:`island.island_messages.MAX_ROWS`)."""
HISTORY_EVERY_S = 0.25
"""How often an island sends its history rows by default."""
HISTORY_MESSAGES_PER_S = 1000.0
"""History messages a second a coordinator is asked to take from all its islands together: an island of a
campaign of more than 250 islands sends its rows less often than every :data:`HISTORY_EVERY_S`
(:meth:`IslandNode.history_period`)."""
HISTORY_PERIOD_MAX_S = 0.75
"""The longest an island holds its rows back: below the transports' heartbeat period (1 s), so that a running
island's history is its heartbeat."""


def history_period(every_s: float, members: int) -> float:
    """Seconds between two history messages of an island of a campaign of ``members`` islands: ``every_s``; in
    a campaign whose islands would send more than :data:`HISTORY_MESSAGES_PER_S` together at
    :data:`HISTORY_EVERY_S`, long enough for them to send that many (at most :data:`HISTORY_PERIOD_MAX_S`)."""
    scaled = members / HISTORY_MESSAGES_PER_S
    return every_s if scaled <= HISTORY_EVERY_S else max(every_s, min(scaled, HISTORY_PERIOD_MAX_S))


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
        history_every_s: float = HISTORY_EVERY_S,
        turns: Turns | None = None,
    ) -> None:
        """``turns``: shared with the other islands of a process, how many of them compute at once
        (:class:`island.turns.Turns`; None: this island computes whenever it can)."""
        self.island = check_name("island", island)
        self.space = SpaceObjective(objective) if isinstance(objective, Objective) and objective.model.has_memory else None
        """The objective in the coordinates of :mod:`island.space` where the island is memetic (module docstring)."""
        self.optimizer: PopulationOptimizer | Island = (
            make_optimizer(algo, objective.bounds, seed, config.island_options(algo))
            if self.space is None
            else Island(self.space, algo, seed, config.island_options(algo), starts=self._u(starting_points(objective, config.start)))
        )
        self.algo = algo
        self.seed = seed
        self.config = config
        self.objective = objective
        self.credentials: Credentials | None = None
        self.history_every_s = history_every_s
        self.turns = turns
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
        self.arrivals: Arrivals | None = None
        self._seq = Counter()
        self._lock = threading.Lock()
        self._taken: dict[str, tuple[str, int]] = {}
        """Per sender, the (run, seq) of the message last taken in."""
        self._claim: tuple[bytes, float] = (b"", np.inf)
        """The point of the last claim :meth:`_leads` re-evaluated and its fitness here: a stalled island checks
        the same claim at every iteration until a better one arrives, and evaluates it once."""

    @property
    def run_id(self) -> str:
        return "" if self.credentials is None else self.credentials.run

    def _attached(self) -> tuple[Transport, Credentials]:
        """The transport and the run's credentials; a :class:`RuntimeError` before :meth:`attach` (the
        node used before it joined: a caller's mistake, not bad input)."""
        if self._transport is None or self.credentials is None:
            raise RuntimeError(f"island {self.island!r} has not joined: attach a transport (IslandNode.attach or run) first")
        return self._transport, self.credentials

    def _arrivals(self) -> Arrivals:
        """The migrant messages this island takes from; a :class:`RuntimeError` before :meth:`attach`."""
        if self.arrivals is None:
            raise RuntimeError(f"island {self.island!r} has not joined: attach a transport (IslandNode.attach or run) first")
        return self.arrivals

    def count_rejected(self) -> None:
        with self._lock:
            self.stats["rejected"] += 1

    def count_unlisted(self) -> None:
        """A migrant message waited in vain for the roster to list its run (:mod:`island.arrivals`)."""
        with self._lock:
            self.stats["unlisted"] += 1

    # --- the loop ---------------------------------------------------------------
    def attach(self, transport: Transport) -> None:
        """Take messages through ``transport`` from now on (its credentials are the island's)."""
        self._transport = transport
        self.credentials = transport.credentials
        self.arrivals = transport.arrivals or Arrivals(
            self.config.name, self.objective.bounds, transport.key_for, transport.members, self.count_rejected, self.count_unlisted
        )
        self.arrivals.join(self.island)

    def run(self, transport: Transport) -> list[tuple[int, float, int, float]]:
        """Optimize until done or stopped; returns the rows ``(iteration, best, evaluations, wall s)``."""
        self.attach(transport)
        transport.wait_for_members(self.config.min_islands, START_TIMEOUT_S)
        if self.config.migration.interval:  # isolated islands take nothing from others, the global best neither
            self._best_in = next((b for b in map(self._decode_best, transport.global_best()) if b is not None), None)
        turns = self.turns

        def should_stop() -> bool:
            if turns is not None:
                turns.next()  # an iteration at a time, in turn with the other islands of the process
            return transport.stop_requested()

        if turns is not None:
            turns.acquire()
        try:
            run(self.optimizer, self.space or self.objective, callback=self._record, should_stop=should_stop, migrate=self._migrate)
            self.stop_reason = transport.stop_reason() if transport.stop_requested() else "own budget spent"
        finally:
            if turns is not None:
                turns.release()
            self.finished = True
            waited = self._arrivals().leave(self.island)  # what still waits for its run to be listed waited in vain
            with self._lock:
                self.stats["unlisted"] += waited
            self._flush(final=True)
        self.confirmed = transport.confirm(self.rows[-1][0] if self.rows else -1)
        return list(self.rows)

    def _record(self, row: HistoryRow) -> None:
        self.rows.append((row.iteration, row.best_fitness, row.evaluations + self.migrant_evaluations, row.wall_s))
        x, f = self.optimizer.best(1)
        if not f[0] > self._snapshot[1]:  # the best so far: a memetic island's fresh search after a restart starts above it
            self._snapshot = (self._theta(x[0]), float(f[0]))
        since, interval = time.monotonic() - self._last_flush, self.config.migration.interval
        at_migration = bool(interval and row.iteration and row.iteration % interval == 0)
        if since < self.history_every_s and not at_migration:
            return  # the period is never shorter: no need to count the members
        period = self.history_period()
        if since >= period or (at_migration and period <= self.history_every_s):
            self._flush()

    def history_period(self) -> float:
        """Seconds between two history messages (:func:`history_period`, with the members alive now)."""
        return history_period(self.history_every_s, len(self._transport.members()) if self._transport is not None else 1)

    # --- migrants -----------------------------------------------------------------
    def receive(self, sender: str, data: bytes) -> None:
        """A migrant message as it arrives (from any thread): see :class:`island.arrivals.Arrivals`."""
        if sender != self.island:  # not our own publication, back through a subscription to every island's migrants
            self._arrivals().receive(sender, data)

    def _follow_assignment(self) -> PopulationOptimizer | Island:
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

    def _migrate(self, optimizer: PopulationOptimizer | Island) -> PopulationOptimizer | Island:
        """After an iteration: follow a new assignment, take the starting point and the global best
        in once, and migrate every ``migration.interval`` iterations; returns the optimizer to go on with."""
        transport, credentials = self._attached()
        arrivals = self._arrivals()
        if optimizer.iteration == handover_iteration(self.config.algos, self.config.share, self.config.migration.interval, self.algo):
            self._flush()  # the history the coordinator hands this run over on, then its order
            await_handover(self.algo, transport.assigned_algo, transport.stop_requested, self.turns)
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
        arrivals.listed()
        roster = transport.members()
        senders = in_neighbours(mig.topology, self._sending(roster), self.island, epoch=epoch, seed=self.config.seed, random_k=mig.random_k)
        self._take(self._intake(senders, set(roster), mig.k))
        return optimizer

    def _sending(self, members: list[str]) -> list[str]:
        """The members (in the order they joined) that sent migrants within the transport's ``silent_s``,
        and this island: a member that sends nothing is no ring neighbour."""
        silent_s = self._transport.silent_s if self._transport is not None else None
        if silent_s is None or self.arrivals is None:
            return members
        heard = self.arrivals.heard(silent_s)
        return [m for m in members if m == self.island or m in heard]

    def _intake(self, senders: set[str], members: set[str], k: int) -> list[np.ndarray]:
        """The newest untaken message of each in-neighbour (at most ``k`` migrants from each)."""
        batches = []
        for m in self._arrivals().newest(senders, members):
            if self._taken.get(m.island) != (m.run, m.seq):
                batches.append(m.x[:k])
                self._taken[m.island] = (m.run, m.seq)
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
        trusted), once per point (:attr:`_claim`)."""
        rank = {s: i for i, s in enumerate(roster)}
        claims = [(float(m.claimed.min()), rank[m.island], m.x[int(np.argmin(m.claimed))]) for m in self._arrivals().newest(set(rank) - {self.island}, rank)]
        if not claims:
            return True
        _, rank_theirs, x = min(claims, key=lambda c: c[:2])
        if x.tobytes() != self._claim[0]:
            self._claim = (x.tobytes(), float(self.objective(x[None, :])[0]))
            self.migrant_evaluations += 1
        theirs, mine = self._claim[1], island.fitness
        earlier = self.island in rank and rank[self.island] < rank_theirs
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
        rows = np.array([r for r in list(self.rows) if r[0] > since], dtype=float).reshape(-1, 4)
        return self._messages([rows[i : i + HISTORY_CHUNK] for i in range(0, rows.shape[0], HISTORY_CHUNK)] or [rows], final)

    def heartbeat(self) -> bytes:
        """A history message without rows (from any thread): the island is alive while it has no new row."""
        return self._messages([np.zeros((0, 4))], final=False)[0]

    def _messages(self, chunks: list[np.ndarray], final: bool) -> list[bytes]:
        """A history message for each chunk of rows, with the best so far and the counters; ``final``: the last is the goodbye."""
        _, credentials = self._attached()
        x, f = self._snapshot
        with self._lock:
            stats = dict(self.stats)
        return [
            encode_history(
                History(
                    self.config.name,
                    self.island,
                    self.run_id,
                    self.algo,
                    self.seed,
                    chunk,
                    x,
                    f,
                    stats,
                    final and i == len(chunks) - 1,
                    self._seq(),
                    self.optimizer.gain,
                ),
                credentials,
            )
            for i, chunk in enumerate(chunks)
        ]

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
