"""Who joins a campaign and for which member, what each member may hold and count, and the roster that says so.

The coordinator's admission (:class:`Admission`, part of :class:`coordinator.state.Coordinator`):

* the join handshake, a challenge-response (:mod:`island.protocol`): a request gets a challenge signed by the
  coordinator; a proof of the admission secret of the *member* the request names (the campaign's shared secret for
  the shared member "", a member's secret for a named one, made from the members' key only the coordinator holds,
  :meth:`coordinator.keys.CampaignKeys.admission_for`: a member's islands bear its name) for a challenge this process
  issued within the last :data:`CHALLENGE_S` gets a run id, stored (with the run's public key and its member) before
  the island hears of it;
* what a member may hold: each island id at most :data:`RUNS_PER_ISLAND` runs, each member (the shared one too) at
  most :data:`MEMBER_RUNS` (its share of the campaign's run slots: another member still finds room);
* what a member's effort counts toward the budget and the stall rule (:meth:`Admission.countable`): while more than
  one member is alive, a member's effort counts no further than all the other members' of that time together, so
  that one member, however plausible each of its runs' claims, cannot spend the campaign's budget alone;
* the roster (:meth:`Admission.control_message`, the signed ``control`` message: every run in the order it joined,
  alive or not, how far its history is committed, its algorithm, its public key and the last message number
  accepted of it), sent at every join before the joiner hears it joined (so that every island knows the run before
  its first migrant can come), after every commit that changed something and at least every second.
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
import time
from collections import Counter
from collections.abc import Callable
from typing import TYPE_CHECKING

from coordinator.held import Held
from coordinator.link import Link
from coordinator.records import RunInfo
from hysid_model.errors import HysidInputError
from island.algorithms import ALGORITHMS
from island.coordinator_messages import Control, MemberState, encode_control
from island.handshake import JoinRequest, decode_join_step, encode_challenge, encode_joined, proof_holds
from island.sealing import Credentials, new_key, public_key
from island.secret import of_member
from island.wire import MAX_MEMBERS, NAME_PATTERN, MessageRejected

if TYPE_CHECKING:
    from coordinator.members import Member

CHALLENGE_S = 30.0
"""A join challenge holds for this long (to at most twice this): the proof must come within it."""
RUNS_PER_ISLAND = 64
"""Runs one island id may be admitted (restarts): an island that proved the secret cannot take every run
slot of the campaign under its own id."""
MEMBER_RUNS = MAX_MEMBERS // 2
"""Runs one member may be admitted (the shared member, all holders of the campaign's shared secret together, too): its
share of the campaign's run slots."""


def member_name(member: str) -> str:
    """How a message names ``member``: ``member 'lab2'``, or the shared member of the campaign's shared secret."""
    return f"member {member!r}" if member else "the shared member (the campaign's shared secret)"


class Admission(Held):
    """The admission part of :class:`coordinator.state.Coordinator` (see the module docstring): its joins, runs,
    members' shares and roster (a part of the coordinator's state, which holds the store, membership, sharing and
    checks it uses)."""

    if TYPE_CHECKING:  # what the other parts give this one (the state it uses: Held)

        @property
        def members(self) -> dict[str, Member]: ...

        def review_following(self, link: Link | None = None) -> None: ...

        def last_seq(self, island: str, run: str) -> int: ...

    def _admitted(self, stored: list[tuple[str, str, bytes, str, int, float, str]]) -> None:
        """The runs a stored campaign admitted (``store.runs``): each island's latest run, each member's runs."""
        self._challenges = secrets.token_bytes(32)
        """This process' key for join challenges (a proof for a challenge of another process is stale)."""
        self.runs: dict[tuple[str, str], RunInfo] = {}
        self.current: dict[str, str] = {}
        """Each island's latest run."""
        self.member_runs: Counter[str] = Counter()
        for island, run, key, algo, seed, joined, member in stored:
            self.runs[(island, run)] = RunInfo(key, algo, seed, joined, member)
            self.current[island] = run
            self.member_runs[member] += 1
        self.solo_effort = 0
        """Evaluations counted while at most one member was alive (all of them count)."""
        self.shared_effort: Counter[str] = Counter()
        """Each member's evaluations while more than one member was alive (:meth:`countable`)."""
        self._alive_members: tuple[int, frozenset[str]] = (-1, frozenset())

    # --- the join handshake -----------------------------------------------------------------
    def _join(self, link: Link, island: str, payload: bytes, reply: Callable[[bytes], None]) -> None:
        """A request gets a signed challenge; a proof that holds for a fresh challenge gets the run (:meth:`admit`),
        announced in the roster (:meth:`announce`) and then answered, signed; a proof that does not hold, or comes too
        late, is rejected unanswered."""
        step = decode_join_step(payload, self.name, sender=island)
        if isinstance(step, JoinRequest):
            reply(encode_challenge(self.name, island, step.nonce, self._challenge(step, 0), self.run_id, self.signing))
            return
        request = step.request
        if request.member and not of_member(request.island, request.member):
            raise MessageRejected("sender", f"join of island {island!r} for member {request.member!r}: a member's islands bear its name")
        if not any(hmac.compare_digest(step.challenge, self._challenge(request, age)) for age in (0, 1)):
            raise MessageRejected("replay", f"join proof of {island!r} answers no challenge of the last {2 * CHALLENGE_S:g} s")
        if not proof_holds(step, self.keys.admission_for(request.member)):
            raise MessageRejected("forged", f"join proof of {island!r} does not hold: not a holder of the secret of {member_name(request.member)}")
        try:
            run = self.admit(request.island, request.algo, request.seed, request.key, request.nonce, request.member)
        except HysidInputError as exc:
            reply(encode_joined(self.name, request.nonce, island, "refused", self.run_id, self.signing, refused=exc.detail))
            return
        self.announce(link)
        reply(encode_joined(self.name, request.nonce, island, run, self.run_id, self.signing))

    def _challenge(self, request: JoinRequest, age: int) -> bytes:
        """The challenge for ``request`` in the window ``age`` windows of :data:`CHALLENGE_S` ago (kept by nobody: recomputed)."""
        window = int(time.monotonic() // CHALLENGE_S) - age
        return hmac.new(self._challenges, request.transcript(window.to_bytes(8, "big", signed=True)), hashlib.sha256).digest()[:16]

    def admit(self, island: str, algo: str, seed: int, key: bytes, nonce: bytes = b"", member: str = "") -> str:
        """Admit a new run of ``island`` for ``member`` that signs with public ``key``: its run id, stored (and
        committed) before the island hears of it. Refused (:class:`HysidInputError`) while the id has a live run,
        for an unknown algorithm, for an id that had :data:`RUNS_PER_ISLAND` runs, for a member that holds
        :data:`MEMBER_RUNS`, for a full campaign and once the campaign is stopping. The same request again
        (``nonce``: its answer was lost) gets the same run."""
        alive = self.members.get(island)
        if alive is not None and nonce and alive.nonce == nonce and self.runs[(island, alive.run)].key == key:
            return alive.run
        if not NAME_PATTERN.match(island):
            raise HysidInputError(f"island id {island[:64]!r} is not a valid name")
        if algo not in ALGORITHMS:
            raise HysidInputError(f"unknown algorithm {algo!r}; this campaign runs {', '.join(ALGORITHMS)}")
        if self.stop_reason is not None:
            raise HysidInputError(f"the campaign is stopping ({self.stop_reason})")
        if alive is not None and alive.status == "alive":
            raise HysidInputError(f"island id {island!r} is taken by a running island; give another --id")
        if sum(i == island for i, _ in self.runs) >= RUNS_PER_ISLAND:
            raise HysidInputError(f"island id {island!r} has joined {RUNS_PER_ISLAND} times, its limit; give another --id")
        if self.member_runs[member] >= MEMBER_RUNS:
            raise HysidInputError(f"{member_name(member)} holds {self.member_runs[member]:,} runs, its share of the campaign's {MAX_MEMBERS:,}")
        if len(self.runs) >= MAX_MEMBERS:
            raise HysidInputError(f"the campaign has admitted {MAX_MEMBERS} island runs, its limit")
        run = secrets.token_hex(6)
        joined = time.time()
        self.store.add_run(self.name, island, run, key, algo, seed, joined, member)
        self.runs[(island, run)] = RunInfo(key, algo, seed, joined, member)
        self.member_runs[member] += 1
        self.sharing.joined((island, run), algo)
        self.current[island] = run
        self.membership.joined(island, run, nonce)
        self.checks.expect(self.config.algos)  # measured meanwhile: before the run's first history comes
        self.review_following()
        self.store.commit()
        return run

    def join(self, island: str, algo: str, seed: int, member: str = "") -> Credentials:
        """A run of an island of this process (benches, tests) admitted for ``member`` with a signing key made here."""
        key = new_key()
        return Credentials(island, self.admit(island, algo, seed, public_key(key), member=member), key, self.secret.coordinator)

    # --- the roster ---------------------------------------------------------------------
    def control_message(self, stop: str = "") -> bytes:
        """The signed roster (every run that joined, in that order, alive or not, how far its rows are
        committed, its algorithm, public key and last message number accepted) and the stop order."""
        members = tuple(
            MemberState(
                island,
                run,
                self.membership.alive(island, run),
                self.gaps.stored((island, run)),
                self.sharing.assigned[(island, run)],
                info.key,
                self.last_seq(island, run),
            )
            for (island, run), info in self.runs.items()
        )
        self.control_seq = max(self.control_seq + 1, time.time_ns() // 1000)  # rises across coordinator restarts
        return encode_control(Control(self.name, members, stop, self.control_seq), self.run_id, self.signing)

    def announce(self, link: Link, stop: str | None = None) -> None:
        """Send the roster (and the stop order, if ``stop``) now."""
        link.publish_control(self.control_message(stop or ""), bool(stop))
        self.control_at, self.changed, self.announced_events = time.monotonic(), False, self.membership.events

    # --- each member's effort ------------------------------------------------------------------
    def count_effort(self, key: tuple[str, str], evaluations: int) -> None:
        """Run ``key`` reports ``evaluations`` so far: what it adds counts for its member (:meth:`countable`)."""
        added = evaluations - self.run_evaluations.get(key, 0)
        if added <= 0:
            return
        self.run_evaluations[key] = evaluations
        self.evaluations += added
        if len(self.members_alive()) > 1:
            self.shared_effort[self.runs[key].member] += added
        else:
            self.solo_effort += added

    def members_alive(self) -> frozenset[str]:
        """The members with a run alive (recounted when membership changed)."""
        events, alive = self._alive_members
        if events != self.membership.events:
            alive = frozenset(self.runs[(island, m.run)].member for island, m in self.members.items() if m.status == "alive")
            self._alive_members = (self.membership.events, alive)
        return alive

    def countable(self) -> int:
        """The evaluations that count toward the budget and the stall rule: all of those made while at most one member
        was alive; of those made while more were, each member's no further than the other members' of that time
        together (a member cannot spend the campaign's budget alone)."""
        shared = sum(self.shared_effort.values())
        return self.solo_effort + sum(min(e, shared - e) for e in self.shared_effort.values())
