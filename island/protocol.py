"""Messages of a campaign (msgpack) and their strict validation.

The dissertation leaves cooperating islands as future work (section 6.1); here
they exchange five kinds of message under ``hysid/<campaign>/`` (see
:mod:`island.node`). Each one is a msgpack map with the protocol version
``v``, its ``type`` and the ``campaign`` it belongs to:

* ``config``: the campaign configuration and the extracted loop set (with
  each loop's measured displacement harmonics, as real/imaginary pairs),
  served by the coordinator so that islands need no shared file system;
* ``migrants``: an island's ``k`` best partial solutions with the fitness it
  *claims* for them; receivers always re-evaluate (the claim only orders);
* ``history``: convergence rows ``[iteration, best fitness, evaluations, wall
  s]`` of one island, its current best and its migration counters;
* ``best``: the coordinator's global best (fitness re-evaluated by it);
* ``stop``: the coordinator's stop order.

Float arrays travel as ``{"shape": [...], "data": <little-endian float64
bytes>}``. Decoding never trusts a sender: size limits are checked before
unpacking, then every field's type, every shape against the campaign's
dimension, finiteness and the search bounds. A bad message raises
:class:`MessageRejected` whose ``reason`` is one of :data:`REASONS`.

This is the wire format only: it depends on msgpack, numpy and the loop set,
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

PROTOCOL_VERSION = 1
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}\Z")
"""Campaign and island names: usable as one Zenoh key chunk (no ``/ * $ ? #``)."""
ALGO_PATTERN = re.compile(r"[a-z][a-z0-9_]{0,15}\Z")
"""An island's algorithm label (``ga``, ``pso``) as it travels in its history."""

MAX_BYTES = {
    "config": 256 << 20,
    "migrants": 256 << 10,
    "history": 4 << 20,
    "best": 64 << 10,
    "stop": 4 << 10,
}
"""Largest accepted encoded size of each message type, in bytes."""
MAX_MIGRANTS = 256
MAX_ROWS = 100_000
MAX_DIM = 256
REASONS = ("oversized", "undecodable", "schema", "version", "campaign", "sender", "shape", "not_finite", "out_of_bounds")


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


# --- low-level packing ----------------------------------------------------------
def pack_array(a: np.ndarray) -> dict[str, Any]:
    a = np.ascontiguousarray(a, dtype="<f8")
    return {"shape": list(a.shape), "data": a.tobytes()}


def _pack(msg_type: str, campaign: str, body: dict[str, Any]) -> bytes:
    return msgpack.packb({"v": PROTOCOL_VERSION, "type": msg_type, "campaign": campaign, **body}, use_bin_type=True)


def _unpack(data: bytes, msg_type: str, campaign: str) -> dict[str, Any]:
    """Size check, msgpack decoding and the common envelope."""
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise MessageRejected("schema", f"payload is {type(data).__name__}, not bytes")
    if len(data) > MAX_BYTES[msg_type]:
        raise MessageRejected("oversized", f"{msg_type} message of {len(data)} bytes exceeds {MAX_BYTES[msg_type]}")
    try:
        msg = msgpack.unpackb(bytes(data), raw=False, strict_map_key=True)
    except Exception as exc:  # msgpack raises ValueError subclasses, StackError, UnicodeDecodeError...
        raise MessageRejected("undecodable", f"not msgpack ({type(exc).__name__})") from None
    if not isinstance(msg, dict):
        raise MessageRejected("schema", f"top level is {type(msg).__name__}, not a map")
    if msg.get("v") != PROTOCOL_VERSION:
        raise MessageRejected("version", f"protocol version {msg.get('v')!r}, expected {PROTOCOL_VERSION}")
    if msg.get("type") != msg_type:
        raise MessageRejected("schema", f"type {msg.get('type')!r}, expected {msg_type!r}")
    if msg.get("campaign") != campaign:
        raise MessageRejected("campaign", f"campaign {str(msg.get('campaign'))[:80]!r}, expected {campaign!r}")
    return msg


def _get(msg: dict[str, Any], key: str, types: type | tuple[type, ...]) -> Any:
    if key not in msg:
        raise MessageRejected("schema", f"field {key!r} missing")
    value = msg[key]
    if isinstance(value, bool) and bool not in (types if isinstance(types, tuple) else (types,)):
        raise MessageRejected("schema", f"field {key!r} is a bool")
    if not isinstance(value, types):
        raise MessageRejected("schema", f"field {key!r} is {type(value).__name__}")
    return value


def _int(msg: dict[str, Any], key: str, minimum: int = 0) -> int:
    value = _get(msg, key, int)
    if value < minimum:
        raise MessageRejected("schema", f"field {key!r} = {value} is below {minimum}")
    return value


def _number(msg: dict[str, Any], key: str) -> float:
    return float(_get(msg, key, (int, float)))


def _name(msg: dict[str, Any], key: str) -> str:
    value = _get(msg, key, str)
    if not NAME_PATTERN.match(value):
        raise MessageRejected("schema", f"field {key!r} is not a valid name")
    return value


def _array(msg: dict[str, Any], key: str, shape: tuple[int | None, ...], max_size: int) -> np.ndarray:
    """A float64 array whose shape matches ``shape`` (None = any length up to ``max_size``)."""
    obj = _get(msg, key, dict)
    if set(obj) != {"shape", "data"} or not isinstance(obj["shape"], list) or not isinstance(obj["data"], bytes):
        raise MessageRejected("schema", f"field {key!r} is not an array {{shape, data}}")
    dims = obj["shape"]
    if len(dims) != len(shape) or not all(isinstance(d, int) and not isinstance(d, bool) and d >= 0 for d in dims):
        raise MessageRejected("shape", f"field {key!r} has shape {dims!r}, expected {len(shape)} dimensions")
    if any(want is not None and got != want for got, want in zip(dims, shape)):
        raise MessageRejected("shape", f"field {key!r} has shape {dims}, expected {list(shape)}")
    size = int(np.prod(dims))
    if size > max_size:
        raise MessageRejected("oversized", f"field {key!r} holds {size} values, more than {max_size}")
    if len(obj["data"]) != 8 * size:
        raise MessageRejected("shape", f"field {key!r} has {len(obj['data'])} bytes for shape {dims}")
    return np.frombuffer(obj["data"], dtype="<f8").astype(float).reshape(dims)


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


# --- campaign configuration ---------------------------------------------------------
def _packable(value: Any) -> bool:
    try:
        msgpack.packb(value, use_bin_type=True)
    except (TypeError, ValueError, OverflowError):
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
        "meq_kg": loops.meq_kg,
        "cycles": [int(c) for c in loops.cycles],
        "labels": list(loops.labels),
        "meta": {k: v for k, v in loops.meta.items() if _packable(v)},
        "x_harmonics": None if loops.x_harmonics is None else pack_array(np.stack([loops.x_harmonics.real, loops.x_harmonics.imag], axis=-1)),
    }
    return _pack("config", campaign, {"config": config, "loops": wire_loops})


