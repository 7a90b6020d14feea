"""Who is in a campaign: the coordinator's record of island runs alive, left or lost.

An island run is a member once it joined (:meth:`Membership.joined`, the join
handshake of :meth:`coordinator.state.Coordinator.admit`). What keeps it
alive is what it signs: every message whose signature verified
(:meth:`Membership.heard`; an island sends its history at least every second,
a heartbeat when it has no new row). Its Zenoh liveliness token is only a hint
for noticing a loss sooner: anyone who reaches the router can declare a token
under any name, and Zenoh shows one token per name whoever holds it, so a
token never makes a run a member or brings one back, and a token held by a
stranger cannot hide a loss for longer than :data:`STALE_S`. The run's final
history is its leave (:meth:`Membership.final_history`), whatever token stays
(also one handled after the run was found lost: it was sent before);
a token that goes without it for :data:`LEAVE_GRACE_S`, or no signed message
for :data:`STALE_S`, is a loss (:meth:`Membership.settle`): crash, kill, or a
frozen process. Once the user stopped the campaign (Ctrl-C), a run's final history records
that it was ``stopped`` (by the user) instead of ``left`` (:meth:`Membership.stopped_by_user`).
A lost run is back with its next signed message; a run that
left or was stopped never comes back (a new run of the island joins anew). After a restart
(``--resume``) the runs that were alive when the previous coordinator died are
taken up again (:meth:`Membership.take_up`), lost unless they are heard from
within :data:`STALE_S`. Every event is stored as it happens
(:meth:`coordinator.store.Store.member_event`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from coordinator.store import Store

LEAVE_GRACE_S = 0.3
"""After a token disappears, how long a final history may still arrive to count as a graceful leave."""
STALE_S = 10.0
"""A joined island run with no signed message for this long is lost (an island sends one every second
at least)."""
STATUS_AFTER = {"join": "alive", "seen": "alive", "back": "alive", "left": "left", "lost": "lost", "stopped": "stopped"}
"""A member's status after each recorded membership event."""


@dataclass
class Member:
    status: str = "alive"
    """alive, left (said goodbye), stopped (said goodbye, or was given up on, once the user stopped the
    campaign), lost (vanished: crash, kill, lease expired, silent)"""
    run: str = ""
    gone_at: float | None = None
    token: bool = False
    """A liveliness token under its name is there (its own, or anyone's)."""
    joined_at: float = 0.0
    nonce: bytes = b""
    """The join request that admitted this run (a repeated request gets the same credentials)."""
    resumed: bool = False
    """Alive when the previous coordinator died: taken up by this one, lost unless it is heard from
    within :data:`STALE_S`."""
    heard_at: float = 0.0
    """``time.monotonic()`` of the run's last message whose signature verified (or of its join)."""
    lost_at: float | None = None
    """``time.monotonic()`` when it was found lost (None: it was not)."""


