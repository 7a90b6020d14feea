"""Messages of a campaign (msgpack), their strict validation and who may send them (protocol version 5).

The dissertation leaves cooperating islands as future work (section 6.1); here
they exchange these messages under ``hysid/<campaign>/`` (see
:mod:`island.node`). Each one is a msgpack map with the protocol version
``v``, its ``type`` and the ``campaign`` it belongs to:

* ``config``: the campaign configuration and the extracted loop set (with
  each loop's measured displacement harmonics, as real/imaginary pairs),
  served by the coordinator so that islands need no shared file system; it
  is served sealed (signed) by the coordinator, and stored unsealed;
* the *join handshake*, a challenge-response on ``join/<id>`` (two queries, :mod:`island.handshake`):
  ``join`` (the island's id, the member it joins for, its algorithm, seed, a
  fresh nonce and the public key its run will sign with) is answered by a
  signed ``challenge``; ``prove`` (the request again with the challenge, an
  HMAC over both with that member's admission secret, :mod:`island.secret`, and
  a signature with the run's key)
  is answered by a signed ``joined`` holding the run id, or the refusal. The
  secret never travels; an island takes answers only with the signature of the
  coordinator named in its secret, and the coordinator admits only islands
  whose proof holds;
* ``migrants``: an island's ``k`` best partial solutions with the fitness it
  *claims* for them and its clock's send time; receivers always re-evaluate
  (the claim only orders);
* ``history``: convergence rows ``[iteration, best fitness, evaluations, wall
  s]`` of one island, its current best and its migration counters;
* ``control``: the coordinator's roster (which island runs joined, in that order,
  which are alive, how many of each one's history rows it has committed, which
  algorithm each runs, the public key each signs with and the last message
  number the coordinator accepted of it) and its stop order;
* ``best``: the coordinator's global best (fitness re-evaluated by it);
* a *history query* (``history/<id>?run=R;since=N;seq=Q;sig=S``): the
  coordinator asking an island for rows it missed, signed, its ``seq`` rising.

Everything but ``join`` and ``prove`` is *sealed* (:mod:`island.sealing`:
sender, run, message number and an Ed25519 signature by the sender; replays
dropped once the signature verified). Every field is checked strictly as it
is decoded (:mod:`island.wire`), times and fitness values against the ranges
a campaign can produce; a bad message raises
:class:`island.wire.MessageRejected` naming why.

Version 4 (before): a join proved the one campaign secret (every holder was alike), an island's history counted
migrant messages that waited in vain for the roster among those it rejected, the roster held no message numbers.
Version 3: HMAC tags instead of signatures, a campaign key every
joined island shared (so a member could tag migrants as another), the run key
sent in the clear in an unauthenticated ``joined`` answer, ``config``,
``best`` and history queries unauthenticated. Messages of another version are
rejected (``version``).

This is the wire format only: with :mod:`island.wire` and :mod:`island.sealing`
it depends on msgpack, numpy, ``cryptography`` and the loop set,
not on models, objectives or optimizers (the campaign settings inside
``config`` are checked by :class:`island.config.CampaignConfig`).
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass
from typing import Any

import msgpack
import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.loops import LoopSet
from island.sealing import KEY_BYTES, SIGNATURE_BYTES, Credentials, KeyLookup, Sealed, seal, sign, unseal, verify
from island.wire import (
    EPOCH_2020,
    INT64_MAX,
    MAX_BYTES,
    MAX_COUNT,
    MAX_FITNESS,
    MAX_MEMBERS,
    MAX_TEXT,
    NAME_PATTERN,
    PROTOCOL_VERSION,
    MessageRejected,
    _array,
    _bytes,
    _dumps,
    _finite,
    _get,
    _in_bounds,
    _int,
    _name,
    _number,
    _plain,
    _text,
    _unpack,
    pack_array,
)

ALGO_PATTERN = re.compile(r"[a-z][a-z0-9_]{0,15}\Z")
QUERY_NUMBER = re.compile(r"-?[0-9]{1,16}\Z")
"""An island's algorithm label (``ga``, ``pso``) as it travels in its history."""
COORDINATOR = "coordinator"
"""The sender name of the coordinator's sealed messages."""
MAX_MIGRANTS = 256
MAX_ROWS = 100_000
MAX_DIM = 256
NONCE_BYTES = 16
MAX_CLOCK_SKEW_S = 86400.0
"""How far a migrant's send time may be from the receiver's clock (machines' clocks differ, not by a day)."""
MAX_GAIN = 1e6
"""Most orders of magnitude an island's own moves can have gained (a float64 best spans about 630 per
fall from its largest to its smallest value; a campaign of a million falls is beyond any budget)."""


