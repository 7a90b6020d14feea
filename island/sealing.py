"""Sealed messages: who sent them, signed and numbered; and the proof that an island holds the campaign secret.

Every party signs what it sends with a key of its own (Ed25519): the
coordinator with the key whose public half is in the campaign secret
(:class:`island.secret.CampaignSecret`), an island with the key of its run,
made by the island itself; its public half is registered when the island joins
(:mod:`island.protocol`'s join handshake, where the island also proves with
:func:`prove` that it holds the campaign's admission secret) and listed in the
coordinator's roster, so that everyone can check everyone and nobody can sign
as another. No key is shared.

A sealed message (:func:`seal`, :func:`unseal`) carries its fields as a
msgpack ``body`` inside an envelope naming the sender, its run and a message
number ``seq`` (:class:`Counter`), signed over all of it. A message from a
sender run nobody knows, with a signature that does not verify, or whose
number was seen before (a replay, see :class:`ReplayGuard`: checked only once
the signature verified, so that a forged number cannot move a sender's window)
is rejected with a :class:`island.wire.MessageRejected`.
"""

from __future__ import annotations

import functools
import hashlib
import hmac
import secrets
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from island.wire import MAX_MEMBERS, PROTOCOL_VERSION, MessageRejected, _dumps, _get, _int, _loads, _name, _unpack, check_name

KEY_BYTES = 32
"""Bytes of a private signing key (its seed), of a public key and of the admission secret."""
SIGNATURE_BYTES = 64


def new_key() -> bytes:
    """A fresh private signing key (Ed25519, its 32-byte seed)."""
    return secrets.token_bytes(KEY_BYTES)


@functools.lru_cache(maxsize=64)
def _private(key: bytes) -> Ed25519PrivateKey:
    return Ed25519PrivateKey.from_private_bytes(key)


@functools.lru_cache(maxsize=8192)
def _public(key: bytes) -> Ed25519PublicKey | None:
    try:
        return Ed25519PublicKey.from_public_bytes(key)
    except ValueError:
        return None


def public_key(key: bytes) -> bytes:
    """The public half of private key ``key``."""
    from cryptography.hazmat.primitives.serialization import Encoding, PublicFormat

    return _private(key).public_key().public_bytes(Encoding.Raw, PublicFormat.Raw)


def sign(key: bytes, data: bytes) -> bytes:
    return _private(key).sign(data)


def verify(public: bytes, signature: Any, data: bytes) -> bool:
    """Whether ``signature`` is ``data`` signed by the private half of ``public`` (False for anything malformed)."""
    if not isinstance(signature, bytes) or len(signature) != SIGNATURE_BYTES or not isinstance(public, bytes) or len(public) != KEY_BYTES:
        return False
    key = _public(public)
    if key is None:
        return False
    try:
        key.verify(signature, data)
    except InvalidSignature:
        return False
    return True


def prove(admission: bytes, transcript: bytes) -> bytes:
    """The proof that whoever sends ``transcript`` (which holds the coordinator's fresh challenge) holds the admission secret."""
    return hmac.new(admission, b"hysid admission\x00" + transcript, hashlib.sha256).digest()


def proven(admission: bytes, transcript: bytes, proof: bytes) -> bool:
    return hmac.compare_digest(prove(admission, transcript), proof)


@dataclass(frozen=True)
class Credentials:
    """An island run's identity in a campaign: its island id, the run id the coordinator issued, its own
    private signing key, and the coordinator's public key (from the campaign secret)."""

    island: str
    run: str
    key: bytes = field(repr=False)
    coordinator: bytes

    @property
    def public(self) -> bytes:
        return public_key(self.key)

    @classmethod
    def issue(cls, island: str, coordinator: bytes) -> Credentials:
        """Credentials of a new run of ``island`` with a fresh run id and key (in-process campaigns, tests)."""
        return cls(check_name("island", island), secrets.token_hex(6), new_key(), coordinator)