class Membership:
    """The members of campaign ``campaign`` (``members``: island -> its latest run as a :class:`Member`),
    each event stored in ``store``; ``finished(island, run)`` says whether that run sent its final
    history."""

    def __init__(self, store: Store, campaign: str, min_islands: int, finished: Callable[[str, str], bool]) -> None:
        self.store = store
        self.campaign = campaign
        self.min_islands = min_islands
        self.finished = finished
        self.stale_s = STALE_S
        """How long a run may stay silent (islands of this process, which cannot be impersonated: never lost so)."""
        self.members: dict[str, Member] = {}
        self.full_at: float | None = None
        """``time.monotonic()`` when ``min_islands`` islands were first alive: the islands start searching."""
        self.idle_since: float | None = None
        """Since when no island has been alive, once some joined (None while one is)."""
        self.events = 0
        """Membership events recorded by this process (progress is shown at each)."""
        self.leave_event = "left"
        """What a final history records: ``left``, or ``stopped`` once the user stopped the campaign."""

    def alive(self, island: str, run: str) -> bool:
        member = self.members.get(island)
        return member is not None and member.status == "alive" and member.run == run

    def any_alive(self) -> bool:
        return any(m.status == "alive" for m in self.members.values())

    def take_up(self, current: dict[str, str]) -> None:
        """After a restart: every island run (``current``: island -> its latest run) that was alive when
        the previous coordinator died (its last membership event says so, it never said goodbye) is a
        member again; :meth:`settle` records it lost if it is not heard from within :data:`STALE_S`, so
        an island that died with the coordinator is not listed alive forever, and one that comes back
        carries on as the same run."""
        status = {island: STATUS_AFTER[event] for island, event, _ in self.store.members(self.campaign)}
        now = time.monotonic()
        for island, run in current.items():
            if status.get(island) == "alive" and not self.finished(island, run):
                self.members[island] = Member("alive", run, joined_at=now, resumed=True, heard_at=now)

    def joined(self, island: str, run: str, nonce: bytes) -> None:
        """Run ``run`` of ``island`` was admitted by the join request ``nonce``."""
        now = time.monotonic()
        self.members[island] = Member("alive", run, joined_at=now, nonce=nonce, heard_at=now)
        self._event(island, "join")
        self._now_alive()

    def token(self, island: str, run: str, alive: bool) -> None:
        """A liveliness token of ``island`` (whose latest run is ``run``) appeared (``alive``) or went."""
        member = self.members.get(island)
        if member is None:
            return
        member.token = alive
        if member.status == "alive":
            member.gone_at = None if alive else time.monotonic()

    def heard(self, island: str, run: str, arrived: float) -> None:
        """A message of ``island``'s latest run ``run`` whose signature verified, arrived at ``arrived``
        (``time.monotonic()``): it is alive (a lost run is back, unless the message arrived
        before it was found lost and only waited to be handled; one that joined before this coordinator
        restarted is a member again)."""
        member = self.members.get(island)
        now = time.monotonic()
        if member is not None and member.status == "lost" and member.lost_at is not None and arrived <= member.lost_at:
            return  # sent before it vanished: no sign that it is back
        if member is None:
            self.members[island] = Member("alive", run, joined_at=now, heard_at=now)
            self._event(island, "join")
        elif member.run != run:
            return
        elif member.status == "lost":
            member.status, member.gone_at, member.heard_at = "alive", None, now
            self._event(island, "back")
        else:
            member.heard_at = now
            if member.resumed:  # taken up after a restart, and heard again
                member.resumed = False
                self._event(island, "join")
            return
        self._now_alive()

    def final_history(self, island: str, run: str) -> None:
        """The final history of ``run`` of ``island`` arrived: it left (its token may go later, or be held by someone
        else). Also when it was found lost: a coordinator that is behind handles a token's going (urgent) before the
        final history that came first and waited longer than :data:`LEAVE_GRACE_S`; the loss stays recorded, then the leave."""
        member = self.members.get(island)
        if member is not None and member.run == run and member.status in ("alive", "lost"):
            self._leave(island, member, self.leave_event)

    def stopped_by_user(self, *, give_up: bool = False) -> None:
        """The user stopped the campaign (Ctrl-C): final histories from now on record ``stopped``; with
        ``give_up`` (the coordinator no longer waits for their last rows) every run still alive is recorded
        ``stopped`` now."""
        self.leave_event = "stopped"
        if give_up:
            for island, member in self.members.items():
                if member.status == "alive":
                    self._leave(island, member, "stopped")

    def settle(self, waiting: Callable[[str], bool] | None = None) -> None:
        """A token gone without a final history for :data:`LEAVE_GRACE_S`, or no signed message for
        :attr:`stale_s`: the island is lost; with ``waiting`` (once the stop order went out, when every island
        leaves), not while ``waiting(island)`` says messages of it wait to be handled: its final history is
        likely one of them."""
        now = time.monotonic()
        for island, member in self.members.items():
            vanished = member.gone_at is not None and now - member.gone_at >= LEAVE_GRACE_S and not (waiting is not None and waiting(island))
            if member.status == "alive" and (vanished or now - member.heard_at >= self.stale_s):
                self._leave(island, member, "lost")

    def _now_alive(self) -> None:
        alive = sum(m.status == "alive" for m in self.members.values())
        if alive:
            self.idle_since = None
        if self.full_at is None and alive >= self.min_islands:
            self.full_at = time.monotonic()

    def _leave(self, island: str, member: Member, event: str) -> None:
        member.status = event
        member.lost_at = time.monotonic() if event == "lost" else None
        self._event(island, event)
        if not self.any_alive():
            self.idle_since = time.monotonic()

    def _event(self, island: str, event: str) -> None:
        self.store.member_event(self.campaign, island, event)
        self.events += 1
