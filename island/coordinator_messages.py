"""The coordinator's messages (protocol version 5, :mod:`island.protocol`): ``control`` (the roster of the runs
that joined, in that order, each alive or not, its committed rows, algorithm, public key and last accepted message
number; and the stop order), ``best`` (the global best, re-evaluated by the coordinator) and the history query
(``history/<id>?run=R;since=N;seq=Q;sig=S``: rows an island is asked for again, its ``seq`` rising). Each is
signed with the coordinator's key (:mod:`island.sealing`); islands take them only under its public key.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from island.protocol import COORDINATOR, MAX_DIM, _algo
from island.sealing import KEY_BYTES, SIGNATURE_BYTES, seal, sign, unseal, verify
from island.wire import (
    INT64_MAX,
    MAX_COUNT,
    MAX_MEMBERS,
    MAX_TEXT,
    NAME_PATTERN,
    PROTOCOL_VERSION,
    MessageRejected,
    _array,
    _bytes,
    _dumps,
    _get,
    _in_bounds,
    _int,
    _name,
    _number,
    _text,
    pack_array,
)

QUERY_NUMBER = re.compile(r"-?[0-9]{1,16}\Z")
"""A number in a history query's selector parameters."""


# --- control -------------------------------------------------------------------------
@dataclass(frozen=True)
class MemberState:
    """One joined island run as the coordinator sees it: alive or not, the last iteration up to
    which all of its history rows are committed to the database (-1: none), the algorithm it
    is to run (a mixed campaign may move it to another one, :mod:`island.share`), the public
    key its messages are signed with, and the last message number of it the coordinator accepted
    (-1: none; how far an island lets the run's first message it hears be ahead, :class:`island.sealing.ReplayGuard`)."""

    island: str
    run: str
    alive: bool
    stored: int
    algo: str
    key: bytes
    seq: int = -1


@dataclass(frozen=True)
class Control:
    """The coordinator's roster (in the order the runs joined) and stop order (``stop`` = "" while the campaign goes on)."""

    campaign: str
    members: tuple[MemberState, ...]
    stop: str
    seq: int


def encode_control(c: Control, run: str, key: bytes) -> bytes:
    """Signed by the coordinator run ``run`` with the coordinator's private ``key``."""
    fields = {"members": [[m.island, m.run, bool(m.alive), int(m.stored), m.algo, m.key, int(m.seq)] for m in c.members], "stop": c.stop[:MAX_TEXT]}
    return seal("control", c.campaign, COORDINATOR, run, c.seq, fields, key)


def decode_control(data: bytes, campaign: str, coordinator: bytes) -> Control:
    """A control message, checked with the coordinator's public key (from the campaign secret)."""
    s = unseal(data, "control", campaign, key_for=lambda sender, run: coordinator, sender=COORDINATOR)
    entries = _get(s.fields, "members", list)
    if len(entries) > MAX_MEMBERS:
        raise MessageRejected("oversized", f"roster of {len(entries)} runs exceeds {MAX_MEMBERS}")
    members = []
    for e in entries:
        if not (isinstance(e, list) and len(e) == 7):
            raise MessageRejected("schema", "roster entry is not [island, run, alive, stored, algo, key, seq]")
        entry = dict(zip(("island", "run", "alive", "stored", "algo", "key", "seq"), e))
        members.append(
            MemberState(
                _name(entry, "island"),
                _name(entry, "run"),
                _get(entry, "alive", bool),
                _int(entry, "stored", -1, MAX_COUNT),
                _algo(entry, "algo"),
                _bytes(entry, "key", KEY_BYTES),
                _int(entry, "seq", -1, INT64_MAX),
            )
        )
    return Control(campaign, tuple(members), _text(s.fields, "stop"), s.seq)


# --- best ------------------------------------------------------------------
@dataclass(frozen=True)
class Best:
    """The global best: ``fitness`` as re-evaluated by the coordinator, found by ``island``."""

    campaign: str
    island: str
    x: np.ndarray
    fitness: float


def encode_best(b: Best, run: str, key: bytes) -> bytes:
    """Signed by the coordinator (run ``run``, private ``key``)."""
    return seal("best", b.campaign, COORDINATOR, run, 0, {"island": b.island, "x": pack_array(b.x), "fitness": float(b.fitness)}, key)


def decode_best(data: bytes, campaign: str, bounds: np.ndarray, coordinator: bytes) -> Best:
    """Checked with the coordinator's public key; an island still re-evaluates the candidate before it takes it in."""
    s = unseal(data, "best", campaign, key_for=lambda sender, run: coordinator, sender=COORDINATOR)
    x = _array(s.fields, "x", (bounds.shape[0],), MAX_DIM)
    _in_bounds(x[None, :], bounds)
    fitness = _number(s.fields, "fitness")
    if fitness < 0:
        raise MessageRejected("not_finite", "best fitness is not a finite non-negative number")
    return Best(campaign, _name(s.fields, "island"), x, fitness)


# --- history queries ----------------------------------------------------------------
@dataclass(frozen=True)
class HistoryQuery:
    """The coordinator asking island ``island`` for the rows of its run ``run`` after iteration ``since``;
    ``seq`` rises with every query (across coordinator restarts), so that a captured query cannot be replayed."""

    campaign: str
    island: str
    run: str
    since: int
    seq: int


def _query_signed(q: HistoryQuery) -> bytes:
    return _dumps([PROTOCOL_VERSION, "history_query", q.campaign, q.island, q.run, q.since, q.seq])


def encode_history_query(q: HistoryQuery, key: bytes) -> str:
    """The selector parameters of a history query (``history/<id>?...``), signed by the coordinator."""
    return f"run={q.run};since={q.since};seq={q.seq};sig={sign(key, _query_signed(q)).hex()}"


def decode_history_query(params: Any, campaign: str, island: str, coordinator: bytes) -> HistoryQuery:
    """The query in selector parameters ``params`` (a mapping with ``get``) addressed to ``island``, if the
    coordinator of public key ``coordinator`` signed it; whether ``seq`` is new is the island's check."""

    def number(name: str, low: int) -> int:
        text = params.get(name)
        if not isinstance(text, str) or not QUERY_NUMBER.match(text) or not low <= int(text) <= MAX_COUNT:
            raise MessageRejected("schema", f"history query parameter {name!r} is not a number from {low} to 2**53")
        return int(text)

    run = params.get("run")
    if not isinstance(run, str) or not NAME_PATTERN.match(run):
        raise MessageRejected("schema", "history query names no valid run")
    q = HistoryQuery(campaign, island, run, number("since", -1), number("seq", 0))
    sig = params.get("sig")
    try:
        signature = bytes.fromhex(sig) if isinstance(sig, str) and len(sig) == 2 * SIGNATURE_BYTES else None
    except ValueError:
        signature = None
    if signature is None or not verify(coordinator, signature, _query_signed(q)):
        raise MessageRejected("forged", f"history query for {island!r} not signed by the coordinator")
    return q