@dataclass(frozen=True)
class Sealed:
    """An opened sealed message: who sent it, in which run, its number and its fields."""

    sender: str
    run: str
    seq: int
    fields: dict[str, Any]


def _signed(msg_type: str, campaign: str, sender: str, run: str, seq: int, body: bytes) -> bytes:
    return _dumps([PROTOCOL_VERSION, msg_type, campaign, sender, run, seq]) + body


def seal(msg_type: str, campaign: str, sender: str, run: str, seq: int, fields: dict[str, Any], key: bytes) -> bytes:
    """A sealed message: ``fields`` as the body, signed with the private ``key`` of ``sender``'s run ``run``."""
    body = _dumps(fields)
    signature = sign(key, _signed(msg_type, campaign, sender, run, seq, body))
    return _dumps({"v": PROTOCOL_VERSION, "type": msg_type, "campaign": campaign, "sender": sender, "run": run, "seq": seq, "body": body, "sig": signature})


KeyLookup = Callable[[str, str], "bytes | None"]
"""``key_for(sender, run)``: the public key to check a sender run's signature with, None if nobody knows that run."""


@dataclass(frozen=True)
class Envelope:
    """A sealed message's envelope, read but not yet checked against its sender's key."""

    msg_type: str
    campaign: str
    sender: str
    run: str
    seq: int
    body: bytes
    signature: Any


def envelope(data: bytes, msg_type: str, campaign: str, sender: str | None = None) -> Envelope:
    """The envelope of a sealed message (``sender``: the one the Zenoh key names must be the one it claims)."""
    env = _unpack(data, msg_type, campaign)
    source = _name(env, "sender")
    if sender is not None and source != sender:
        raise MessageRejected("sender", f"message from the key of {sender!r} claims sender {source!r}")
    return Envelope(msg_type, campaign, source, _name(env, "run"), _int(env, "seq"), _get(env, "body", bytes), env.get("sig"))


def open_envelope(env: Envelope, key: bytes | None) -> Sealed:
    """The fields of a sealed message once its signature verifies under ``key`` (None: its sender run is unknown)."""
    if key is None:
        raise MessageRejected("unjoined", f"{env.sender!r} run {env.run!r} did not join the campaign")
    if not verify(key, env.signature, _signed(env.msg_type, env.campaign, env.sender, env.run, env.seq, env.body)):
        raise MessageRejected("forged", f"{env.msg_type} message of {env.sender!r} run {env.run!r} has no valid signature")
    fields = _loads(env.body, f"{env.msg_type} body")
    if not isinstance(fields, dict):
        raise MessageRejected("schema", f"{env.msg_type} body is {type(fields).__name__}, not a map")
    return Sealed(env.sender, env.run, env.seq, fields)


def unseal(data: bytes, msg_type: str, campaign: str, *, key_for: KeyLookup, sender: str | None = None) -> Sealed:
    """Open a sealed message: envelope, sender (``sender`` is the one the Zenoh key names), its key,
    the signature, then the body. Nothing of the body is read before the signature verifies."""
    env = envelope(data, msg_type, campaign, sender)
    return open_envelope(env, key_for(env.sender, env.run))


class Counter:
    """Message numbers of one sender run: 0, 1, 2, ... (thread-safe)."""

    def __init__(self, start: int = 0) -> None:
        self._next = start
        self._lock = threading.Lock()

    def __call__(self) -> int:
        with self._lock:
            n = self._next
            self._next += 1
            return n


MESSAGES_PER_S = 10_000.0
"""The most messages a second a run may number: far beyond what an island sends (its history every 0.02-0.75 s, a
migrant message every migration interval: a thousand a second at the fastest tiny problem), far below what takes one
message further than a replay window ahead of its sender."""
AHEAD_BURST = 2048
"""How far ahead of the last number accepted from a run a message may be at once (half a window: a run's next
messages stay inside it)."""
Known = tuple[int, float]
"""``(number, seconds ago)``: a message number a run had reached that long ago (what a receiver knows of a run it has
not heard from yet: the run just joined, ``(-1, since the join)``, or the coordinator's roster says so)."""


