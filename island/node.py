"""The island node: one ask/tell optimizer, cooperating with other islands through a transport.

The node holds no optimizer logic. It drives :func:`island.run.run` (ask ->
evaluate -> tell) and uses its hooks:

* after every iteration the history row goes to the coordinator (in batches,
  every ``history_every_s``; iteration, best fitness, evaluations, wall time);
* every ``migration.interval`` iterations (the *epoch*) it publishes its ``k``
  best candidates and takes what its in-neighbours (:mod:`island.migration`)
  sent: each message is validated (:mod:`island.protocol`), every migrant's
  fitness is **re-evaluated locally** (the claimed value is never used), and
  the optimizer's migrant policy decides what to replace;
* a late joiner takes the coordinator's current global best the same way;
* it stops at the coordinator's stop order or when its own budget is spent.

Two transports carry the bytes: :class:`ZenohTransport` (one process per
island, key space ``hysid/<campaign>/...``) and :class:`MemoryTransport`
(islands as threads of one process, in lock step at every epoch so that a
single-node campaign is reproducible).
"""

from __future__ import annotations

import secrets
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Protocol

import numpy as np
import zenoh

from hysid_model.errors import HysidInputError
from hysid_model.objective import Objective
from hysid_model.thesis_port import ThesisObjective
from island.algorithms import make_optimizer
from island.config import CampaignConfig
from island.migration import in_neighbours
from island.population import PopulationOptimizer
from island.protocol import (
    STAT_NAMES,
    Best,
    History,
    MessageRejected,
    Migrants,
    check_name,
    decode_best,
    decode_migrants,
    decode_stop,
    encode_history,
    encode_migrants,
)
from island.run import HistoryRow, run

START_TIMEOUT_S = 60.0
"""Longest wait for ``min_islands`` members before an island starts anyway."""
HISTORY_CHUNK = 20_000
"""History rows per message (well under :data:`island.protocol.MAX_ROWS`)."""
MAX_INBOX = 4096
"""Migrant messages an island keeps between two epochs; older ones are dropped first."""
JOIN_GRACE_S = 5.0
"""How long migrants from a sender that is not (yet) a member wait for its liveliness token.

Zenoh does not order a new member's token before its first publications, so a
joiner's first migrants can arrive before the island knows it is a member."""


def key_prefix(campaign: str) -> str:
    return f"hysid/{check_name('campaign', campaign)}"


