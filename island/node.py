"""The island node: one ask/tell optimizer, cooperating with other islands through a transport.

The node holds no optimizer logic. It drives :func:`island.run.run` (ask ->
evaluate -> tell) and uses its hooks:

* it joins the campaign first: the coordinator issues its run id and keys
  (:class:`island.sealing.Credentials`), and every message it sends is sealed
  with them;
* after every iteration the history row goes to the coordinator (in batches,
  every ``history_every_s``; iteration, best fitness, evaluations, wall time);
* every ``migration.interval`` iterations (the *epoch*) it publishes its ``k``
  best candidates and takes what its in-neighbours (:mod:`island.migration`)
  sent. Each message is validated as it arrives (:mod:`island.protocol`:
  form, the campaign tag, replays), rejects are counted, and of each sender
  only the newest message is kept: an epoch takes at most ``k`` migrants from
  each in-neighbour, so a flood cannot starve the evolution. Every migrant's
  fitness is **re-evaluated locally** (the claimed value is never used), and
  the optimizer's migrant policy decides what to replace;
* who is a member, and the stop order, come from the coordinator's sealed
  ``control`` messages (a liveliness token alone makes nobody a member);
* a late joiner takes the coordinator's current global best the same way;
* when the roster assigns its run another algorithm (a mixed campaign's
  adaptive share, :mod:`island.share`), it carries its search on with that
  algorithm from the next iteration;
* it stops at the coordinator's stop order or when its own budget is spent,
  then waits (bounded) until the coordinator confirms it has committed every
  history row, serving the rows it asks for again (e.g. after a restart).

Two transports carry the bytes: :class:`ZenohTransport` (one process per
island, key space ``hysid/<campaign>/...``) and :class:`MemoryTransport`
(islands as threads of one process, in lock step at every epoch so that a
single-node campaign is reproducible).
"""

from __future__ import annotations

import re
import secrets
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable
from typing import Protocol

import numpy as np
import zenoh

from hysid_model.errors import HysidInputError
from hysid_model.objective import Objective
from hysid_model.thesis_port import ThesisObjective
from island.algorithms import make_optimizer, switch_algorithm
from island.config import CampaignConfig
from island.migration import in_neighbours
from island.population import PopulationOptimizer
from island.protocol import (
    STAT_NAMES,
    Best,
    Control,
    History,
    JoinRequest,
    Migrants,
    decode_best,
    decode_control,
    decode_joined,
    decode_migrants,
    encode_history,
    encode_join,
    encode_migrants,
)
from island.run import HistoryRow, run
from island.sealing import Counter, Credentials, ReplayGuard, check_replay
from island.wire import MAX_COUNT, MAX_MEMBERS, MessageRejected, check_name

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
SILENT_S = 4.0
"""An island whose coordinator sent no control message for this long (it sends one every second at
least) says so and waits for it, searching on, up to its ``wait_s`` more; then it stops."""
HISTORY_QUERIES_PER_S = 4.0
"""History queries an island answers per second (the coordinator asks every 2 s at most)."""
SINCE_PATTERN = re.compile(r"-?[0-9]{1,16}\Z")


def key_prefix(campaign: str) -> str:
    return f"hysid/{check_name('campaign', campaign)}"


