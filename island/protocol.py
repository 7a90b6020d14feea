"""Messages of a campaign (msgpack), their strict validation and who may send them.

The dissertation leaves cooperating islands as future work (section 6.1); here
they exchange these messages under ``hysid/<campaign>/`` (see
:mod:`island.node`). Each one is a msgpack map with the protocol version
``v``, its ``type`` and the ``campaign`` it belongs to:

* ``config``: the campaign configuration and the extracted loop set (with
  each loop's measured displacement harmonics, as real/imaginary pairs),
  served by the coordinator so that islands need no shared file system;
* ``join`` / ``joined``: an island asks the coordinator to join and gets its
  :class:`Credentials`: a run id, a per-run key, and the campaign key that
  every joined island shares (the *join handshake*);
* ``migrants``: an island's ``k`` best partial solutions with the fitness it
  *claims* for them; receivers always re-evaluate (the claim only orders);
* ``history``: convergence rows ``[iteration, best fitness, evaluations, wall
  s]`` of one island, its current best and its migration counters;
* ``control``: the coordinator's roster (which islands joined, which are
  alive, how many of each one's history rows it has committed) and its stop
  order;
* ``best``: the coordinator's global best (fitness re-evaluated by it).

``migrants``, ``history`` and ``control`` are *sealed*: the fields travel as a
msgpack ``body`` inside an envelope naming the sender, its run and a message
number ``seq``, with HMAC-SHA256 tags over all of it. An island tags with its
run key (checked by the coordinator) and, for migrants, the campaign key
(checked by other islands); the coordinator tags a control message once per
joined island with that island's run key. A message from a sender that did not
join, with a wrong tag, or whose number was seen before (a replay, see
:class:`ReplayGuard`) is rejected.

Float arrays travel as ``{"shape": [...], "data": <little-endian float64
bytes>}``. Decoding never trusts a sender: size limits are checked before
unpacking, then every field's type, integer range (SQLite's 64 bits, and 2**53
for counts carried as floats), string length, every shape (sizes computed
without overflow) against the campaign's dimension, finiteness and the search
bounds. A bad message raises :class:`MessageRejected` whose ``reason`` is one
of :data:`REASONS`.

This is the wire format only: it depends on msgpack, numpy and the loop set,
not on models, objectives or optimizers (the campaign settings inside
``config`` are checked by :class:`island.config.CampaignConfig`).
"""

from __future__ import annotations

import hashlib
import hmac
import math
import re
import secrets
import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any, Callable

import msgpack
import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.loops import LoopSet

PROTOCOL_VERSION = 3
MAX_GAIN = 1e6
"""Most orders of magnitude an island's own moves can have gained (a float64 best spans about 630 per
fall from its largest to its smallest value; a campaign of a million falls is beyond any budget)."""
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}\Z")
"""Campaign, island and run names: usable as one Zenoh key chunk (no ``/ * $ ? #``)."""
ALGO_PATTERN = re.compile(r"[a-z][a-z0-9_]{0,15}\Z")
"""An island's algorithm label (``ga``, ``pso``) as it travels in its history."""
COORDINATOR = "coordinator"
"""The sender name of the coordinator's sealed messages."""

MAX_BYTES = {
    "config": 256 << 20,
    "join": 4 << 10,
    "joined": 4 << 10,
    "migrants": 256 << 10,
    "history": 4 << 20,
    "control": 1 << 20,
    "best": 64 << 10,
}
"""Largest accepted encoded size of each message type, in bytes."""
MAX_MIGRANTS = 256
MAX_ROWS = 100_000
MAX_DIM = 256
MAX_MEMBERS = 4096
"""Island runs a campaign admits (and a control message lists)."""
MAX_TEXT = 200
"""Longest free text (a stop reason, a refusal) taken from a message."""
INT64_MAX = 2**63 - 1
"""Largest integer SQLite stores."""
MAX_COUNT = 2**53
"""Largest count (iterations, evaluations) carried exactly in a float64 array."""
KEY_BYTES = 32
REASONS = (
    "oversized", "undecodable", "schema", "version", "campaign", "sender", "unjoined", "forged", "replay",
    "shape", "not_finite", "out_of_bounds", "implausible", "overflow",
)
"""Why a message is rejected. ``sender``: the key it came on names another island; ``unjoined``: its
sender or run never joined; ``forged``: its tag does not match; ``replay``: its number was seen;
``implausible``: well-formed but impossible (e.g. more evaluations than the island could have done);
``overflow``: dropped because the receiver's queue for that sender was full."""