class Transport(Protocol):
    """How an island's messages travel (bytes in, bytes out)."""

    def exchange(self, epoch: int, payload: bytes) -> list[tuple[str, bytes]]:
        """Publish this island's migrants; return ``(sender, message)`` received since the last call."""

    def publish_history(self, payload: bytes) -> None: ...

    def members(self) -> list[str]:
        """Islands currently alive in the campaign."""

    def stop_requested(self) -> bool: ...

    def global_best(self) -> bytes | None:
        """The coordinator's current best message, if there is one (asked once, when the island starts)."""

    def wait_for_members(self, n: int, timeout_s: float) -> None:
        """Return once ``n`` islands are members (or after ``timeout_s``, or on a stop order)."""


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
        self.optimizer: PopulationOptimizer = make_optimizer(algo, objective.bounds, seed, config.options.get(algo))
        self.algo = algo
        self.seed = seed
        self.config = config
        self.objective = objective
        self.run_id = secrets.token_hex(6)
        self.history_every_s = history_every_s
        self.stats = dict.fromkeys(STAT_NAMES, 0)
        self.rows: list[tuple[int, float, int, float]] = []
        self.migrant_evaluations = 0
        self.stop_reason = ""
        self._published = 0
        self._last_flush = 0.0
        self._snapshot: tuple[np.ndarray, float] = (objective.bounds.mean(axis=1), np.inf)
        self._best_in: Best | None = None
        self._transport: Transport | None = None
        self._unknown_senders: deque[tuple[float, Migrants]] = deque(maxlen=MAX_INBOX)
        """Valid migrants from senders not yet members, with when they arrived (see :data:`JOIN_GRACE_S`)."""

    # --- the loop ---------------------------------------------------------------
    def run(self, transport: Transport) -> list[tuple[int, float, int, float]]:
        """Optimize until done or stopped; returns the rows ``(iteration, best, evaluations, wall s)``."""
        self._transport = transport
        transport.wait_for_members(self.config.min_islands, START_TIMEOUT_S)
        self._best_in = self._decode_best(transport.global_best())
        try:
            run(self.optimizer, self.objective, callback=self._record, should_stop=transport.stop_requested, migrate=self._migrate)
            self.stop_reason = "stopped by the coordinator" if transport.stop_requested() else "own budget spent"
        finally:
            self._flush(final=True)
        return list(self.rows)

    def _record(self, row: HistoryRow) -> None:
        self.rows.append((row.iteration, row.best_fitness, row.evaluations + self.migrant_evaluations, row.wall_s))
        x, f = self.optimizer.best(1)
        self._snapshot = (x[0].copy(), float(f[0]))
        if time.monotonic() - self._last_flush >= self.history_every_s:
            self._flush()

    def _migrate(self, optimizer: PopulationOptimizer) -> None:
        assert self._transport is not None
        if optimizer.iteration == 0 and self.config.start is not None:  # the campaign's starting point joins first
            x = np.array(self.config.start, dtype=float)[None, :]
            self.migrant_evaluations += 1
            optimizer.inject(x, self.objective(x))
        if self._best_in is not None:
            self._take([self._best_in.x[None, :]])
            self._best_in = None
        mig = self.config.migration
        if mig.interval == 0 or optimizer.iteration == 0 or optimizer.iteration % mig.interval:
            return
        epoch = optimizer.iteration // mig.interval
        x, f = optimizer.best(mig.k)
        outgoing = encode_migrants(Migrants(self.config.name, self.island, self.run_id, optimizer.iteration, x, f, time.time()))
        received = self._transport.exchange(epoch, outgoing)
        self.stats["sent"] += 1
        members = self._transport.members()
        senders = in_neighbours(mig.topology, members, self.island, epoch=epoch, seed=self.config.seed, random_k=mig.random_k)
        now = time.monotonic()
        arrived = list(self._unknown_senders)
        self._unknown_senders.clear()
        for sender, data in received:
            try:
                arrived.append((now, decode_migrants(data, self.config.name, self.objective.bounds, sender)))
            except MessageRejected:
                self.stats["rejected"] += 1
        batches = []
        for at, m in arrived:
            if m.island in senders:
                batches.append(m.x)
            elif m.island not in members and now - at < JOIN_GRACE_S:
                self._unknown_senders.append((at, m))
        self._take(batches)

    def _take(self, batches: list[np.ndarray]) -> None:
        """Re-evaluate migrants here (never trusting their claimed fitness) and offer them to the optimizer."""
        if not batches:
            return
        x = np.vstack(batches)
        f = self.objective(x)
        self.migrant_evaluations += x.shape[0]
        self.stats["received"] += x.shape[0]
        self.stats["taken"] += self.optimizer.inject(x, f)

    def _decode_best(self, data: bytes | None) -> Best | None:
        if data is None:
            return None
        try:
            return decode_best(data, self.config.name, self.objective.bounds)
        except MessageRejected:
            self.stats["rejected"] += 1
            return None

    # --- history ---------------------------------------------------------------------
    def history_messages(self, since: int = -1, final: bool = False) -> list[bytes]:
        """This island's rows after iteration ``since`` (in chunks of :data:`HISTORY_CHUNK`), each
        with its best so far and its counters; ``final`` marks the last one as its goodbye."""
        rows = np.array([r for r in list(self.rows) if r[0] > since], dtype=float).reshape(-1, 4)
        x, f = self._snapshot
        chunks = [rows[i : i + HISTORY_CHUNK] for i in range(0, rows.shape[0], HISTORY_CHUNK)] or [rows]
        return [
            encode_history(History(
                self.config.name, self.island, self.run_id, self.algo, self.seed, chunk, x, f, dict(self.stats),
                final and i == len(chunks) - 1,
            ))
            for i, chunk in enumerate(chunks)
        ]

    def _flush(self, final: bool = False) -> None:
        assert self._transport is not None
        last = self.rows[self._published - 1][0] if self._published else -1
        if self._published == len(self.rows) and not final:
            return
        for message in self.history_messages(since=last, final=final):
            self._transport.publish_history(message)
        self._published = len(self.rows)
        self._last_flush = time.monotonic()