def _algo(msg: dict[str, Any], key: str) -> str:
    value = _get(msg, key, str)
    if not ALGO_PATTERN.match(value):
        raise MessageRejected("schema", f"field {key!r} is not an algorithm label (a short lower-case name)")
    return value


# --- campaign configuration ---------------------------------------------------------
def _packable(value: Any) -> bool:
    try:
        _plain(value)
        msgpack.packb(value, use_bin_type=True)
    except (TypeError, ValueError, OverflowError, MessageRejected):
        return False
    return True


def encode_config(campaign: str, config: dict[str, Any], loops: LoopSet) -> bytes:
    """The ``config`` message: the campaign's settings (plain data) and its loop set."""
    wire_loops = {
        "name": loops.name,
        "freq_hz": pack_array(loops.freq_hz),
        "x0": pack_array(loops.x0),
        "top": pack_array(loops.top),
        "bottom": pack_array(loops.bottom),
        "sigma": pack_array(loops.sigma),
        "meq_kg": None if loops.meq_kg is None else float(loops.meq_kg),
        "cycles": [int(c) for c in loops.cycles],
        "labels": list(loops.labels),
        "meta": {k: v for k, v in loops.meta.items() if _packable(v)},
        "x_harmonics": None if loops.x_harmonics is None else pack_array(np.stack([loops.x_harmonics.real, loops.x_harmonics.imag], axis=-1)),
    }
    return _dumps({"v": PROTOCOL_VERSION, "type": "config", "campaign": campaign, "config": config, "loops": wire_loops})


def encode_signed_config(message: bytes, campaign: str, run: str, key: bytes) -> bytes:
    """The ``config`` message as the coordinator serves it: sealed (signed) by its ``key``."""
    return seal("config", campaign, COORDINATOR, run, 0, {"message": message}, key)


def decode_signed_config(data: bytes, campaign: str, coordinator: bytes) -> bytes:
    """The ``config`` message inside a sealed one, if the coordinator of public key ``coordinator`` signed it."""
    s = unseal(data, "config", campaign, key_for=lambda sender, run: coordinator, sender=COORDINATOR)
    return _get(s.fields, "message", bytes)


def decode_config(data: bytes, campaign: str) -> tuple[dict[str, Any], LoopSet]:
    """The campaign settings (a map, checked by :class:`island.config.CampaignConfig`) and the loop
    set, which is checked like a loaded file."""
    msg = _unpack(data, "config", campaign)
    wire = _get(msg, "loops", dict)
    config = _get(msg, "config", dict)
    _plain(config)
    n_max = MAX_BYTES["config"] // 8
    meq = _get(wire, "meq_kg", (int, float, type(None)))
    cycles = _get(wire, "cycles", list)
    labels = _get(wire, "labels", list)
    if not all(isinstance(c, int) and not isinstance(c, bool) and 0 <= c <= INT64_MAX for c in cycles):
        raise MessageRejected("schema", "loop cycles must be non-negative 64-bit integers")
    if not all(isinstance(s, str) and len(s) <= MAX_TEXT for s in labels):
        raise MessageRejected("schema", f"loop labels must be strings of at most {MAX_TEXT} characters")
    meta = _get(wire, "meta", dict)
    _plain(meta)
    try:
        xh = None
        if wire.get("x_harmonics") is not None:  # optional: absent or None is the ideal sine
            pair = _array(wire, "x_harmonics", (None, None, 2), n_max)
            xh = pair[..., 0] + 1j * pair[..., 1]
        loops = LoopSet(
            name=_text(wire, "name"),
            freq_hz=_array(wire, "freq_hz", (None,), n_max),
            x0=_array(wire, "x0", (None,), n_max),
            top=_array(wire, "top", (None, None, 2), n_max),
            bottom=_array(wire, "bottom", (None, None, 2), n_max),
            sigma=_array(wire, "sigma", (None,), n_max),
            meq_kg=None if meq is None else _number(wire, "meq_kg"),
            cycles=np.array(cycles, dtype=np.int64),
            labels=list(labels),
            meta=meta,
            x_harmonics=xh,
        )
    except MessageRejected:
        raise
    except (HysidInputError, TypeError, ValueError, OverflowError) as exc:
        raise MessageRejected("schema", f"loop set invalid: {exc}") from None
    return config, loops