class MessageRejected(HysidInputError):
    """A message that failed validation; ``reason`` is one of :data:`REASONS`."""

    def __init__(self, reason: str, detail: str) -> None:
        self.reason = reason
        super().__init__(f"rejected message ({reason}): {detail}")


def check_name(param: str, value: Any) -> str:
    """A campaign or island name usable as a Zenoh key chunk, else :class:`HysidInputError` naming ``param``."""
    if not isinstance(value, str) or not NAME_PATTERN.match(value):
        raise HysidInputError("must be 1-64 characters of letters, digits, '_', '.', '-' (starting with a letter or digit)", param=param, value=value)
    return value


# --- low-level packing and field checks --------------------------------------------
def pack_array(a: np.ndarray) -> dict[str, Any]:
    a = np.ascontiguousarray(a, dtype="<f8")
    return {"shape": list(a.shape), "data": a.tobytes()}


def _dumps(obj: Any) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


def _loads(data: bytes, what: str) -> Any:
    try:
        return msgpack.unpackb(bytes(data), raw=False, strict_map_key=True)
    except Exception as exc:  # msgpack raises ValueError subclasses, StackError, UnicodeDecodeError...
        raise MessageRejected("undecodable", f"{what} is not msgpack ({type(exc).__name__})") from None


def _unpack(data: bytes, msg_type: str, campaign: str) -> dict[str, Any]:
    """Size check, msgpack decoding and the common envelope."""
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise MessageRejected("schema", f"payload is {type(data).__name__}, not bytes")
    if len(data) > MAX_BYTES[msg_type]:
        raise MessageRejected("oversized", f"{msg_type} message of {len(data)} bytes exceeds {MAX_BYTES[msg_type]}")
    msg = _loads(data, f"{msg_type} message")
    if not isinstance(msg, dict):
        raise MessageRejected("schema", f"top level is {type(msg).__name__}, not a map")
    if msg.get("v") != PROTOCOL_VERSION or isinstance(msg.get("v"), bool):
        raise MessageRejected("version", f"protocol version {_show(msg.get('v'))}, expected {PROTOCOL_VERSION}")
    if msg.get("type") != msg_type:
        raise MessageRejected("schema", f"type {_show(msg.get('type'))}, expected {msg_type!r}")
    if msg.get("campaign") != campaign:
        raise MessageRejected("campaign", f"campaign {_show(msg.get('campaign'))}, expected {campaign!r}")
    return msg


def _show(value: Any) -> str:
    """A received value for an error message: its type, or a short repr of a short plain value."""
    if isinstance(value, (bool, int, float)) or (isinstance(value, str) and len(value) <= 64):
        return repr(value)[:80]
    return f"<{type(value).__name__}>"


def _get(msg: dict[str, Any], key: str, types: type | tuple[type, ...]) -> Any:
    if key not in msg:
        raise MessageRejected("schema", f"field {key!r} missing")
    value = msg[key]
    if isinstance(value, bool) and bool not in (types if isinstance(types, tuple) else (types,)):
        raise MessageRejected("schema", f"field {key!r} is a bool")
    if not isinstance(value, types):
        raise MessageRejected("schema", f"field {key!r} is {type(value).__name__}")
    return value


def _int(msg: dict[str, Any], key: str, minimum: int = 0, maximum: int = INT64_MAX) -> int:
    value = _get(msg, key, int)
    if not minimum <= value <= maximum:
        raise MessageRejected("schema", f"field {key!r} = {_show(value)} is outside [{minimum}, {maximum}]")
    return value


def _number(msg: dict[str, Any], key: str, allow_inf: bool = False) -> float:
    """A float (or an integer that is exactly one) that is not NaN, and finite unless ``allow_inf``."""
    value = _get(msg, key, (int, float))
    if isinstance(value, int) and abs(value) > MAX_COUNT:
        raise MessageRejected("schema", f"field {key!r} is an integer too large for a float")
    value = float(value)
    if math.isnan(value) or (math.isinf(value) and not allow_inf):
        raise MessageRejected("not_finite", f"field {key!r} is {value}")
    return value


def _name(msg: dict[str, Any], key: str) -> str:
    value = _get(msg, key, str)
    if not NAME_PATTERN.match(value):
        raise MessageRejected("schema", f"field {key!r} is not a valid name")
    return value


