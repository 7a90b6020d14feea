"""What arrives at the coordinator, and how: into its inbox from the threads messages arrive on, then handled
one item at a time on its own thread, or rejected with the reason.

:class:`Receiving` (part of :class:`coordinator.state.Coordinator`):

* :meth:`Receiving.receive`, :meth:`Receiving.member` and :meth:`Receiving.join_request` are what other
  threads (a Zenoh link's callbacks, the island threads of a single-node campaign) call: each puts an item in the
  bounded, fair inbox (:mod:`coordinator.inbox`), in the queue of its sender once it joined (strangers share one).
  A publication too large for its kind waits without its bytes; a joined island's migrant message, checked as it
  arrives (signature and form), may replace its one still waiting: only its newest matters;
* :meth:`Receiving.handle` takes an item on the coordinator's thread to the join handshake
  (:class:`coordinator.admission.Admission`), the membership (a liveliness token), or the history and migrant
  handling (:class:`coordinator.intake.Intake`). Nothing a message holds raises out of it: what fails a check, or
  slips through the checks and fails later (:data:`SLIPPED_THROUGH`), is rejected and recorded with its reason,
  one by one up to :data:`REJECTED_PER_S` a second (a :class:`TokenBucket`), beyond it counted in summaries; only a
  database that cannot be written (:class:`coordinator.writes.StoreError`) stops the coordinator.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from coordinator.held import Held
from coordinator.link import Link
from coordinator.writes import StoreError
from island.island_messages import Migrants, decode_history, decode_migrants
from island.wire import MAX_BYTES, NAME_PATTERN, MessageRejected

if TYPE_CHECKING:
    from island.island_messages import History

REJECTED_PER_S, REJECTED_BURST = 200.0, 5000
"""Rejected messages recorded one by one (a token bucket); beyond it they are counted in summaries."""
SLIPPED_THROUGH = (ValueError, TypeError, OverflowError, ArithmeticError, IndexError, KeyError)
"""What a message the checks let through may still raise when it is handled: it is rejected, never raised."""


class TokenBucket:
    """``burst`` tokens at most, ``rate`` more a second: :meth:`take` says whether one was left."""

    def __init__(self, rate: float, burst: int) -> None:
        self.rate, self.burst = rate, burst
        self.level, self.at = float(burst), time.monotonic()

    def take(self) -> bool:
        now = time.monotonic()
        self.level = min(self.burst, self.level + (now - self.at) * self.rate)
        self.at = now
        if self.level >= 1.0:
            self.level -= 1.0
            return True
        return False


class Receiving(Held):
    """The receiving part of :class:`coordinator.state.Coordinator` (see the module docstring; the state it uses,
    the inbox, the store and the membership among it, is the coordinator's)."""

    if TYPE_CHECKING:  # its own rate of logged rejections (set in Coordinator.__init__), and what the other parts give it
        _rejected_log: TokenBucket

        def _join(self, link: Link, island: str, payload: bytes, reply: Callable[[bytes], None]) -> None: ...

        def _history(self, link: Link, h: History, arrived: float) -> None: ...

        def _migrants(self, link: Link, m: Migrants, arrived: float) -> None: ...

    # --- what other threads call: into the inbox ------------------------------------------------
    def _source(self, island: str) -> str:
        """Inbox queue of a sender: its own once it joined, else the one all strangers share."""
        return island if island in self.current else "?"

    def receive(self, key: str, payload: bytes, wait_s: float | None = 1.0) -> bool:
        """A publication (``hysid/<c>/<kind>/<sender>``) for the coordinator's thread; False if dropped. A
        joined island's migrant message may replace its one still waiting (only its newest matters:
        :mod:`coordinator.inbox`), once it proved to be its run's, well formed: what could be rejected
        waits to be, with its reason. Migrant messages are let pass once the coordinator stopped following
        them (:meth:`coordinator.intake.Intake.review_following`)."""
        kind, sender = key.rsplit("/", 2)[-2:] if key.count("/") >= 2 else ("", key)
        if kind == "migrants" and not self.follows_migrants:
            return True  # on its way when the coordinator stopped following them: the islands count it
        source = self._source(sender)
        if len(payload) > MAX_BYTES.get(kind, 0) > 0:  # rejected as it is: its bytes need not wait (a flood of them would fill the inbox)
            return self.inbox.put(source, ("oversized", key, len(payload), MAX_BYTES[kind]), 0, wait_s)
        m = self._authentic(payload, sender) if kind == "migrants" and source != "?" and self.inbox.is_crowded() else None
        if m is not None:
            return self.inbox.put(source, ("migrants", key, m, time.monotonic()), len(payload), wait_s, replace=True)
        return self.inbox.put(source, ("msg", key, payload, time.monotonic()), len(payload), wait_s)

    def _authentic(self, payload: bytes, sender: str) -> Migrants | None:
        """A migrant message, if it is signed by a run of ``sender`` and well formed (None: it is not;
        replays are the coordinator's thread's to check; called from the thread a message arrives on)."""
        try:
            return decode_migrants(payload, self.name, self.objective.bounds, key_for=self._key_for, sender=sender)
        except (MessageRejected, *SLIPPED_THROUGH):
            return None

    def member(self, island: str, alive: bool, wait_s: float | None = 1.0) -> bool:
        """A liveliness token of ``members/<island>`` appeared (``alive``) or went."""
        return self.inbox.put("!" + self._source(island), ("member", island, alive), 0, wait_s, urgent=True)

    def join_request(self, island: str, payload: bytes, reply: Callable[[bytes], None], wait_s: float | None = 1.0) -> bool:
        """A step of the join handshake on ``join/<island>``; ``reply`` sends the answer (called by the coordinator's thread)."""
        return self.inbox.put("!" + self._source(island), ("join", island, payload, reply), len(payload), wait_s, urgent=True)

    # --- handling what arrives ----------------------------------------------------------
    def handle(self, link: Link, item: tuple[Any, ...]) -> None:
        """One inbox item: ``("msg", key, payload, arrived)``, ``("migrants", key, message, arrived)`` (checked
        as it arrived but for replays; ``arrived``: its ``time.monotonic()`` then), ``("oversized", key, size, most)``
        (a publication too large for its kind, its bytes dropped as it came), ``("member", island, alive)``
        or ``("join", island, payload, reply)``.

        Nothing a message holds can raise out of here: a rejected message is
        recorded with its reason; only a database that cannot be written
        (:class:`StoreError`) stops the coordinator.
        """
        key, size = f"{item[0]}/{item[1]}", 0
        try:
            if item[0] == "member":
                key = f"members/{item[1]}"
                self._member(link, item[1], item[2])
            elif item[0] == "join":
                key, size = f"join/{item[1]}", len(item[2])
                self._join(link, item[1], item[2], item[3])
            elif item[0] == "migrants":
                key = item[1]
                self._migrants(link, item[2], item[3])
            elif item[0] == "oversized":
                key, size = item[1], item[2]
                raise MessageRejected("oversized", f"a message of {item[2]} bytes under {key[:100]} exceeds {item[3]}")
            else:
                _, key, payload, arrived = item
                size = len(payload)
                kind, _, sender = key[len(self.prefix) + 1 :].partition("/") if key.startswith(self.prefix + "/") else ("", "", "")
                if kind == "history":
                    self._history(link, decode_history(payload, self.name, self.objective.bounds, key_for=self._key_for, sender=sender), arrived)
                elif kind == "migrants":
                    self._migrants(link, decode_migrants(payload, self.name, self.objective.bounds, key_for=self._key_for, sender=sender), arrived)
                else:
                    raise MessageRejected("schema", f"unexpected key {key[:100]}")
        except MessageRejected as exc:
            self.reject(key, exc.reason, str(exc), size)
        except StoreError:
            raise
        except SLIPPED_THROUGH as exc:
            self.reject(key, "schema", f"could not be handled ({type(exc).__name__}: {exc})", size)

    def reject(self, key: str, reason: str, detail: str, size: int) -> None:
        """Count a rejected message; record it, or (in a flood) count it in the next summary row."""
        self.rejected += 1
        if self._rejected_log.take():
            self.store.add_rejected(self.name, key, reason, detail, size)
        else:
            self.rejected_backlog[reason] += 1

    def _key_for(self, island: str, run: str) -> bytes | None:
        info = self.runs.get((island, run))
        return None if info is None else info.key

    def _member(self, link: Link, island: str, alive: bool) -> None:
        if not NAME_PATTERN.match(island):
            raise MessageRejected("sender", "liveliness token with an invalid island name")
        run = self.current.get(island)
        if run is None:
            raise MessageRejected("unjoined", f"liveliness token of {island!r}, which never joined")
        self.membership.token(island, run, alive)
        if alive:
            link.request_history(island, run, self.gaps.stored((island, run)))