class Transport(Protocol):
    """How an island's messages travel (bytes in, bytes out)."""

    credentials: Credentials
    """What the coordinator issued when the island joined."""

    def exchange(self, epoch: int, payload: bytes) -> list[tuple[str, bytes]]:
        """Publish this island's migrants; return ``(sender, message)`` pairs the node should still
        :meth:`IslandNode.receive` (a transport may hand them over as they arrive instead)."""

    def publish_history(self, payload: bytes) -> None: ...

    def members(self) -> list[str]:
        """Islands currently alive in the campaign."""

    def stop_requested(self) -> bool:
        """The coordinator ordered the stop, or (Zenoh) it has been silent for longer than the island waits."""

    def global_best(self) -> bytes | None:
        """The coordinator's current best message, if there is one (asked once, when the island starts)."""

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
        self.optimizer: PopulationOptimizer = make_optimizer(algo, objective.bounds, seed, config.island_options(algo))
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
        self._taken: dict[str, tuple[str, int]] = {}
        """Per sender, the (run, seq) of the message last taken in."""

    @property
    def run_id(self) -> str:
        return "" if self.credentials is None else self.credentials.run

    def count_rejected(self) -> None:
        with self._lock:
            self.stats["rejected"] += 1

    # --- the loop ---------------------------------------------------------------
    def run(self, transport: Transport) -> list[tuple[int, float, int, float]]:
        """Optimize until done or stopped; returns the rows ``(iteration, best, evaluations, wall s)``."""
        self._transport = transport
        self.credentials = transport.credentials
        transport.wait_for_members(self.config.min_islands, START_TIMEOUT_S)
        self._best_in = self._decode_best(transport.global_best())
        try:
            run(self.optimizer, self.objective, callback=self._record, should_stop=transport.stop_requested, migrate=self._migrate)
            self.stop_reason = transport.stop_reason() if transport.stop_requested() else "own budget spent"
        finally:
            self.finished = True
            self._flush(final=True)
        self.confirmed = transport.confirm(self.rows[-1][0] if self.rows else -1)
        return list(self.rows)

    def _record(self, row: HistoryRow) -> None:
        self.rows.append((row.iteration, row.best_fitness, row.evaluations + self.migrant_evaluations, row.wall_s))
        x, f = self.optimizer.best(1)
        self._snapshot = (x[0].copy(), float(f[0]))
        if time.monotonic() - self._last_flush >= self.history_every_s:
            self._flush()

    # --- migrants -----------------------------------------------------------------
    def receive(self, sender: str, data: bytes) -> None:
        """A migrant message as it arrives (from any thread): validated against the campaign key and
        for replays, counted if rejected, else kept as ``sender``'s newest."""
        assert self.credentials is not None
        if sender == self.island:
            return  # our own publication, back through the subscription to every island's migrants
        campaign_key = self.credentials.campaign_key
        try:
            m = decode_migrants(data, self.config.name, self.objective.bounds, tag="campaign", key_for=lambda s, r: campaign_key, sender=sender)
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

    def _follow_assignment(self) -> PopulationOptimizer:
        """The optimizer to go on with: this one, or its search carried on by the algorithm the
        coordinator now assigns this run (a mixed campaign's adaptive share, :mod:`island.share`)."""
        assert self._transport is not None
        algo = self._transport.assigned_algo()
        if algo is not None and algo != self.algo and algo in self.config.algos:
            self.optimizer = switch_algorithm(self.optimizer, algo, self.config.island_options(algo))
            self.moves.append((self.optimizer.iteration, self.algo, algo))
            self.algo = algo
        return self.optimizer

    def _migrate(self, optimizer: PopulationOptimizer) -> PopulationOptimizer:
        """After an iteration: follow a new assignment, take the starting point and the global best
        in once, and migrate every ``migration.interval`` iterations; returns the optimizer to go on with."""
        assert self._transport is not None and self.credentials is not None
        optimizer = self._follow_assignment()
        if optimizer.iteration == 0 and self.config.start is not None:  # the campaign's starting point joins first
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
            Migrants(self.config.name, self.island, self.run_id, optimizer.iteration, x, f, time.time(), self._seq()), self.credentials
        )
        for sender, data in self._transport.exchange(epoch, outgoing):
            self.receive(sender, data)
        with self._lock:
            self.stats["sent"] += 1
        members = self._transport.members()
        senders = in_neighbours(mig.topology, members, self.island, epoch=epoch, seed=self.config.seed, random_k=mig.random_k)
        self._take(self._intake(senders, set(members), mig.k))
        return optimizer

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
        x = np.vstack(batches)
        f = self.objective(x)
        self.migrant_evaluations += x.shape[0]
        taken = self.optimizer.inject(x, f)
        with self._lock:
            self.stats["received"] += x.shape[0]
            self.stats["taken"] += taken

    def _decode_best(self, data: bytes | None) -> Best | None:
        if data is None:
            return None
        try:
            return decode_best(data, self.config.name, self.objective.bounds)
        except MessageRejected:
            self.count_rejected()
            return None

    # --- history ---------------------------------------------------------------------
    def history_messages(self, since: int = -1, final: bool = False) -> list[bytes]:
        """This island's rows after iteration ``since`` (in chunks of :data:`HISTORY_CHUNK`), each
        with its best so far and its counters; ``final`` marks the last one as its goodbye."""
        assert self.credentials is not None
        rows = np.array([r for r in list(self.rows) if r[0] > since], dtype=float).reshape(-1, 4)
        x, f = self._snapshot
        with self._lock:
            stats = dict(self.stats)
        chunks = [rows[i : i + HISTORY_CHUNK] for i in range(0, rows.shape[0], HISTORY_CHUNK)] or [rows]
        return [
            encode_history(History(
                self.config.name, self.island, self.run_id, self.algo, self.seed, chunk, x, f, stats,
                final and i == len(chunks) - 1, self._seq(), self.optimizer.gain,
            ), self.credentials)
            for i, chunk in enumerate(chunks)
        ]

    def _flush(self, final: bool = False) -> None:
        assert self._transport is not None
        published = self._published
        if published == len(self.rows):
            if not final:
                return
            published = max(published - 1, 0)  # the goodbye carries the last row again
        last = self.rows[published - 1][0] if published else -1
        for message in self.history_messages(since=last, final=final):
            self._transport.publish_history(message)
        self._published = len(self.rows)
        self._last_flush = time.monotonic()