def _algo(msg: dict[str, Any], key: str) -> str:
    value = _get(msg, key, str)
    if not ALGO_PATTERN.match(value):
        raise MessageRejected("schema", f"field {key!r} is not an algorithm label (a short lower-case name)")
    return value


def _text(msg: dict[str, Any], key: str) -> str:
    value = _get(msg, key, str)
    if len(value) > MAX_TEXT:
        raise MessageRejected("schema", f"field {key!r} is longer than {MAX_TEXT} characters")
    return value


def _bytes(msg: dict[str, Any], key: str, size: int) -> bytes:
    value = _get(msg, key, bytes)
    if len(value) != size:
        raise MessageRejected("schema", f"field {key!r} has {len(value)} bytes, not {size}")
    return value


def _array(msg: dict[str, Any], key: str, shape: tuple[int | None, ...], max_size: int) -> np.ndarray:
    """A float64 array whose shape matches ``shape`` (None = any length, ``max_size`` values in all)."""
    obj = _get(msg, key, dict)
    if set(obj) != {"shape", "data"} or not isinstance(obj["shape"], list) or not isinstance(obj["data"], bytes):
        raise MessageRejected("schema", f"field {key!r} is not an array {{shape, data}}")
    dims = obj["shape"]
    if len(dims) != len(shape) or not all(isinstance(d, int) and not isinstance(d, bool) and 0 <= d <= max_size for d in dims):
        raise MessageRejected("shape", f"field {key!r} has shape {_show_shape(dims)}, expected {len(shape)} dimensions of at most {max_size}")
    if any(want is not None and got != want for got, want in zip(dims, shape)):
        raise MessageRejected("shape", f"field {key!r} has shape {dims}, expected {list(shape)}")
    size = math.prod(dims)  # Python integers: no wrap-around however large the dimensions
    if size > max_size:
        raise MessageRejected("oversized", f"field {key!r} holds {size} values, more than {max_size}")
    if len(obj["data"]) != 8 * size:
        raise MessageRejected("shape", f"field {key!r} has {len(obj['data'])} bytes for shape {dims}")
    return np.frombuffer(obj["data"], dtype="<f8").astype(float).reshape(dims)


def _show_shape(dims: list[Any]) -> str:
    return repr(dims)[:80] if len(dims) <= 8 else f"<{len(dims)} dimensions>"


def _finite(values: np.ndarray, what: str, allow_inf: bool = False) -> None:
    bad = np.isnan(values) if allow_inf else ~np.isfinite(values)
    if np.any(bad):
        raise MessageRejected("not_finite", f"{what} holds NaN" + ("" if allow_inf else " or inf"))


def _in_bounds(x: np.ndarray, bounds: np.ndarray) -> None:
    _finite(x, "candidate vector")
    outside = (x < bounds[:, 0]) | (x > bounds[:, 1])
    if np.any(outside):
        dim = int(np.flatnonzero(np.any(outside.reshape(-1, bounds.shape[0]), axis=0))[0])
        raise MessageRejected("out_of_bounds", f"candidate outside the search bounds in parameter {dim}")


def _plain(value: Any, depth: int = 0, budget: list[int] | None = None) -> None:
    """A plain-data tree (maps with string keys, lists, short strings, numbers) no deeper than 16 and
    of at most 100,000 nodes; raises :class:`MessageRejected` otherwise."""
    budget = budget if budget is not None else [100_000]
    budget[0] -= 1
    if budget[0] < 0 or depth > 16:
        raise MessageRejected("schema", "metadata nested too deep or too large")
    if isinstance(value, dict):
        for k, v in value.items():
            if not isinstance(k, str) or len(k) > MAX_TEXT:
                raise MessageRejected("schema", "metadata key is not a short string")
            _plain(v, depth + 1, budget)
    elif isinstance(value, list):
        for v in value:
            _plain(v, depth + 1, budget)
    elif isinstance(value, str):
        if len(value) > 10_000:
            raise MessageRejected("schema", "metadata string longer than 10,000 characters")
    elif isinstance(value, float):
        if not math.isfinite(value):
            raise MessageRejected("not_finite", "metadata holds NaN or inf")
    elif isinstance(value, int) and not isinstance(value, bool):
        if abs(value) > INT64_MAX:
            raise MessageRejected("schema", "metadata integer outside 64 bits")
    elif not (value is None or isinstance(value, bool)):
        raise MessageRejected("schema", f"metadata holds a {type(value).__name__}")


# --- sealed messages: sender, run, number, tags -------------------------------------------
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
