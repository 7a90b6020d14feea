"""How an island's messages travel over Zenoh (in memory between island threads: :mod:`island.memory`).

:class:`ZenohTransport`: an island over Zenoh, key space ``hysid/<campaign>/...``
(:func:`island.joining.key_prefix`, which the coordinator's :mod:`coordinator.links`
speaks too), on a :class:`ZenohHost` that the islands of one process share (one
session, migrants and the roster checked once for all of them); it joins with
:func:`island.joining.join`. Every answer and every roster is checked against the
coordinator's key in the campaign secret (:mod:`island.secret`): a stranger that
answers first changes nothing. It is the :class:`island.transport.Transport` of an
:class:`island.node.IslandNode` over Zenoh.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable

import numpy as np
import zenoh

from island.arrivals import Arrivals
from island.coordinator_messages import Control, MemberState, decode_control, decode_history_query
from island.joining import join, key_prefix, replies
from island.node import IslandNode
from island.secret import CampaignSecret
from island.wire import MessageRejected

SILENT_S = 4.0
"""An island whose coordinator sent no control message for this long (it sends one every second at
least) says so and waits for it, searching on, up to its ``wait_s`` more; then it stops."""
HISTORY_QUERIES_PER_S = 4.0
"""History queries an island answers per second (the coordinator asks every 2 s at most)."""
HEARTBEAT_S = 1.0
"""An island with no new history row for this long sends a heartbeat (a signed history without rows):
the coordinator counts an island alive by what it signs, not by its liveliness token."""
CONTROL_QUEUE = 16
"""Control messages waiting to be taken (only the newest counts; every other one is read and counted)."""
QUERY_QUEUE = 16
"""History queries waiting for an island to answer them (the coordinator asks every 2 s at most)."""
MIGRANT_QUEUE = 1024
"""Migrant messages waiting for a process' islands to take them in; when that many wait, Zenoh waits
for room (nothing is dropped unread: a flood of bad messages is read, and counted, to the last)."""
SILENT_MEMBER_S = 5.0
"""A ring member whose migrants have not arrived for this long is skipped by the island after it
(:meth:`island.node.IslandNode._sending`): a member that sends nothing cannot starve its successor."""


class ZenohHost:
    """What the islands of one process share over one Zenoh session under ``hysid/<campaign>/``.

    It subscribes to ``migrants/*`` (into one :class:`island.arrivals.Arrivals`:
    each message read and its signature verified once, however many islands of
    the process take from its sender) and to ``control`` (checked once: only
    messages signed by the coordinator of ``secret`` count; their roster gives
    the members in the order they joined, the public key of each run, the
    algorithm each is to run and how far its history is committed, and the
    stop order), watches the coordinator's silence and sends the heartbeats of
    all its islands from one thread. ``bounds`` is the campaign's search space
    (of the ``config`` message).

    A coordinator that sent no control message for :data:`SILENT_S` (killed,
    or cut off) is waited for, the islands searching on, up to ``wait_s``
    more: the session reconnects to a coordinator resumed on the same endpoint,
    which takes each island up as the same run; after ``SILENT_S + wait_s`` of
    silence the islands stop. ``notify`` hears (one line each) when the
    coordinator falls silent, when it is back and when it moves an island to
    another algorithm. :meth:`stop` ends every island of the host (Ctrl-C).

    What arrives waits in channels that Zenoh fills without Python (up to
    :data:`MIGRANT_QUEUE` migrant messages, :data:`CONTROL_QUEUE` control
    messages, each island's history queries; a full channel makes Zenoh wait,
    so nothing is dropped unread and uncounted), and threads of this process
    take it in: islands busy computing never hold up the session, and no Zenoh
    thread runs Python code (one that still did when the interpreter exits
    would abort the process).
    """

    def __init__(
        self, session: zenoh.Session, secret: CampaignSecret, bounds: np.ndarray, wait_s: float = 30.0, notify: Callable[[str], None] | None = None
    ) -> None:
        self.session = session
        self.secret = secret
        self.campaign = secret.campaign
        self.prefix = key_prefix(secret.campaign)
        self.wait_s = wait_s
        self.confirm_s = wait_s
        """How long an island that finished waits for the coordinator to confirm its rows (shorter after :meth:`stop`)."""
        self.notify = notify or (lambda message: None)
        self._cond = threading.Condition()
        self._control_seq = -1
        self._roster: dict[tuple[str, str], MemberState] = {}
        """(island, run) -> its entry in the coordinator's last control message, in join order."""
        self._roster_at = time.monotonic()
        """When that control message came."""
        self._alive: list[str] = []
        """Islands alive by that roster, in the order they joined."""
        self._listed: set[str] = set()
        """Islands that roster lists, including those that have left."""
        self._stop = ""
        self._heard_at = time.monotonic()
        """When the coordinator was last heard (a control message, or a join)."""
        self._silent = False
        self._gone = ""
        """Why the islands stopped on their own: the coordinator was silent for too long, or :meth:`stop`."""
        self._islands: dict[str, ZenohTransport] = {}
        self.arrivals = Arrivals(self.campaign, bounds, self.key_for, self.members, self._reject, self._unlisted, self.known)
        self._migrants = session.declare_subscriber(f"{self.prefix}/migrants/*", zenoh.handlers.FifoChannel(MIGRANT_QUEUE))
        self._control = session.declare_subscriber(f"{self.prefix}/control", zenoh.handlers.FifoChannel(CONTROL_QUEUE))
        self._closing = threading.Event()
        self._threads = [
            threading.Thread(target=self._beat, name="heartbeat", daemon=True),
            threading.Thread(target=self._take_migrants, name="migrants", daemon=True),
            threading.Thread(target=self._take_control, name="control", daemon=True),
        ]
        for t in self._threads:
            t.start()

    def _who(self) -> str:
        with self._cond:
            ids = list(self._islands)
        return f"island {ids[0]}" if len(ids) == 1 else f"{len(ids)} islands of this process"

    def _reject(self) -> None:
        """A message every island of the host would have rejected: counted by each."""
        with self._cond:
            islands = list(self._islands.values())
        for t in islands:
            t.node.count_rejected()

    def _unlisted(self) -> None:
        """A migrant message that waited in vain for the roster, for every island of the host: counted by each."""
        with self._cond:
            islands = list(self._islands.values())
        for t in islands:
            t.node.count_unlisted()

    def add(self, transport: ZenohTransport) -> None:
        """An island of this host joined: the coordinator answered it (a roster that lists its run already
        came: the algorithm it assigns the run is the transport's from now on, as from every roster after it)."""
        with self._cond:
            self._islands[transport.node.island] = transport
            transport.assign(self._roster.get((transport.node.island, transport.credentials.run)))
            self._heard_at = time.monotonic()

    def remove(self, transport: ZenohTransport) -> None:
        with self._cond:
            self._islands.pop(transport.node.island, None)

    def _beat(self) -> None:
        """Every :data:`HEARTBEAT_S` without a history publication, until the island finished: a heartbeat."""
        while not self._closing.wait(HEARTBEAT_S / 2):
            with self._cond:
                islands = list(self._islands.values())
            for t in islands:
                t.beat()

    def _take_migrants(self) -> None:
        """Take in the migrant messages of the ring as they come (until the subscriber goes)."""
        for sample in self._migrants:
            self.arrivals.receive(str(sample.key_expr).rsplit("/", 1)[-1], sample.payload.to_bytes())

    def _take_control(self) -> None:
        """Take the control messages as they come (the newest few wait: only the newest one counts)."""
        for sample in self._control:
            try:
                control = decode_control(sample.payload.to_bytes(), self.campaign, self.secret.coordinator)
            except MessageRejected:
                self._reject()
                continue
            self.apply(control)

    def apply(self, control: Control) -> None:
        """Take a (validated) control message: the newest one wins, an older one is a replay."""
        with self._cond:
            replay = control.seq <= self._control_seq
            if not replay:
                self._control_seq = control.seq
                self._roster = {(m.island, m.run): m for m in control.members}
                self._roster_at = time.monotonic()
                self._alive = list(dict.fromkeys(m.island for m in control.members if m.alive))
                self._listed = {m.island for m in control.members}
                self._stop = self._stop or control.stop
                silent_s, self._heard_at = time.monotonic() - self._heard_at, time.monotonic()
                if self._silent:
                    self._silent = False
                    self.notify(f"{self._who()}: the coordinator of campaign {self.campaign!r} is back after {silent_s:.0f} s of silence; carrying on")
                for t in self._islands.values():
                    t.assign(self._roster.get((t.node.island, t.credentials.run)))
                self._cond.notify_all()
        if replay:
            self._reject()

    def members(self) -> list[str]:
        with self._cond:
            return self._alive

    def key_for(self, island: str, run: str) -> bytes | None:
        """The public key the roster lists for that run, or, for a run of this host's own islands that
        the roster does not list yet, the key it joined with (its messages come back through the
        subscription to every island's migrants)."""
        with self._cond:
            entry = self._roster.get((island, run))
            own = self._islands.get(island)
        if entry is not None:
            return entry.key
        return own.credentials.public if own is not None and own.credentials.run == run else None

    def known(self, island: str, run: str) -> tuple[int, float] | None:
        """The last message number of that run the coordinator accepted, and how long ago it said so (None: the roster
        does not list the run; :class:`island.sealing.ReplayGuard`)."""
        with self._cond:
            entry = self._roster.get((island, run))
            return None if entry is None else (entry.seq, time.monotonic() - self._roster_at)

    def stored(self, island: str, run: str) -> int:
        """The last iteration of that run whose history the coordinator said it committed (-1: none)."""
        entry = self._roster.get((island, run))
        return -1 if entry is None else entry.stored

    def stop_requested(self) -> bool:
        with self._cond:
            if self._stop or self._gone:
                return True
            silent_s = time.monotonic() - self._heard_at
            if silent_s >= SILENT_S and not self._silent:
                self._silent = True
                self.notify(
                    f"{self._who()}: the coordinator of campaign {self.campaign!r} has been silent for "
                    f"{silent_s:.0f} s; searching on and waiting up to {self.wait_s:g} s (--wait) for it to come back"
                )
            if silent_s >= SILENT_S + self.wait_s:
                self._gone = f"the coordinator was silent for {silent_s:.0f} s"
                self.notify(f"{self._who()}: {self._gone}; stopping")
                self._cond.notify_all()
            return bool(self._gone)

    def stop_reason(self) -> str:
        with self._cond:
            return self._gone or "stopped by the coordinator"

    def stop(self, reason: str) -> None:
        """End every island of this host (they send their last history and leave), e.g. on Ctrl-C."""
        with self._cond:
            self._gone = self._gone or reason
            self._cond.notify_all()

    def wait(self, done: Callable[[], bool], timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` until ``done()`` holds (checked at every control message)."""
        with self._cond:
            return self._cond.wait_for(done, timeout=timeout_s)

    def close(self) -> None:
        self._closing.set()
        for entity in (self._migrants, self._control):
            entity.undeclare()
        for t in self._threads:
            t.join()


class ZenohTransport:
    """One island's Zenoh entities under ``hysid/<campaign>/``, on a :class:`ZenohHost` it shares with the
    other islands of its process (one of its own by default).

    Joins through ``join/<id>`` (:func:`join`, with the campaign ``secret``),
    then publishes on ``migrants/<id>`` and ``history/<id>``, answers
    ``history/<id>?run=R;since=N;...`` with the rows the coordinator is missing
    (after a coordinator restart; only queries the coordinator signed, each
    once), declares the liveliness token ``members/<id>`` (last: it tells the
    coordinator the island is up), and sends a heartbeat whenever it published
    no history for :data:`HEARTBEAT_S`. What it hears (migrants, the roster,
    the stop order, the coordinator's silence) is the host's. ``wait_s``
    bounds the join, the final wait for the coordinator's confirmation, and how
    long the islands wait for a coordinator that fell silent.
    """

    silent_s: float | None = SILENT_MEMBER_S

    def __init__(
        self,
        session: zenoh.Session,
        node: IslandNode,
        secret: CampaignSecret,
        wait_s: float = 30.0,
        notify: Callable[[str], None] | None = None,
        host: ZenohHost | None = None,
    ) -> None:
        self.session = session
        self.node = node
        self.wait_s = wait_s
        self.notify = notify or (lambda message: None)
        self.secret = secret.check_campaign(node.config.name, "the campaign secret")
        self._own_host = host is None
        self.host = host if host is not None else ZenohHost(session, secret, node.objective.bounds, wait_s, notify)
        self.arrivals = self.host.arrivals
        prefix = key_prefix(node.config.name)
        self.prefix = prefix
        try:
            self.credentials = join(session, node.config.name, node.island, node.algo, node.seed, secret, wait_s, node.count_rejected)
        except BaseException:
            if self._own_host:
                self.host.close()
            raise
        self._algo: str | None = None
        """The algorithm the roster assigns this run (None: not said)."""
        self._query_seq = -1
        self._queries: deque[float] = deque(maxlen=int(HISTORY_QUERIES_PER_S))
        node.attach(self)  # migrants are taken from the moment they can arrive
        self._migrants = session.declare_publisher(f"{prefix}/migrants/{node.island}")
        self._history = session.declare_publisher(f"{prefix}/history/{node.island}", congestion_control=zenoh.CongestionControl.BLOCK)
        self._queryable = session.declare_queryable(f"{prefix}/history/{node.island}", zenoh.handlers.FifoChannel(QUERY_QUEUE))
        self._answering = threading.Thread(target=self._take_queries, name=f"queries-{node.island}", daemon=True)
        self._answering.start()
        self._token = session.liveliness().declare_token(f"{prefix}/members/{node.island}")
        self._published_at = time.monotonic()
        self.host.add(self)

    def beat(self) -> None:
        """A heartbeat if the island has published no history for :data:`HEARTBEAT_S` and is still running."""
        if not self.node.finished and time.monotonic() - self._published_at >= HEARTBEAT_S:
            self.publish_history(self.node.heartbeat())

    def assign(self, entry: MemberState | None) -> None:
        """This run's entry of a new roster (the host holds its lock): the algorithm it is to run."""
        algo = self._algo if entry is None else entry.algo
        if algo is not None and algo != self._algo and algo != self.node.algo:
            self.notify(
                f"island {self.node.island}: campaign {self.node.config.name!r} moves this island from "
                f"{self.node.algo.upper()} to {algo.upper()} (the share of a mixed campaign); its search carries on"
            )
        self._algo = algo

    def _take_queries(self) -> None:
        """Answer the history queries as they come (until the queryable goes)."""
        for query in self._queryable:
            try:
                self._answer(query)
            finally:
                query.drop()  # the asker's last answer: it need not wait for its timeout

    def _answer(self, query: zenoh.Query) -> None:
        """Rows for the coordinator only: its signature, a number it never used before, at most
        :data:`HISTORY_QUERIES_PER_S` a second; anything else is counted as rejected and not answered."""
        now = time.monotonic()
        if len(self._queries) == self._queries.maxlen and now - self._queries[0] < 1.0:
            self.node.count_rejected()  # more history queries than the coordinator ever sends
            return
        try:
            q = decode_history_query(query.parameters, self.node.config.name, self.node.island, self.secret.coordinator)
        except MessageRejected:
            self.node.count_rejected()
            return
        with self.host._cond:
            fresh = q.seq > self._query_seq
            self._query_seq = max(self._query_seq, q.seq)
        if not fresh:
            self.node.count_rejected()
            return
        self._queries.append(now)
        since = q.since if q.run == self.node.run_id else -1
        for message in self.node.history_messages(since=since, final=self.node.finished):
            query.reply(query.key_expr, message)

    # --- Transport ---
    def exchange(self, epoch: int, payload: bytes) -> list[tuple[str, bytes]]:
        """Migrants arrive through the host's subscription as they come; nothing is left to hand over."""
        self._migrants.put(payload)
        return []

    def publish_history(self, payload: bytes) -> None:
        self._published_at = time.monotonic()
        self._history.put(payload)

    def members(self) -> list[str]:
        """Islands alive by the roster, in the order they joined (this one where it joined, or last)."""
        alive = self.host.members()
        return alive if self.node.island in alive else [*alive, self.node.island]

    def key_for(self, island: str, run: str) -> bytes | None:
        return self.host.key_for(island, run)

    def stop_requested(self) -> bool:
        return self.host.stop_requested()

    def stop_reason(self) -> str:
        return self.host.stop_reason()

    def assigned_algo(self) -> str | None:
        with self.host._cond:
            return self._algo

    def global_best(self) -> list[bytes]:
        """Every answer on ``best`` (a stranger's among them is refused when decoded)."""
        return replies(self.session, f"{self.prefix}/best", 2.0)

    def wait_for_members(self, n: int, timeout_s: float) -> None:
        """Islands the roster lists count, including those that have left: a fast island may finish before a slow one starts."""
        self.host.wait(lambda: len(self.host._listed | {self.node.island}) >= n or bool(self.host._stop or self.host._gone), timeout_s)

    def confirm(self, iteration: int) -> bool:
        """Wait (up to the host's ``confirm_s``) for a control message saying rows up to ``iteration`` are committed."""
        return self.host.wait(lambda: self.host.stored(self.node.island, self.credentials.run) >= iteration, self.host.confirm_s)

    def close(self) -> None:
        """Leave the campaign: the token goes last, after the final history was sent."""
        self.host.remove(self)
        for entity in (self._queryable, self._migrants, self._history):
            entity.undeclare()
        self._answering.join()
        self._token.undeclare()
        if self._own_host:
            self.host.close()
