"""Migrant messages as they arrive: checked once, each sender's newest kept for the islands that take them.

One :class:`Arrivals` serves one island (in memory, :mod:`island.transports`'
:class:`~island.memory.MemoryTransport`), or every island of a process
over one Zenoh session (:class:`~island.transports.ZenohHost`): a message is
read, its signature verified and its number checked against replays once,
however many islands of the process take from its sender.

* Each message is validated as it arrives (:mod:`island.protocol`: form, the
  signature of its sender's run with the public key the roster lists for it,
  then replays and numbers too far ahead, the first one a run is heard with
  bounded by the last number the coordinator accepted of it: nobody can sign as
  another island, nor move another's replay window); rejects are counted
  (``on_reject``).
* Of each sender only the newest valid message is kept (at most
  :data:`MAX_SENDERS` senders; strangers are forgotten first), so that a flood
  cannot grow it; an island takes at most ``k`` migrants of it per migration
  (:meth:`island.node.IslandNode._intake`).
* A message from a run the roster does not list yet waits (the newest of each
  sender, up to :data:`JOIN_GRACE_S`) for it: the coordinator sends its roster at
  every join, before the joiner hears it joined, but Zenoh does not promise the
  order of two publishers. One that waited in vain is counted apart from those
  rejected (``on_unlisted``): its run was never listed within the grace
  (:meth:`Arrivals.listed`), a newer one of its sender came, there was no room,
  or the last island taking from it ended first (:meth:`Arrivals.leave`).
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Collection
from dataclasses import dataclass, field

import numpy as np

from island.island_messages import Migrants, migrants_of
from island.sealing import Envelope, KeyLookup, Known, ReplayGuard, check_replay, envelope, open_envelope
from island.wire import MAX_MEMBERS, MessageRejected

MAX_SENDERS = MAX_MEMBERS
"""Senders whose newest migrant message is kept between two migrations (every island a campaign admits)."""
JOIN_GRACE_S = 5.0
"""How long migrants from a sender that is not (yet) a member wait for the roster to list it."""


@dataclass(eq=False)
class Arrivals:
    """The migrant messages of campaign ``campaign`` (search space ``bounds``) that arrived (see the module
    docstring). ``key_for(island, run)`` is the public key the roster lists for a run (None: not listed),
    ``members()`` the islands alive, ``on_reject()`` counts a rejected message, ``on_unlisted()`` one that waited
    in vain for the roster; ``known(island, run)`` what the roster says of a run's message numbers
    (:data:`island.sealing.Known`; None: nothing). Thread-safe."""

    campaign: str
    bounds: np.ndarray
    key_for: KeyLookup
    members: Callable[[], list[str]]
    on_reject: Callable[[], None]
    on_unlisted: Callable[[], None]
    known: Callable[[str, str], Known | None] = field(default=lambda island, run: None)
    _lock: threading.Lock = field(default_factory=threading.Lock, init=False, repr=False)
    _replays: ReplayGuard = field(default_factory=ReplayGuard, init=False, repr=False)
    _latest: OrderedDict[str, tuple[float, Migrants]] = field(default_factory=OrderedDict, init=False, repr=False)
    """Each sender's newest valid migrant message and when it arrived."""
    _pending: OrderedDict[str, tuple[float, Envelope]] = field(default_factory=OrderedDict, init=False, repr=False)
    """Each sender's newest message from a run the roster does not list yet (checked once it does)."""
    _takers: set[str] = field(default_factory=set, init=False, repr=False)
    """The islands taking from these arrivals (:meth:`join`, :meth:`leave`)."""

    def join(self, island: str) -> None:
        """``island`` takes from these arrivals from now on."""
        with self._lock:
            self._takers.add(island)

    def leave(self, island: str) -> int:
        """``island`` takes no more; if it was the last, what still waits for its run to be listed has waited
        in vain: returns how many such messages (the caller counts them as unlisted, in its last history)."""
        with self._lock:
            self._takers.discard(island)
            if self._takers:
                return 0
            waited, self._pending = len(self._pending), OrderedDict()
        return waited

    def receive(self, sender: str, data: bytes) -> None:
        """A migrant message as it arrives on ``migrants/<sender>`` (from any thread)."""
        try:
            env = envelope(data, "migrants", self.campaign, sender)
        except MessageRejected:
            self.on_reject()
            return
        key = self.key_for(env.sender, env.run)
        if key is None:
            with self._lock:
                waited = int(self._pending.pop(env.sender, None) is not None)  # a newer one of a joiner: the older waited in vain
                self._pending[env.sender] = (time.monotonic(), env)
                while len(self._pending) > MAX_SENDERS:
                    self._pending.popitem(last=False)
                    waited += 1
            for _ in range(waited):
                self.on_unlisted()
            return
        self._open(env, key)

    def _open(self, env: Envelope, key: bytes) -> None:
        try:
            m = migrants_of(open_envelope(env, key), self.campaign, self.bounds, time.time())
            check_replay(self._replays, "migrants", m.island, m.run, m.seq, self.known(m.island, m.run))
        except MessageRejected:
            self.on_reject()
            return
        members = set(self.members())
        with self._lock:
            if m.island not in self._latest and len(self._latest) >= MAX_SENDERS:
                strangers = [s for s in self._latest if s not in members]
                if not strangers and m.island not in members:
                    return  # no room for yet another stranger
                del self._latest[strangers[0] if strangers else next(iter(self._latest))]
            self._latest.pop(m.island, None)
            self._latest[m.island] = (time.monotonic(), m)

    def listed(self) -> None:
        """Check the waiting messages whose run the roster lists by now; those older than
        :data:`JOIN_GRACE_S` waited in vain (their run was never listed): counted as unlisted."""
        now = time.monotonic()
        with self._lock:
            waiting = list(self._pending.items())
        for sender, (at, env) in waiting:
            key = self.key_for(env.sender, env.run)
            if key is not None or now - at >= JOIN_GRACE_S:
                with self._lock:
                    if self._pending.get(sender, (None, None))[1] is env:
                        del self._pending[sender]
                    else:
                        continue  # another island of the process took it meanwhile
                if key is not None:
                    self._open(env, key)
                else:
                    self.on_unlisted()

    def heard(self, within_s: float) -> set[str]:
        """Senders whose newest message arrived within the last ``within_s`` seconds."""
        now = time.monotonic()
        with self._lock:
            return {sender for sender, (at, _) in self._latest.items() if now - at <= within_s}

    def newest(self, senders: Collection[str], members: Collection[str]) -> list[Migrants]:
        """The newest message of each of ``senders``; messages of non-members older than
        :data:`JOIN_GRACE_S` are forgotten."""
        now = time.monotonic()
        found = []
        with self._lock:
            for sender, (at, m) in list(self._latest.items()):
                if sender in senders:
                    found.append(m)
                elif sender not in members and now - at >= JOIN_GRACE_S:
                    del self._latest[sender]
        return found
