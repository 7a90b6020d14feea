"""Messages of a campaign (msgpack), their strict validation and who may send them.

The dissertation leaves cooperating islands as future work (section 6.1); here
they exchange these messages under ``hysid/<campaign>/`` (see
:mod:`island.node`). Each one is a msgpack map with the protocol version
``v``, its ``type`` and the ``campaign`` it belongs to:

* ``config``: the campaign configuration and the extracted loop set (with
  each loop's measured displacement harmonics, as real/imaginary pairs),
  served by the coordinator so that islands need no shared file system;
* ``join`` / ``joined``: an island asks the coordinator to join and gets its
  :class:`island.sealing.Credentials`: a run id, a per-run key, and the campaign key that
  every joined island shares (the *join handshake*);
* ``migrants``: an island's ``k`` best partial solutions with the fitness it
  *claims* for them; receivers always re-evaluate (the claim only orders);
* ``history``: convergence rows ``[iteration, best fitness, evaluations, wall
  s]`` of one island, its current best and its migration counters;
* ``control``: the coordinator's roster (which islands joined, which are
  alive, how many of each one's history rows it has committed) and its stop
  order;
* ``best``: the coordinator's global best (fitness re-evaluated by it).

``migrants``, ``history`` and ``control`` are *sealed* (:mod:`island.sealing`:
sender, run, message number and HMAC tags; replays dropped). Every field is
checked strictly as it is decoded (:mod:`island.wire`); a bad message raises
:class:`island.wire.MessageRejected` naming why.

This is the wire format only: with :mod:`island.wire` and :mod:`island.sealing`
it depends on msgpack, numpy and the loop set,
not on models, objectives or optimizers (the campaign settings inside
``config`` are checked by :class:`island.config.CampaignConfig`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import msgpack
import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.loops import LoopSet
from island.sealing import KEY_BYTES, Credentials, KeyLookup, seal, unseal
from island.wire import (
    INT64_MAX,
    MAX_BYTES,
    MAX_COUNT,
    MAX_MEMBERS,
    MAX_TEXT,
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
"""An island's algorithm label (``ga``, ``pso``) as it travels in its history."""
COORDINATOR = "coordinator"
"""The sender name of the coordinator's sealed messages."""
MAX_MIGRANTS = 256
MAX_ROWS = 100_000
MAX_DIM = 256
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


# --- the join handshake ----------------------------------------------------------------
@dataclass(frozen=True)
class JoinRequest:
    """An island asking to join: its id, algorithm and seed, and a fresh ``nonce`` the answer echoes."""

    campaign: str
    island: str
    algo: str
    seed: int
    nonce: bytes


def encode_join(r: JoinRequest) -> bytes:
    return _dumps({"v": PROTOCOL_VERSION, "type": "join", "campaign": r.campaign, "island": r.island, "algo": r.algo, "seed": int(r.seed), "nonce": r.nonce})


def decode_join(data: bytes, campaign: str, sender: str | None = None) -> JoinRequest:
    """``sender`` is the island named by the Zenoh key the request was sent to (``join/<id>``)."""
    msg = _unpack(data, "join", campaign)
    island = _name(msg, "island")
    if sender is not None and island != sender:
        raise MessageRejected("sender", f"join request on the key of {sender!r} names island {island!r}")
    return JoinRequest(campaign, island, _algo(msg, "algo"), _int(msg, "seed"), _bytes(msg, "nonce", 16))


def encode_joined(campaign: str, nonce: bytes, credentials: Credentials | None = None, refused: str = "") -> bytes:
    """The coordinator's answer to a join request: the credentials, or why it refuses."""
    body: dict[str, Any] = {"v": PROTOCOL_VERSION, "type": "joined", "campaign": campaign, "nonce": nonce, "refused": refused[:MAX_TEXT]}
    if credentials is not None:
        body.update(island=credentials.island, run=credentials.run, key=credentials.key, campaign_key=credentials.campaign_key)
    return _dumps(body)


def decode_joined(data: bytes, campaign: str, island: str, nonce: bytes) -> Credentials:
    """The credentials in the answer to our join request; a refusal is a :class:`HysidInputError`
    with the coordinator's reason."""
    msg = _unpack(data, "joined", campaign)
    if _bytes(msg, "nonce", 16) != nonce:
        raise MessageRejected("replay", "answer to another join request")
    refused = _text(msg, "refused")
    if refused:
        raise HysidInputError(f"the coordinator of campaign {campaign!r} refused island {island!r}: {refused}")
    if _name(msg, "island") != island:
        raise MessageRejected("sender", "credentials for another island")
    return Credentials(island, _name(msg, "run"), _bytes(msg, "key", KEY_BYTES), _bytes(msg, "campaign_key", KEY_BYTES))


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
    """Tagged for the coordinator (run key) and for the other islands (campaign key)."""
    fields = {"iteration": int(m.iteration), "x": pack_array(m.x), "claimed": pack_array(m.claimed), "sent_at": float(m.sent_at)}
    keys = {"run": credentials.key, "campaign": credentials.campaign_key}
    return seal("migrants", m.campaign, m.island, m.run, m.seq, fields, keys)


def decode_migrants(data: bytes, campaign: str, bounds: np.ndarray, *, tag: str, key_for: KeyLookup, sender: str | None = None) -> Migrants:
    """Validate a migrant message against the campaign's ``(D, 2)`` bounds.

    ``sender`` is the island named by the Zenoh key the message came on; the
    message must name the same island. The coordinator checks the ``run`` tag,
    islands the ``campaign`` tag.
    """
    s = unseal(data, "migrants", campaign, tag=tag, key_for=key_for, sender=sender)
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
    sent_at = _number(msg, "sent_at")
    return Migrants(campaign, s.sender, s.run, _int(msg, "iteration", maximum=MAX_COUNT), x, claimed, sent_at, s.seq)