# --- migrants ---------------------------------------------------------------
@dataclass(frozen=True)
class Migrants:
    """``k`` candidate vectors ``x (k, D)`` of one island and the fitness it claims for them."""

    campaign: str
    island: str
    run: str
    iteration: int
    x: np.ndarray
    claimed: np.ndarray
    sent_at: float
    seq: int = 0


def encode_migrants(m: Migrants, credentials: Credentials) -> bytes:
    """Signed with the island run's key: the coordinator and every island check it with its public half."""
    fields = {"iteration": int(m.iteration), "x": pack_array(m.x), "claimed": pack_array(m.claimed), "sent_at": float(m.sent_at)}
    return seal("migrants", m.campaign, m.island, m.run, m.seq, fields, credentials.key)


def decode_migrants(data: bytes, campaign: str, bounds: np.ndarray, *, key_for: KeyLookup, sender: str | None = None, now: float | None = None) -> Migrants:
    """Validate a migrant message against the campaign's ``(D, 2)`` bounds.

    ``sender`` is the island named by the Zenoh key the message came on; the
    message must name the same island and verify under the public key
    ``key_for`` knows for its run. ``now`` (the receiver's ``time.time()``):
    a send time further than :data:`MAX_CLOCK_SKEW_S` from it, or before
    2020, is ``out_of_range``.
    """
    return migrants_of(unseal(data, "migrants", campaign, key_for=key_for, sender=sender), campaign, bounds, now)


def migrants_of(s: Sealed, campaign: str, bounds: np.ndarray, now: float | None = None) -> Migrants:
    """The fields of an opened migrant message, checked."""
    msg = s.fields
    dim = bounds.shape[0]
    x = _array(msg, "x", (None, dim), MAX_MIGRANTS * dim)
    claimed = _array(msg, "claimed", (x.shape[0],), MAX_MIGRANTS)
    if x.shape[0] == 0:
        raise MessageRejected("shape", "no migrants in message")
    _in_bounds(x, bounds)
    _finite(claimed, "claimed fitness")
    if np.any(claimed < 0):
        raise MessageRejected("schema", "claimed fitness is negative")
    if np.any(claimed > MAX_FITNESS):
        raise MessageRejected("out_of_range", f"claimed fitness above {MAX_FITNESS:g}")
    sent_at = _number(msg, "sent_at")
    latest = (time.time() if now is None else now) + MAX_CLOCK_SKEW_S
    if not EPOCH_2020 <= sent_at <= latest:
        raise MessageRejected("out_of_range", f"sent at {sent_at:.6g} (Unix time): before 2020 or more than a day ahead of this clock")
    return Migrants(campaign, s.sender, s.run, _int(msg, "iteration", maximum=MAX_COUNT), x, claimed, sent_at, s.seq)


# --- history ----------------------------------------------------------------------
HISTORY_COLUMNS = ("iteration", "best_fitness", "evaluations", "wall_s")
STAT_NAMES = ("sent", "received", "taken", "rejected", "unlisted")
"""Island migration counters: migrant messages sent, migrants received from in-neighbours,
migrants taken in by the optimizer, messages rejected by validation, and migrant messages that waited in vain for
the roster to list their run (none in an honest campaign: the coordinator sends the roster at every join)."""


