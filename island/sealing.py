"""Sealed messages: who may send them, tagged and numbered.

An island that joins gets its :class:`Credentials`: a run id, a per-run key,
and the campaign key that every joined island shares. The ``migrants``,
``history`` and ``control`` messages of :mod:`island.protocol` are *sealed*
(:func:`seal`, :func:`unseal`): the fields travel as a msgpack ``body`` inside
an envelope naming the sender, its run and a message number ``seq``
(:class:`Counter`), with HMAC-SHA256 tags over all of it. An island tags with
its run key (checked by the coordinator) and, for migrants, the campaign key
(checked by other islands); the coordinator tags a control message once per
joined island with that island's run key. A message from a sender that did not
join, with a wrong tag, or whose number was seen before (a replay, see
:class:`ReplayGuard`) is rejected with a :class:`island.wire.MessageRejected`.
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any, Callable

from island.wire import MAX_MEMBERS, PROTOCOL_VERSION, MessageRejected, _dumps, _get, _int, _loads, _name, _unpack, check_name

KEY_BYTES = 32


@dataclass(frozen=True)
class Credentials:
    """What an island gets when it joins: its run id and run key, and the campaign key that every
    joined island shares (migrants are tagged with it so that other islands can check them)."""

    island: str
    run: str
    key: bytes
    campaign_key: bytes

    @classmethod
    def issue(cls, island: str, campaign_key: bytes) -> "Credentials":
        """New credentials for a run of ``island`` (a fresh run id and key)."""
        return cls(check_name("island", island), secrets.token_hex(6), secrets.token_bytes(KEY_BYTES), campaign_key)


@dataclass(frozen=True)
class Sealed:
    """An opened sealed message: who sent it, in which run, its number and its fields."""

    sender: str
    run: str
    seq: int
    fields: dict[str, Any]


def _tag(key: bytes, msg_type: str, campaign: str, sender: str, run: str, seq: int, body: bytes) -> bytes:
    header = _dumps([PROTOCOL_VERSION, msg_type, campaign, sender, run, seq])
    return hmac.new(key, header + body, hashlib.sha256).digest()


def seal(msg_type: str, campaign: str, sender: str, run: str, seq: int, fields: dict[str, Any], keys: dict[str, bytes]) -> bytes:
    """A sealed message: ``fields`` as the body, tagged with each of ``keys`` (tag name -> key)."""
    body = _dumps(fields)
    tags = {name: _tag(key, msg_type, campaign, sender, run, seq, body) for name, key in keys.items()}
    return _dumps({"v": PROTOCOL_VERSION, "type": msg_type, "campaign": campaign, "sender": sender, "run": run, "seq": seq, "body": body, "tags": tags})


KeyLookup = Callable[[str, str], "bytes | None"]
"""``key_for(sender, run)``: the key to check a sender's tag with, None if that run never joined."""


def unseal(data: bytes, msg_type: str, campaign: str, *, tag: str, key_for: KeyLookup, sender: str | None = None) -> Sealed:
    """Open a sealed message: envelope, sender (``sender`` is the one the Zenoh key names), its key,
    the tag named ``tag``, then the body. Nothing of the body is read before the tag matches."""
    env = _unpack(data, msg_type, campaign)
    source = _name(env, "sender")
    if sender is not None and source != sender:
        raise MessageRejected("sender", f"message from the key of {sender!r} claims sender {source!r}")
    run = _name(env, "run")
    seq = _int(env, "seq")
    body = _get(env, "body", bytes)
    tags = _get(env, "tags", dict)
    key = key_for(source, run)
    if key is None:
        raise MessageRejected("unjoined", f"{source!r} run {run!r} did not join the campaign")
    got = tags.get(tag)
    if not isinstance(got, bytes) or not hmac.compare_digest(got, _tag(key, msg_type, campaign, source, run, seq, body)):
        raise MessageRejected("forged", f"{msg_type} message of {source!r} run {run!r} has no valid tag")
    fields = _loads(body, f"{msg_type} body")
    if not isinstance(fields, dict):
        raise MessageRejected("schema", f"{msg_type} body is {type(fields).__name__}, not a map")
    return Sealed(source, run, seq, fields)


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


class ReplayGuard:
    """Drops replays: remembers, per sender run, which of the last ``window`` message numbers it saw
    (a bit mask: a few hundred bytes per run).

    A number seen before, or older than the window, is a replay. Messages may
    arrive out of order within the window (a history re-sent on request passes
    a newer publication). At most ``runs`` sender runs are tracked; the least
    recently heard one is forgotten first.
    """

    def __init__(self, window: int = 4096, runs: int = 2 * MAX_MEMBERS) -> None:
        self.window = window
        self.runs = runs
        self._seen: OrderedDict[tuple[str, ...], tuple[int, int]] = OrderedDict()
        """key -> (highest number, bit i set when number highest - i was seen)"""
        self._lock = threading.Lock()

    def fresh(self, key: tuple[str, ...], seq: int) -> bool:
        """True (and remembered) the first time ``seq`` comes from ``key``; False for a replay."""
        with self._lock:
            high, seen = self._seen.pop(key, (-1, 0))
            if seq > high:
                shift = seq - high
                seen = ((seen << shift) | 1) & ((1 << self.window) - 1) if shift < self.window else 1
                high, fresh = seq, True
            else:
                age = high - seq
                fresh = age < self.window and not (seen >> age) & 1
                if fresh:
                    seen |= 1 << age
            self._seen[key] = (high, seen)
            while len(self._seen) > self.runs:
                self._seen.popitem(last=False)
            return fresh


def check_replay(guard: ReplayGuard, kind: str, sender: str, run: str, seq: int) -> None:
    """:class:`MessageRejected` ("replay") unless message ``seq`` of ``kind`` is new from that sender run."""
    if not guard.fresh((kind, sender, run), seq):
        raise MessageRejected("replay", f"{kind} message {seq} of {sender!r} run {run!r} was seen before")