# --- history ----------------------------------------------------------------------
HISTORY_COLUMNS = ("iteration", "best_fitness", "evaluations", "wall_s")
STAT_NAMES = ("sent", "received", "taken", "rejected")
"""Island migration counters: migrant messages sent, migrants received from in-neighbours,
migrants taken in by the optimizer, messages rejected by validation."""


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
    fields = {
        "algo": h.algo, "seed": int(h.seed), "rows": pack_array(np.asarray(h.rows, dtype=float).reshape(-1, 4)),
        "best_x": pack_array(h.best_x), "best_f": float(h.best_f), "stats": {k: int(h.stats[k]) for k in STAT_NAMES},
        "final": bool(h.final), "gain": float(h.gain),
    }
    return seal("history", h.campaign, h.island, h.run, h.seq, fields, {"run": credentials.key})


def decode_history(data: bytes, campaign: str, bounds: np.ndarray, *, key_for: KeyLookup, sender: str | None = None) -> History:
    """A history message checked for form: rows sorted by iteration, counts whole, non-negative and
    exact in float64, evaluations and best fitness monotone (how many evaluations are plausible
    is the coordinator's check)."""
    s = unseal(data, "history", campaign, tag="run", key_for=key_for, sender=sender)
    msg = s.fields
    algo = _algo(msg, "algo")
    rows = _array(msg, "rows", (None, 4), 4 * MAX_ROWS)
    _finite(rows[:, [0, 2, 3]], "history iteration, evaluations or wall time")
    _finite(rows[:, 1], "history best fitness", allow_inf=True)
    counts = rows[:, [0, 2]]
    if np.any(rows < 0) or np.any(counts != np.round(counts)) or np.any(counts > MAX_COUNT):
        raise MessageRejected("schema", "history rows need whole iterations and evaluations up to 2**53 and non-negative values")
    if np.any(np.diff(rows[:, 0]) <= 0) or np.any(np.diff(rows[:, 2]) < 0) or np.any(np.diff(rows[:, 1]) > 0):
        raise MessageRejected("implausible", "history rows must have rising iterations, evaluations that never fall and a best that never worsens")
    best_x = _array(msg, "best_x", (bounds.shape[0],), MAX_DIM)
    _in_bounds(best_x[None, :], bounds)
    best_f = _number(msg, "best_f", allow_inf=True)
    if best_f < 0:
        raise MessageRejected("schema", "best fitness is negative")
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
    which all of its history rows are committed to the database (-1: none), and the algorithm it
    is to run (a mixed campaign may move it to another one, :mod:`island.share`)."""

    island: str
    run: str
    alive: bool
    stored: int
    algo: str


@dataclass(frozen=True)
class Control:
    """The coordinator's roster and stop order (``stop`` = "" while the campaign goes on)."""

    campaign: str
    members: tuple[MemberState, ...]
    stop: str
    seq: int


def encode_control(c: Control, run: str, keys: dict[str, bytes]) -> bytes:
    """Tagged once per joined island (``keys``: island -> its run key) by the coordinator run ``run``."""
    fields = {"members": [[m.island, m.run, bool(m.alive), int(m.stored), m.algo] for m in c.members], "stop": c.stop[:MAX_TEXT]}
    return seal("control", c.campaign, COORDINATOR, run, c.seq, fields, keys)


def decode_control(data: bytes, campaign: str, credentials: Credentials) -> Control:
    """A control message, checked with our own run key."""
    s = unseal(data, "control", campaign, tag=credentials.island, key_for=lambda sender, run: credentials.key, sender=COORDINATOR)
    entries = _get(s.fields, "members", list)
    if len(entries) > MAX_MEMBERS:
        raise MessageRejected("oversized", f"roster of {len(entries)} runs exceeds {MAX_MEMBERS}")
    members = []
    for e in entries:
        if not (isinstance(e, list) and len(e) == 5):
            raise MessageRejected("schema", "roster entry is not [island, run, alive, stored, algo]")
        entry = dict(zip(("island", "run", "alive", "stored", "algo"), e))
        members.append(MemberState(
            _name(entry, "island"), _name(entry, "run"), _get(entry, "alive", bool), _int(entry, "stored", -1, MAX_COUNT), _algo(entry, "algo"),
        ))
    return Control(campaign, tuple(members), _text(s.fields, "stop"), s.seq)


# --- best ------------------------------------------------------------------
@dataclass(frozen=True)
class Best:
    """The global best: ``fitness`` as re-evaluated by the coordinator, found by ``island``."""

    campaign: str
    island: str
    x: np.ndarray
    fitness: float


def encode_best(b: Best) -> bytes:
    return _dumps({"v": PROTOCOL_VERSION, "type": "best", "campaign": b.campaign, "island": b.island, "x": pack_array(b.x), "fitness": float(b.fitness)})


def decode_best(data: bytes, campaign: str, bounds: np.ndarray) -> Best:
    """Not sealed: an island re-evaluates the candidate before it takes it in."""
    msg = _unpack(data, "best", campaign)
    x = _array(msg, "x", (bounds.shape[0],), MAX_DIM)
    _in_bounds(x[None, :], bounds)
    fitness = _number(msg, "fitness")
    if fitness < 0:
        raise MessageRejected("not_finite", "best fitness is not a finite non-negative number")
    return Best(campaign, _name(msg, "island"), x, fitness)
