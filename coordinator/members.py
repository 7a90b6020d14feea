"""Who is in a campaign: the coordinator's record of island runs alive, left or lost.

An island run is a member once it joined (:meth:`Membership.joined`, the join
handshake of :meth:`coordinator.server.Coordinator.admit`); its Zenoh
liveliness token says it is there (:meth:`Membership.token`). A liveliness
token proves nothing (anyone who reaches the router can declare one under any
name), so it only ever counts for a run that joined, and only as far as the
run's signed messages bear it out: the run's final history is its leave
(:meth:`Membership.final_history`), whatever token stays; a token that goes
without it for :data:`LEAVE_GRACE_S`, or never shows within :data:`TOKEN_WAIT_S`,
is a loss (:meth:`Membership.settle`): crash, kill, or a frozen process whose
Zenoh lease expired. A lost run is back when its token returns *and* a signed
message of the run arrived since it was lost (:meth:`Membership.heard`); a
run that left never comes back (a new run of the island joins anew).
After a restart (``--resume``) the runs that were alive when the previous
coordinator died are taken up again (:meth:`Membership.take_up`), lost unless
their token returns. Every event is stored as it happens
(:meth:`coordinator.store.Store.member_event`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from coordinator.store import Store

LEAVE_GRACE_S = 0.3
"""After a token disappears, how long a final history may still arrive to count as a graceful leave."""
TOKEN_WAIT_S = 10.0
"""A joined island whose liveliness token has not shown within this is lost."""
STATUS_AFTER = {"join": "alive", "seen": "alive", "back": "alive", "left": "left", "lost": "lost"}
"""A member's status after each recorded membership event."""


@dataclass
class Member:
    status: str = "alive"
    """alive, left (said goodbye), lost (vanished: crash, kill, lease expired, token never shown)"""
    run: str = ""
    gone_at: float | None = None
    token: bool = False
    """Its liveliness token was seen (since it joined or came back)."""
    joined_at: float = 0.0
    nonce: bytes = b""
    """The join request that admitted this run (a repeated request gets the same credentials)."""
    resumed: bool = False
    """Alive when the previous coordinator died: taken up by this one, lost unless its token shows
    within :data:`TOKEN_WAIT_S`."""
    lost_at: float = 0.0
    heard_at: float = 0.0
    """``time.monotonic()`` of the run's last message whose signature verified."""


class Membership:
    """The members of campaign ``campaign`` (``members``: island -> its latest run as a :class:`Member`),
    each event stored in ``store``; ``finished(island, run)`` says whether that run sent its final
    history."""

    def __init__(self, store: Store, campaign: str, min_islands: int, finished: Callable[[str, str], bool]) -> None:
        self.store = store
        self.campaign = campaign
        self.min_islands = min_islands
        self.finished = finished
        self.members: dict[str, Member] = {}
        self.full_at: float | None = None
        """``time.monotonic()`` when ``min_islands`` islands were first alive: the islands start searching."""
        self.idle_since: float | None = None
        """Since when no island has been alive, once some joined (None while one is)."""
        self.events = 0
        """Membership events recorded by this process (progress is shown at each)."""

    def alive(self, island: str, run: str) -> bool:
        member = self.members.get(island)
        return member is not None and member.status == "alive" and member.run == run

    def any_alive(self) -> bool:
        return any(m.status == "alive" for m in self.members.values())

    def take_up(self, current: dict[str, str]) -> None:
        """After a restart: every island run (``current``: island -> its latest run) that was alive when
        the previous coordinator died (its last membership event says so, it never said goodbye) is a
        member again, waiting for its liveliness token; :meth:`settle` records it lost if the token
        does not show within :data:`TOKEN_WAIT_S`, so an island that died with the coordinator is not
        listed alive forever, and one that comes back carries on as the same run."""
        status = {island: STATUS_AFTER[event] for island, event, _ in self.store.members(self.campaign)}
        now = time.monotonic()
        for island, run in current.items():
            if status.get(island) == "alive" and not self.finished(island, run):
                self.members[island] = Member("alive", run, joined_at=now, resumed=True)

    def joined(self, island: str, run: str, nonce: bytes) -> None:
        """Run ``run`` of ``island`` was admitted by the join request ``nonce``."""
        self.members[island] = Member("alive", run, joined_at=time.monotonic(), nonce=nonce)
        self._event(island, "join")
        self._now_alive()

    def token(self, island: str, run: str, alive: bool) -> None:
        """The liveliness token of ``island`` (whose latest run is ``run``) appeared (``alive``) or went."""
        member = self.members.get(island)
        if alive:
            if member is None or (member.resumed and member.status == "alive"):  # joined before this coordinator (re)started
                self.members[island] = Member("alive", run, token=True, joined_at=time.monotonic())
                self._event(island, "join")
                self._now_alive()
            elif member.status == "lost":
                member.token = True
                self._back(island, member)
            elif member.status == "alive":
                member.gone_at, member.token = None, True
        elif member is not None:
            member.token = False
            if member.status == "alive":
                member.gone_at = time.monotonic()

    def heard(self, island: str, run: str) -> None:
        """A message of run ``run`` of ``island`` whose signature verified: a lost run whose token is back is back."""
        member = self.members.get(island)
        if member is not None and member.run == run:
            member.heard_at = time.monotonic()
            if member.status == "lost":
                self._back(island, member)

    def _back(self, island: str, member: Member) -> None:
        if member.token and member.heard_at > member.lost_at:
            member.status, member.gone_at = "alive", None
            self._event(island, "back")
            self._now_alive()

    def final_history(self, island: str, run: str) -> None:
        """The final history of ``run`` of ``island`` arrived: it left (its token may go later, or be held by someone else)."""
        member = self.members.get(island)
        if member is not None and member.run == run and member.status == "alive":
            self._leave(island, member, "left")

    def settle(self) -> None:
        """Tokens gone without a final history for ``LEAVE_GRACE_S``, or never shown: the island is lost."""
        now = time.monotonic()
        for island, member in self.members.items():
            vanished = member.gone_at is not None and now - member.gone_at >= LEAVE_GRACE_S
            never_seen = not member.token and now - member.joined_at >= TOKEN_WAIT_S
            if member.status == "alive" and (vanished or never_seen):
                self._leave(island, member, "lost")

    def _now_alive(self) -> None:
        alive = sum(m.status == "alive" for m in self.members.values())
        if alive:
            self.idle_since = None
        if self.full_at is None and alive >= self.min_islands:
            self.full_at = time.monotonic()

    def _leave(self, island: str, member: Member, event: str) -> None:
        member.status, member.lost_at = event, time.monotonic()
        self._event(island, event)
        if not self.any_alive():
            self.idle_since = time.monotonic()

    def _event(self, island: str, event: str) -> None:
        self.store.member_event(self.campaign, island, event)
        self.events += 1