# --- transports ----------------------------------------------------------------------------
class ZenohTransport:
    """An island's Zenoh entities under ``hysid/<campaign>/``.

    Declares the liveliness token ``members/<id>``, publishes on
    ``migrants/<id>`` and ``history/<id>``, subscribes to ``migrants/*``,
    ``control`` and the members' tokens, and answers ``history/<id>?run=R;since=N``
    with the rows the coordinator is missing (after a coordinator restart).
    """

    def __init__(self, session: zenoh.Session, node: IslandNode) -> None:
        self.session = session
        self.node = node
        prefix = key_prefix(node.config.name)
        self.prefix = prefix
        self._inbox: deque[tuple[str, bytes]] = deque(maxlen=MAX_INBOX)
        self._members: set[str] = set()
        self._joined: set[str] = {node.island}
        """Every island seen since this one started, including those that have left since."""
        self._lock = threading.Lock()
        self._control: deque[bytes] = deque(maxlen=MAX_INBOX)
        self._stopped = False
        self._migrants = session.declare_publisher(f"{prefix}/migrants/{node.island}")
        self._history = session.declare_publisher(f"{prefix}/history/{node.island}", congestion_control=zenoh.CongestionControl.BLOCK)
        self._entities = [
            session.liveliness().declare_subscriber(f"{prefix}/members/*", self._on_member, history=True),
            session.declare_subscriber(f"{prefix}/migrants/*", self._on_migrants),
            session.declare_subscriber(f"{prefix}/control", self._on_control),
            session.declare_queryable(f"{prefix}/history/{node.island}", self._on_history_query),
        ]
        self._token = session.liveliness().declare_token(f"{prefix}/members/{node.island}")

    def _on_member(self, sample: zenoh.Sample) -> None:
        island = str(sample.key_expr).rsplit("/", 1)[-1]
        with self._lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self._members.add(island)
                self._joined.add(island)
            else:
                self._members.discard(island)

    def _on_migrants(self, sample: zenoh.Sample) -> None:
        self._inbox.append((str(sample.key_expr).rsplit("/", 1)[-1], sample.payload.to_bytes()))

    def _on_control(self, sample: zenoh.Sample) -> None:
        self._control.append(sample.payload.to_bytes())

    def _on_history_query(self, query: zenoh.Query) -> None:
        params = query.parameters
        try:
            since = int(params.get("since") or -1) if params.get("run") == self.node.run_id else -1
        except ValueError:
            since = -1
        for message in self.node.history_messages(since=since):
            query.reply(query.key_expr, message)

    # --- Transport ---
    def exchange(self, epoch: int, payload: bytes) -> list[tuple[str, bytes]]:
        self._migrants.put(payload)
        received = []
        while self._inbox:
            received.append(self._inbox.popleft())
        return received

    def publish_history(self, payload: bytes) -> None:
        self._history.put(payload)

    def members(self) -> list[str]:
        with self._lock:
            return sorted(self._members | {self.node.island})

    def _joined_count(self) -> int:
        with self._lock:
            return len(self._joined)

    def stop_requested(self) -> bool:
        """Whether a valid stop order arrived (control messages are validated here, in the island's thread)."""
        while self._control:
            try:
                decode_stop(self._control.popleft(), self.node.config.name)
            except MessageRejected:
                self.node.stats["rejected"] += 1
                continue
            self._stopped = True
        return self._stopped

    def global_best(self) -> bytes | None:
        for reply in self.session.get(f"{self.prefix}/best", timeout=2.0):
            if reply.ok is not None:
                return reply.ok.payload.to_bytes()
        return None

    def wait_for_members(self, n: int, timeout_s: float) -> None:
        """Counts islands that have joined, even if they already left: a fast island may finish before a slow one starts."""
        deadline = time.monotonic() + timeout_s
        while self._joined_count() < n and time.monotonic() < deadline and not self.stop_requested():
            time.sleep(0.05)

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


class MemoryBus:
    """In-process migration between island threads, in lock step per epoch.

    At epoch ``e`` every island posts its migrants and waits until each island
    still running has posted for ``e`` (or finished), so the exchange does not
    depend on thread timing and a seeded single-node campaign is reproducible.
    """

    def __init__(self, campaign: str, islands: list[str], deliver: Callable[[str, bytes], None], stop: threading.Event) -> None:
        self.prefix = key_prefix(campaign)
        self.islands = sorted(islands)
        self.deliver = deliver
        """Receives every publication as ``(key, message)``, as the coordinator's subscribers would."""
        self.stop = stop
        self._active = set(islands)
        self._posts: dict[int, dict[str, bytes]] = {}
        self._cond = threading.Condition()

    def transport(self, island: str) -> "MemoryTransport":
        return MemoryTransport(self, island)

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

    def __init__(self, bus: MemoryBus, island: str) -> None:
        self.bus = bus
        self.island = island

    def exchange(self, epoch: int, payload: bytes) -> list[tuple[str, bytes]]:
        return self.bus.exchange(self.island, epoch, payload)

    def publish_history(self, payload: bytes) -> None:
        self.bus.deliver(f"{self.bus.prefix}/history/{self.island}", payload)

    def members(self) -> list[str]:
        return list(self.bus.islands)

    def stop_requested(self) -> bool:
        return self.bus.stop.is_set()

    def global_best(self) -> bytes | None:
        return None

    def wait_for_members(self, n: int, timeout_s: float) -> None:
        """Every island of the bus exists from the start."""

    def close(self) -> None:
        self.bus.leave(self.island)
