"""The coordinator's inbox: bounded, fair, with back-pressure.

Everything that arrives (island messages, membership changes, join requests)
waits here for the coordinator's one thread. The inbox holds one queue per
*source* (an island that joined has its own; senders that never joined share
one) and hands items out round-robin, so that a flooding source cannot starve
the others. Its size is bounded in items per source, in sources and in bytes:
a producer that finds its queue full waits up to ``wait_s`` (back-pressure:
Zenoh's reader for that link pauses, a publisher with congestion control
``BLOCK`` slows down) and then the item is dropped and counted. Honest islands
lose nothing by a drop: the coordinator asks again for history rows it misses
(:meth:`coordinator.histories.Gaps.arrived`).

Items that only the newest of matters (an island's migrant messages, once the
producer checked they are its run's and well formed: the coordinator takes them
for the global best, and an island's best never gets worse; a message that
would be rejected is never replaceable, so that it is rejected with its reason)
are *replaceable*: while the coordinator keeps up (fewer than
:data:`CROWDED` other items waiting) they queue like any other and every one is
handled; when it falls behind, each source has one slot for them, a newer one
replaces the one waiting (counted as superseded, per source), and slots are
served after the other items (at least every :data:`SLOT_EVERY` th item),
so that they never delay what must all be handled, the history rows. *Urgent* items (membership
changes and join requests: cheap to handle, and a site's islands must be found lost within the
lease and a moment however many history messages wait) have a lane of their own, its sources
served in turn: an urgent item waiting is served next, unless the :data:`URGENT_RUN` items before were
urgent too while others waited (a site's tokens go together and are handled together; a flood of urgent
items still leaves the other lane one turn in ``URGENT_RUN + 1``). Once the coordinator is done
(:meth:`Inbox.close`) every producer returns at once, those waiting included:
nothing that arrives on the network can hold a Zenoh callback, and with it the
process, any longer.
"""

from __future__ import annotations

import threading
import time
from collections import Counter, OrderedDict, deque
from typing import Any

PER_SOURCE = 4096
"""Items one source may have waiting."""
MAX_SOURCES = 8192
MAX_BYTES = 256 << 20
"""Payload bytes waiting in all."""
SLOT_EVERY = 4
"""While other items wait, a replaceable one is served every this many items."""
URGENT_RUN = 8
"""Urgent items served in a row, at most, while other items wait."""
CROWDED = 256
"""Items waiting from which on a replaceable item supersedes its source's one waiting (the coordinator is behind)."""


class Inbox:
    """See the module docstring; thread-safe."""

    def __init__(self, per_source: int = PER_SOURCE, max_sources: int = MAX_SOURCES, max_bytes: int = MAX_BYTES, crowded: int = CROWDED) -> None:
        self.per_source = per_source
        self.max_sources = max_sources
        self.max_bytes = max_bytes
        self.crowded = crowded
        self._queues: OrderedDict[str, deque[tuple[Any, int]]] = OrderedDict()
        """Sources with items waiting, in the order they are served next."""
        self._urgent: OrderedDict[str, deque[tuple[Any, int]]] = OrderedDict()
        """The same, of urgent items."""
        self._slots: OrderedDict[str, tuple[Any, int]] = OrderedDict()
        """Each source's replaceable item waiting, in the order the slots filled."""
        self._served = 0
        self._urgent_run = 0
        """Urgent items served in a row until now."""
        self._waiting = 0
        """Items in the queues (not the slots)."""
        self._bytes = 0
        self._dropped: Counter[str] = Counter()
        self._superseded: Counter[str] = Counter()
        self._closed = False
        self._cond = threading.Condition()

    def is_crowded(self) -> bool:
        """Whether :attr:`crowded` items or more wait (read without the lock: a measure of load, not a count to keep)."""
        return self._waiting >= self.crowded

    def _full(self, lane: OrderedDict[str, deque[tuple[Any, int]]], source: str, size: int) -> bool:
        queue = lane.get(source)
        if queue is None:
            return len(self._queues) + len(self._urgent) >= self.max_sources or self._bytes + size > self.max_bytes
        return len(queue) >= self.per_source or (self._bytes + size > self.max_bytes and bool(queue))

    def put(self, source: str, item: Any, size: int = 0, wait_s: float | None = 1.0, replace: bool = False, urgent: bool = False) -> bool:
        """Queue ``item`` (``size`` payload bytes) from ``source``; waits up to ``wait_s`` (None: as
        long as it takes) while that source's queue is full, then drops it. False if dropped.
        A ``replace`` able item, while :attr:`crowded` items or more wait, takes the source's slot, superseding
        the one waiting there; an ``urgent`` one waits in the urgent lane."""
        if replace and self.is_crowded():
            return self._replace(source, item, size)
        lane = self._urgent if urgent else self._queues
        deadline = None if wait_s is None else time.monotonic() + wait_s
        with self._cond:
            while self._closed or self._full(lane, source, size):
                remaining = None if deadline is None else deadline - time.monotonic()
                if self._closed or (remaining is not None and remaining <= 0):
                    self._dropped[source] += 1
                    return False
                self._cond.wait(remaining)
            lane.setdefault(source, deque()).append((item, size))
            self._waiting += 1
            self._bytes += size
            self._cond.notify_all()
            return True

    def _replace(self, source: str, item: Any, size: int) -> bool:
        with self._cond:
            old = self._slots.get(source)
            if self._closed or (old is None and (len(self._slots) >= self.max_sources or self._bytes + size > self.max_bytes)):
                self._dropped[source] += 1
                return False
            if old is not None:
                self._bytes -= old[1]
                self._superseded[source] += 1
            self._slots[source] = (item, size)
            self._bytes += size
            self._cond.notify_all()
            return True

    def get(self, timeout: float = 0.0) -> Any | None:
        """The next item, taking one from each source of a lane in turn (an urgent one first, but not more than
        :data:`URGENT_RUN` in a row while others wait; a replaceable one when nothing else waits, or every :data:`SLOT_EVERY` th); None if
        nothing came within ``timeout``."""
        with self._cond:
            if not self._cond.wait_for(lambda: bool(self._queues or self._urgent or self._slots), timeout=timeout):
                return None
            self._served += 1
            if self._slots and (not (self._queues or self._urgent) or self._served % SLOT_EVERY == 0):
                _, (item, size) = self._slots.popitem(last=False)
                self._bytes -= size
                self._cond.notify_all()
                return item
            lane = self._urgent if self._urgent and (not self._queues or self._urgent_run < URGENT_RUN) else self._queues
            self._urgent_run = self._urgent_run + 1 if lane is self._urgent else 0
            source, queue = next(iter(lane.items()))
            item, size = queue.popleft()
            self._waiting -= 1
            del lane[source]
            if queue:
                lane[source] = queue  # to the back of the round
            self._bytes -= size
            self._cond.notify_all()
            return item

    def holds(self, source: str) -> bool:
        """Whether items of ``source`` wait (in its queue or its slot; read without the lock, a glance)."""
        return source in self._queues or source in self._slots

    def close(self) -> None:
        """Take nothing more: every put, waiting or to come, returns False at once."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    def __len__(self) -> int:
        with self._cond:
            return self._waiting + len(self._slots)

    def take_dropped(self) -> dict[str, int]:
        """Items dropped per source since the last call."""
        with self._cond:
            dropped = dict(self._dropped)
            self._dropped.clear()
            return dropped

    def take_superseded(self) -> dict[str, int]:
        """Replaceable items superseded per source since the last call."""
        with self._cond:
            superseded = dict(self._superseded)
            self._superseded.clear()
            return superseded