# --- transports ----------------------------------------------------------------------------
def join(
    session: zenoh.Session, campaign: str, island: str, algo: str, seed: int, wait_s: float, on_reject: Callable[[], None] | None = None
) -> Credentials:
    """The join handshake: ask ``join/<id>`` (until a coordinator answers or ``wait_s`` passes) for
    the island's credentials; ``on_reject`` counts answers that fail validation. A refusal (e.g.
    the id is taken) is a :class:`HysidInputError`."""
    key = f"{key_prefix(campaign)}/join/{island}"
    nonce = secrets.token_bytes(16)
    request = encode_join(JoinRequest(campaign, island, algo, seed, nonce))
    deadline = time.monotonic() + wait_s
    while True:
        for reply in session.get(key, payload=request, timeout=min(5.0, max(wait_s, 0.5))):
            if reply.ok is None:
                continue
            try:
                return decode_joined(reply.ok.payload.to_bytes(), campaign, island, nonce)
            except MessageRejected:
                if on_reject is not None:
                    on_reject()
        if time.monotonic() >= deadline:
            raise HysidInputError(f"no coordinator admitted island {island!r} on {key} within {wait_s:g} s")
        time.sleep(0.2)


class ZenohTransport:
    """An island's Zenoh entities under ``hysid/<campaign>/``.

    Joins through ``join/<id>``, then publishes on ``migrants/<id>`` and
    ``history/<id>``, subscribes to ``migrants/*`` and ``control``, answers
    ``history/<id>?run=R;since=N`` with the rows the coordinator is missing
    (after a coordinator restart), and declares the liveliness token
    ``members/<id>`` (last: it tells the coordinator the island is up).
    ``wait_s`` bounds the join, the final wait for the coordinator's
    confirmation, and how long the island waits for a coordinator that fell
    silent (no control message for :data:`SILENT_S`: killed, or cut off) to come
    back: it keeps its state and searches on, and the Zenoh session reconnects
    to a coordinator resumed on the same endpoint, which takes the island up as
    the same run (its rows missed meanwhile fetched again, its best carried on);
    after ``SILENT_S + wait_s`` of silence the island stops. ``notify`` hears
    (one line each) when the coordinator falls silent and when it is back.
    """

    def __init__(self, session: zenoh.Session, node: IslandNode, wait_s: float = 30.0, notify: Callable[[str], None] | None = None) -> None:
        self.session = session
        self.node = node
        self.wait_s = wait_s
        self.notify = notify or (lambda message: None)
        prefix = key_prefix(node.config.name)
        self.prefix = prefix
        self.credentials = join(session, node.config.name, node.island, node.algo, node.seed, wait_s, node.count_rejected)
        node.credentials = self.credentials
        self._cond = threading.Condition()
        self._control_seq = -1
        self._roster: dict[tuple[str, str], tuple[bool, int]] = {}
        """(island, run) -> (alive, stored) as the coordinator's last control message said."""
        self._algo: str | None = None
        """The algorithm that message assigns this run."""
        self._stop = ""
        self._heard_at = time.monotonic()
        """When the coordinator was last heard (a control message, or the join)."""
        self._silent = False
        self._gone = ""
        """Why the island stopped on its own: its coordinator was silent for too long."""
        self._queries: deque[float] = deque(maxlen=int(HISTORY_QUERIES_PER_S))
        self._migrants = session.declare_publisher(f"{prefix}/migrants/{node.island}")
        self._history = session.declare_publisher(f"{prefix}/history/{node.island}", congestion_control=zenoh.CongestionControl.BLOCK)
        self._entities = [
            session.declare_subscriber(f"{prefix}/migrants/*", self._on_migrants),
            session.declare_subscriber(f"{prefix}/control", self._on_control),
            session.declare_queryable(f"{prefix}/history/{node.island}", self._on_history_query),
        ]
        self._token = session.liveliness().declare_token(f"{prefix}/members/{node.island}")

    def _on_migrants(self, sample: zenoh.Sample) -> None:
        self.node.receive(str(sample.key_expr).rsplit("/", 1)[-1], sample.payload.to_bytes())

    def _on_control(self, sample: zenoh.Sample) -> None:
        try:
            control = decode_control(sample.payload.to_bytes(), self.node.config.name, self.credentials)
        except MessageRejected:
            self.node.count_rejected()
            return
        self.apply(control)

    def apply(self, control: Control) -> None:
        """Take a (validated) control message: the newest one wins, an older one is a replay."""
        with self._cond:
            if control.seq <= self._control_seq:
                self.node.count_rejected()
                return
            self._control_seq = control.seq
            self._roster = {(m.island, m.run): (m.alive, m.stored) for m in control.members}
            algo = next((m.algo for m in control.members if (m.island, m.run) == (self.node.island, self.credentials.run)), self._algo)
            if algo is not None and algo != self._algo and algo != self.node.algo:
                self.notify(f"island {self.node.island}: campaign {self.node.config.name!r} moves this island from "
                            f"{self.node.algo.upper()} to {algo.upper()} (the adaptive share); its search carries on")
            self._algo = algo
            self._stop = self._stop or control.stop
            silent_s, self._heard_at = time.monotonic() - self._heard_at, time.monotonic()
            if self._silent:
                self._silent = False
                self.notify(f"island {self.node.island}: the coordinator of campaign {self.node.config.name!r} is back after {silent_s:.0f} s of silence; carrying on")
            self._cond.notify_all()

    def _on_history_query(self, query: zenoh.Query) -> None:
        now = time.monotonic()
        params = query.parameters
        run, since = params.get("run"), params.get("since") or "-1"
        if len(self._queries) == self._queries.maxlen and now - self._queries[0] < 1.0:
            self.node.count_rejected()  # more history queries than the coordinator ever sends
            return
        if not SINCE_PATTERN.match(since) or not -1 <= int(since) <= MAX_COUNT:
            self.node.count_rejected()
            return
        self._queries.append(now)
        since_i = int(since) if run == self.node.run_id else -1
        for message in self.node.history_messages(since=since_i, final=self.node.finished):
            query.reply(query.key_expr, message)

    # --- Transport ---
    def exchange(self, epoch: int, payload: bytes) -> list[tuple[str, bytes]]:
        """Migrants arrive through :meth:`_on_migrants` as they come; nothing is left to hand over."""
        self._migrants.put(payload)
        return []

    def publish_history(self, payload: bytes) -> None:
        self._history.put(payload)

    def members(self) -> list[str]:
        with self._cond:
            alive = {island for (island, _), (up, _) in self._roster.items() if up}
        return sorted(alive | {self.node.island})

    def _joined_count(self) -> int:
        """Islands the roster lists, including those that have left: a fast island may finish before a slow one starts."""
        return len({island for island, _ in self._roster} | {self.node.island})

    def stop_requested(self) -> bool:
        with self._cond:
            if self._stop or self._gone:
                return True
            silent_s = time.monotonic() - self._heard_at
            if silent_s >= SILENT_S and not self._silent:
                self._silent = True
                self.notify(
                    f"island {self.node.island}: the coordinator of campaign {self.node.config.name!r} has been silent for "
                    f"{silent_s:.0f} s; searching on and waiting up to {self.wait_s:g} s (--wait) for it to come back"
                )
            if silent_s >= SILENT_S + self.wait_s:
                self._gone = f"the coordinator was silent for {silent_s:.0f} s"
                self.notify(f"island {self.node.island}: {self._gone}; stopping")
                self._cond.notify_all()
            return bool(self._gone)

    def stop_reason(self) -> str:
        with self._cond:
            return self._gone or "stopped by the coordinator"

    def assigned_algo(self) -> str | None:
        with self._cond:
            return self._algo

    def global_best(self) -> bytes | None:
        for reply in self.session.get(f"{self.prefix}/best", timeout=2.0):
            if reply.ok is not None:
                return reply.ok.payload.to_bytes()
        return None

    def wait_for_members(self, n: int, timeout_s: float) -> None:
        with self._cond:
            self._cond.wait_for(lambda: self._joined_count() >= n or bool(self._stop or self._gone), timeout=timeout_s)

    def confirm(self, iteration: int) -> bool:
        """Wait up to ``wait_s`` for a control message saying rows up to ``iteration`` are committed."""
        me = (self.node.island, self.node.run_id)
        with self._cond:
            return self._cond.wait_for(lambda: self._roster.get(me, (False, -1))[1] >= iteration, timeout=self.wait_s)

    def close(self) -> None:
        """Leave the campaign: the token goes last, after the final history was sent."""
        for entity in self._entities + [self._migrants, self._history]:
            entity.undeclare()
        self._token.undeclare()


