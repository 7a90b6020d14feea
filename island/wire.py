"""The ground floor of the wire format: limits, why a message is rejected, msgpack packing and the
strict check of every field a message may hold.

Every campaign message (:mod:`island.protocol`, sealed ones through
:mod:`island.sealing`) is a msgpack map with the protocol version ``v``, its
``type`` and the ``campaign`` it belongs to; :func:`_unpack` checks that
envelope after the size limit of its type (:data:`MAX_BYTES`).

Float arrays travel as ``{"shape": [...], "data": <little-endian float64
bytes>}``. Decoding never trusts a sender: size limits are checked before
unpacking, then every field's type, integer range (SQLite's 64 bits, and 2**53
for counts carried as floats), string length, every shape (sizes computed
without overflow) against the campaign's dimension, finiteness and the search
bounds. A bad message raises :class:`MessageRejected` whose ``reason`` is one
of :data:`REASONS`.

The underscored helpers are shared by :mod:`island.sealing` and
:mod:`island.protocol` only. This module depends on msgpack, numpy and the
error type.
"""

from __future__ import annotations

import math
import re
from typing import Any

import msgpack
import numpy as np

from hysid_model.errors import HysidInputError

PROTOCOL_VERSION = 5
"""5: a join names the member it is made for (its admission proof is made with that member's secret, and its run
counts for that member: :mod:`island.secret`); an island's history counts apart the migrant messages that waited in
vain for the roster to list their run; the roster says the last message number the coordinator accepted of each run.
4: every message a party relies on is signed (Ed25519) by its sender: the coordinator's by the key whose
public half is in the campaign secret (:mod:`island.secret`), an island's by the key of its run, registered
when it joined (a challenge-response that proves it holds the campaign secret); no key is shared any more.
3: HMAC tags with per-run keys and a campaign key every joined island shared."""
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}\Z")
"""Campaign, island and run names: usable as one Zenoh key chunk (no ``/ * $ ? #``)."""

MAX_BYTES = {
    "config": 256 << 20,
    "join": 4 << 10,
    "challenge": 4 << 10,
    "prove": 4 << 10,
    "joined": 4 << 10,
    "migrants": 256 << 10,
    "history": 4 << 20,
    "control": 1 << 20,
    "best": 64 << 10,
}
"""Largest accepted encoded size of each message type, in bytes."""
MAX_MEMBERS = 4096
"""Island runs a campaign admits (and a control message lists)."""
MAX_TEXT = 200
"""Longest free text (a stop reason, a refusal) taken from a message."""
INT64_MAX = 2**63 - 1
MAX_FITNESS = 1e200
"""Largest fitness (a weighted sum of squared force residuals) taken from a message: far beyond any
candidate inside a campaign's search bounds, far below float64's overflow."""
EPOCH_2020 = 1577836800.0
"""2020-01-01 in Unix time: no campaign message was sent before."""
"""Largest integer SQLite stores."""
MAX_COUNT = 2**53
"""Largest count (iterations, evaluations) carried exactly in a float64 array."""
REASONS = (
    "oversized",
    "undecodable",
    "schema",
    "version",
    "campaign",
    "sender",
    "unjoined",
    "forged",
    "replay",
    "shape",
    "not_finite",
    "out_of_bounds",
    "out_of_range",
    "implausible",
    "overflow",
    "ahead",
)
"""Why a message is rejected. ``sender``: the key it came on names another island; ``unjoined``: its
sender or run never joined (or did not prove it holds the campaign secret); ``forged``: its signature
does not verify under its sender's key; ``replay``: its number was seen; ``out_of_range``: a time or
fitness no campaign can produce (a send time decades away, a wall time longer than the run has existed,
a fitness beyond :data:`MAX_FITNESS`);
``implausible``: well-formed but impossible (e.g. more evaluations than the island could have done);
``overflow``: dropped because the receiver's queue for that sender was full; ``ahead``: its number is further ahead of
the last one accepted from its sender run than that run can have sent since (:class:`island.sealing.ReplayGuard`)."""


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


def _unpack(data: bytes, msg_type: str, campaign: str, types: tuple[str, ...] = ()) -> dict[str, Any]:
    """Size check, msgpack decoding and the common envelope (of type ``msg_type``, or one of ``types``)."""
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise MessageRejected("schema", f"payload is {type(data).__name__}, not bytes")
    if len(data) > MAX_BYTES[msg_type]:
        raise MessageRejected("oversized", f"{msg_type} message of {len(data)} bytes exceeds {MAX_BYTES[msg_type]}")
    msg = _loads(data, f"{msg_type} message")
    if not isinstance(msg, dict):
        raise MessageRejected("schema", f"top level is {type(msg).__name__}, not a map")
    if msg.get("v") != PROTOCOL_VERSION or isinstance(msg.get("v"), bool):
        raise MessageRejected("version", f"protocol version {_show(msg.get('v'))}, expected {PROTOCOL_VERSION}")
    if msg.get("type") not in (types or (msg_type,)):
        raise MessageRejected("schema", f"type {_show(msg.get('type'))}, expected {' or '.join(map(repr, types or (msg_type,)))}")
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
