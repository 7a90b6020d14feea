"""How an island's messages travel: over Zenoh, or in memory between island threads.

* :class:`ZenohTransport`: one process per island, key space
  ``hysid/<campaign>/...`` (:func:`key_prefix`, which the coordinator's
  :mod:`coordinator.links` speaks too); :func:`join` is its join handshake,
  :func:`fetch_config` asks the coordinator for the campaign's ``config``
  message before the island is built;
* :class:`MemoryBus` and its :class:`MemoryTransport`: islands as threads of
  one process, in lock step at every epoch so that a single-node campaign is
  reproducible.

Both are :class:`island.node.Transport` s of an :class:`island.node.IslandNode`.
"""

from __future__ import annotations

import re
import secrets
import threading
import time
from collections import deque
from collections.abc import Callable

import zenoh

from hysid_model.errors import HysidInputError
from island.node import IslandNode
from island.protocol import (
    Control,
    JoinRequest,
    decode_control,
    decode_joined,
    encode_join,
)
from island.sealing import Credentials
from island.wire import MAX_COUNT, MAX_MEMBERS, MessageRejected, check_name

SILENT_S = 4.0
"""An island whose coordinator sent no control message for this long (it sends one every second at
least) says so and waits for it, searching on, up to its ``wait_s`` more; then it stops."""
HISTORY_QUERIES_PER_S = 4.0
"""History queries an island answers per second (the coordinator asks every 2 s at most)."""
SINCE_PATTERN = re.compile(r"-?[0-9]{1,16}\Z")


def key_prefix(campaign: str) -> str:
    """The key space of ``campaign``: ``hysid/<campaign>``."""
    return f"hysid/{check_name('campaign', campaign)}"


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
                            f"{self.node.algo.upper()} to {algo.upper()} (the share of a mixed campaign); its search carries on")
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