@dataclass(frozen=True)
class History:
    """Convergence rows ``(n, 4)`` of :data:`HISTORY_COLUMNS`, the island's best and its counters."""

    campaign: str
    island: str
    run: str
    algo: str
    seed: int
    rows: np.ndarray
    best_x: np.ndarray
    best_f: float
    stats: dict[str, int]
    final: bool = False
    seq: int = 0
    gain: float = 0.0
    """Orders of magnitude the island's own moves gained so far (:attr:`~island.population.PopulationOptimizer.gain`)."""


def encode_history(h: History, credentials: Credentials) -> bytes:
    """Signed with the island run's key (a counter ``h.stats`` lacks is sent as 0)."""
    fields = {
        "algo": h.algo,
        "seed": int(h.seed),
        "rows": pack_array(np.asarray(h.rows, dtype=float).reshape(-1, 4)),
        "best_x": pack_array(h.best_x),
        "best_f": float(h.best_f),
        "stats": {k: int(h.stats.get(k, 0)) for k in STAT_NAMES},
        "final": bool(h.final),
        "gain": float(h.gain),
    }
    return seal("history", h.campaign, h.island, h.run, h.seq, fields, credentials.key)


def decode_history(data: bytes, campaign: str, bounds: np.ndarray, *, key_for: KeyLookup, sender: str | None = None) -> History:
    """A history message checked for form: rows sorted by iteration, counts whole, non-negative and
    exact in float64, evaluations, wall times and best fitness monotone, fitness values finite and up
    to :data:`MAX_FITNESS` (``out_of_range`` otherwise; an infinite best only in a message without rows,
    sent before the island's first iteration). How many evaluations, iterations and seconds are
    plausible is the coordinator's check."""
    s = unseal(data, "history", campaign, key_for=key_for, sender=sender)
    msg = s.fields
    algo = _algo(msg, "algo")
    rows = _array(msg, "rows", (None, 4), 4 * MAX_ROWS)
    _finite(rows[:, [0, 2, 3]], "history iteration, evaluations or wall time")
    _finite(rows[:, 1], "history best fitness", allow_inf=True)
    counts = rows[:, [0, 2]]
    if np.any(rows < 0) or np.any(counts != np.round(counts)) or np.any(counts > MAX_COUNT):
        raise MessageRejected("schema", "history rows need whole iterations and evaluations up to 2**53 and non-negative values")
    if np.any(rows[:, 1] > MAX_FITNESS):
        raise MessageRejected("out_of_range", f"history best fitness above {MAX_FITNESS:g} (or infinite)")
    if np.any(np.diff(rows[:, 0]) <= 0) or np.any(np.diff(rows[:, 2]) < 0) or np.any(np.diff(rows[:, 1]) > 0) or np.any(np.diff(rows[:, 3]) < 0):
        raise MessageRejected(
            "implausible", "history rows must have rising iterations, evaluations and wall times that never fall and a best that never worsens"
        )
    best_x = _array(msg, "best_x", (bounds.shape[0],), MAX_DIM)
    _in_bounds(best_x[None, :], bounds)
    best_f = _number(msg, "best_f", allow_inf=True)
    if best_f < 0:
        raise MessageRejected("schema", "best fitness is negative")
    if best_f > MAX_FITNESS and (rows.size or best_f != np.inf):
        raise MessageRejected("out_of_range", f"best fitness above {MAX_FITNESS:g} (infinite only before the first iteration)")
    stats_msg = _get(msg, "stats", dict)
    stats = {k: _int(stats_msg, k) for k in STAT_NAMES}
    gain = _number(msg, "gain")
    if not 0 <= gain <= MAX_GAIN:
        raise MessageRejected("schema", f"gain {gain:g} is outside [0, {MAX_GAIN:g}] orders of magnitude")
    return History(campaign, s.sender, s.run, algo, _int(msg, "seed"), rows, best_x, best_f, stats, bool(_get(msg, "final", bool)), s.seq, gain)


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