def decode_config(data: bytes, campaign: str) -> tuple[dict[str, Any], LoopSet]:
    """The campaign settings (a map, checked by :class:`island.config.CampaignConfig`) and the loop
    set, which is checked like a loaded file."""
    msg = _unpack(data, "config", campaign)
    wire = _get(msg, "loops", dict)
    config = _get(msg, "config", dict)
    n_max = MAX_BYTES["config"] // 8
    try:
        xh = None
        if wire.get("x_harmonics") is not None:  # optional: absent or None is the ideal sine
            pair = _array(wire, "x_harmonics", (None, None, 2), n_max)
            xh = pair[..., 0] + 1j * pair[..., 1]
        loops = LoopSet(
            name=_get(wire, "name", str),
            freq_hz=_array(wire, "freq_hz", (None,), n_max),
            x0=_array(wire, "x0", (None,), n_max),
            top=_array(wire, "top", (None, None, 2), n_max),
            bottom=_array(wire, "bottom", (None, None, 2), n_max),
            sigma=_array(wire, "sigma", (None,), n_max),
            meq_kg=_get(wire, "meq_kg", (int, float, type(None))),
            cycles=np.array(_get(wire, "cycles", list), dtype=int),
            labels=[str(s) for s in _get(wire, "labels", list)],
            meta=_get(wire, "meta", dict),
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


def encode_migrants(m: Migrants) -> bytes:
    return _pack("migrants", m.campaign, {
        "island": m.island, "run": m.run, "iteration": int(m.iteration),
        "x": pack_array(m.x), "claimed": pack_array(m.claimed), "sent_at": float(m.sent_at),
    })


def decode_migrants(data: bytes, campaign: str, bounds: np.ndarray, sender: str | None = None) -> Migrants:
    """Validate a migrant message against the campaign's ``(D, 2)`` bounds.

    ``sender`` is the island named by the Zenoh key the message came on; the
    message must name the same island.
    """
    msg = _unpack(data, "migrants", campaign)
    island = _name(msg, "island")
    if sender is not None and island != sender:
        raise MessageRejected("sender", f"message from key of {sender!r} claims island {island!r}")
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
    return Migrants(campaign, island, _name(msg, "run"), _int(msg, "iteration"), x, claimed, sent_at)


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


def encode_history(h: History) -> bytes:
    return _pack("history", h.campaign, {
        "island": h.island, "run": h.run, "algo": h.algo, "seed": int(h.seed), "rows": pack_array(np.asarray(h.rows, dtype=float).reshape(-1, 4)),
        "best_x": pack_array(h.best_x), "best_f": float(h.best_f), "stats": {k: int(h.stats[k]) for k in STAT_NAMES},
        "final": bool(h.final),
    })


def decode_history(data: bytes, campaign: str, bounds: np.ndarray, sender: str | None = None) -> History:
    msg = _unpack(data, "history", campaign)
    island = _name(msg, "island")
    if sender is not None and island != sender:
        raise MessageRejected("sender", f"message from key of {sender!r} claims island {island!r}")
    algo = _get(msg, "algo", str)
    if not ALGO_PATTERN.match(algo):
        raise MessageRejected("schema", f"algorithm label {algo[:20]!r} is not a short lower-case name")
    rows = _array(msg, "rows", (None, 4), 4 * MAX_ROWS)
    _finite(rows[:, [0, 2, 3]], "history iteration, evaluations or wall time")
    _finite(rows[:, 1], "history best fitness", allow_inf=True)
    if np.any(rows < 0) or np.any(rows[:, [0, 2]] != np.round(rows[:, [0, 2]])):
        raise MessageRejected("schema", "history rows need integer iteration and evaluations and non-negative values")
    best_x = _array(msg, "best_x", (bounds.shape[0],), MAX_DIM)
    _in_bounds(best_x[None, :], bounds)
    best_f = _number(msg, "best_f")
    if np.isnan(best_f) or best_f < 0:
        raise MessageRejected("not_finite", "best fitness is NaN or negative")
    stats_msg = _get(msg, "stats", dict)
    stats = {k: _int(stats_msg, k) for k in STAT_NAMES}
    return History(campaign, island, _name(msg, "run"), algo, _int(msg, "seed"), rows, best_x, best_f, stats, bool(_get(msg, "final", bool)))


# --- best and stop ------------------------------------------------------------------
@dataclass(frozen=True)
class Best:
    """The global best: ``fitness`` as re-evaluated by the coordinator, found by ``island``."""

    campaign: str
    island: str
    x: np.ndarray
    fitness: float


def encode_best(b: Best) -> bytes:
    return _pack("best", b.campaign, {"island": b.island, "x": pack_array(b.x), "fitness": float(b.fitness)})


def decode_best(data: bytes, campaign: str, bounds: np.ndarray) -> Best:
    msg = _unpack(data, "best", campaign)
    x = _array(msg, "x", (bounds.shape[0],), MAX_DIM)
    _in_bounds(x[None, :], bounds)
    fitness = _number(msg, "fitness")
    if not (np.isfinite(fitness) and fitness >= 0):
        raise MessageRejected("not_finite", "best fitness is not a finite non-negative number")
    return Best(campaign, _name(msg, "island"), x, fitness)


def encode_stop(campaign: str, reason: str) -> bytes:
    return _pack("stop", campaign, {"reason": reason})


def decode_stop(data: bytes, campaign: str) -> str:
    """The stop reason."""
    return _get(_unpack(data, "stop", campaign), "reason", str)[:200]