class ReplayGuard:
    """Drops replays, and numbers no run can have reached: remembers, per sender run, which of the last ``window``
    message numbers it saw (a bit mask: a few hundred bytes per run), and how far ahead its numbers may go.

    A number seen before, or older than the window, is a replay. Messages may
    arrive out of order within the window (a history re-sent on request passes
    a newer publication). A number may run ahead of the highest one accepted by
    at most ``burst``, and by ``rate`` a second more since (a token bucket): one
    message numbered 2**63-1, even validly signed with the run's own key, is
    refused (``ahead``) instead of moving the window beyond every later message
    of the run. At most ``runs`` sender runs are tracked; the least recently
    heard one is forgotten first. Only messages whose signature verified under
    their sender run's own key may be shown to it: a number is the sender's
    word, and nobody else's can move its window.
    """

    def __init__(self, window: int = 4096, runs: int = 2 * MAX_MEMBERS, rate: float = MESSAGES_PER_S, burst: int = AHEAD_BURST) -> None:
        self.window = window
        self.runs = runs
        self.rate = rate
        self.burst = burst
        self._seen: OrderedDict[tuple[str, ...], tuple[int, int, float, float]] = OrderedDict()
        """key -> (highest number, bit i set when number highest - i was seen, how far ahead a number may go, when that was)"""
        self._lock = threading.Lock()

    def check(self, key: tuple[str, ...], seq: int, known: Known | None = None, now: float | None = None) -> str:
        """``"fresh"`` (and remembered) the first time ``seq`` comes from ``key``, ``"replay"`` for a number seen
        before or older than the window, ``"ahead"`` for one further ahead than the run can have numbered (nothing is
        remembered of either). ``known``: what is known of a run not heard from yet (None: nothing; its first number
        is taken as it comes); ``now``: ``time.monotonic()``."""
        now = time.monotonic() if now is None else now
        with self._lock:
            entry = self._seen.get(key)
            if entry is None:
                if known is not None and seq - known[0] > self.burst + self.rate * max(known[1], 0.0):
                    return "ahead"
                high, seen, allowance = seq, 1, float(self.burst)
            else:
                high, seen, allowance, at = entry
                allowance = min(float(self.burst), allowance + self.rate * (now - at))
                if seq > high:
                    shift = seq - high
                    if shift > allowance:
                        return "ahead"
                    seen = ((seen << shift) | 1) & ((1 << self.window) - 1) if shift < self.window else 1
                    high, allowance = seq, allowance - shift
                else:
                    age = high - seq
                    if age >= self.window or (seen >> age) & 1:
                        return "replay"
                    seen |= 1 << age
            self._seen.pop(key, None)
            self._seen[key] = (high, seen, allowance, now)
            while len(self._seen) > self.runs:
                self._seen.popitem(last=False)
            return "fresh"

    def fresh(self, key: tuple[str, ...], seq: int) -> bool:
        """True (and remembered) the first time ``seq`` comes from ``key``; False for a replay or a number too far ahead."""
        return self.check(key, seq) == "fresh"

    def high(self, key: tuple[str, ...]) -> int:
        """The highest number accepted from ``key`` (-1: none)."""
        with self._lock:
            entry = self._seen.get(key)
            return -1 if entry is None else entry[0]


def check_replay(guard: ReplayGuard, kind: str, sender: str, run: str, seq: int, known: Known | None = None) -> None:
    """:class:`MessageRejected` unless message ``seq`` of ``kind`` is new from that sender run: ``replay`` for a number
    seen, ``ahead`` for one further ahead than the run can have numbered (``known``: :meth:`ReplayGuard.check`)."""
    verdict = guard.check((kind, sender, run), seq, known)
    if verdict == "replay":
        raise MessageRejected("replay", f"{kind} message {seq} of {sender!r} run {run!r} was seen before")
    if verdict == "ahead":
        raise MessageRejected("ahead", f"{kind} message {seq} of {sender!r} run {run!r} is further ahead of its last one than it can have sent since")