def fetch_config(session: zenoh.Session, campaign: str, wait_s: float) -> bytes:
    """The coordinator's ``config`` message, asking until one answers or ``wait_s`` passes."""
    key = f"{key_prefix(campaign)}/config"
    deadline = time.monotonic() + wait_s
    while True:
        for reply in session.get(key, timeout=min(2.0, max(wait_s, 0.1))):
            if reply.ok is not None:
                return reply.ok.payload.to_bytes()
        if time.monotonic() >= deadline:
            raise HysidInputError(f"no coordinator answered on {key} within {wait_s:g} s (is the coordinator of campaign {campaign!r} running and reachable?)")
        time.sleep(0.2)


Admit = Callable[[str, str, int], Credentials]
"""``admit(island, algo, seed)``: the join handshake of an in-process island."""


class MemoryBus:
    """In-process migration between island threads, in lock step per epoch.

    At epoch ``e`` every island posts its migrants and waits until each island
    still running has posted for ``e`` (or finished), so the exchange does not
    depend on thread timing and a seeded single-node campaign is reproducible.
    ``admit`` issues each island's credentials (the coordinator's, in a
    single-node campaign; by default the bus' own); ``assigned(island)`` is the
    algorithm the coordinator tells an island to run (None: not said).
    """

    def __init__(
        self, campaign: str, islands: list[str], deliver: Callable[[str, bytes], None], stop: threading.Event, admit: Admit | None = None,
        assigned: Callable[[str], str | None] | None = None,
    ) -> None:
        self.prefix = key_prefix(campaign)
        self.islands = sorted(islands)
        if len(self.islands) > MAX_MEMBERS:
            raise HysidInputError(f"at most {MAX_MEMBERS} islands", param="islands", value=len(self.islands))
        self.deliver = deliver
        """Receives every publication as ``(key, message)``, as the coordinator's subscribers would."""
        self.stop = stop
        campaign_key = secrets.token_bytes(32)
        self.admit = admit or (lambda island, algo, seed: Credentials.issue(island, campaign_key))
        self.assigned = assigned or (lambda island: None)
        self._active = set(islands)
        self._posts: dict[int, dict[str, bytes]] = {}
        self._cond = threading.Condition()

    def transport(self, island: str, algo: str = "", seed: int = 0) -> "MemoryTransport":
        return MemoryTransport(self, island, self.admit(island, algo, seed))

    def exchange(self, island: str, epoch: int, payload: bytes) -> list[tuple[str, bytes]]:
        self.deliver(f"{self.prefix}/migrants/{island}", payload)
        with self._cond:
            posts = self._posts.setdefault(epoch, {})
            posts[island] = payload
            self._cond.notify_all()
            self._cond.wait_for(lambda: self._active <= set(posts) or self.stop.is_set())
            return [(sender, data) for sender, data in sorted(posts.items()) if sender != island]

    def leave(self, island: str) -> None:
        with self._cond:
            self._active.discard(island)
            self._cond.notify_all()


class MemoryTransport:
    """One island's view of a :class:`MemoryBus`."""

    def __init__(self, bus: MemoryBus, island: str, credentials: Credentials) -> None:
        self.bus = bus
        self.island = island
        self.credentials = credentials

    def exchange(self, epoch: int, payload: bytes) -> list[tuple[str, bytes]]:
        return self.bus.exchange(self.island, epoch, payload)

    def publish_history(self, payload: bytes) -> None:
        self.bus.deliver(f"{self.bus.prefix}/history/{self.island}", payload)

    def members(self) -> list[str]:
        return list(self.bus.islands)

    def stop_requested(self) -> bool:
        return self.bus.stop.is_set()

    def stop_reason(self) -> str:
        return "stopped by the coordinator"

    def global_best(self) -> bytes | None:
        return None

    def assigned_algo(self) -> str | None:
        return self.bus.assigned(self.island)

    def wait_for_members(self, n: int, timeout_s: float) -> None:
        """Every island of the bus exists from the start."""

    def confirm(self, iteration: int) -> bool:
        """The coordinator is in this process: what was delivered is in its queue."""
        return True

    def close(self) -> None:
        self.bus.leave(self.island)
