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

This module holds what the messages share (the sender name of the coordinator, limits, the algorithm label) and
the ``config`` message; the island's messages (``migrants``, ``history``) are in :mod:`island.island_messages`,
the coordinator's (``control``, ``best``, history queries) in :mod:`island.coordinator_messages`, the join
handshake's in :mod:`island.handshake`.

This is the wire format only: with :mod:`island.wire` and :mod:`island.sealing`
it depends on msgpack, numpy, ``cryptography`` and the loop set,
not on models, objectives or optimizers (the campaign settings inside
``config`` are checked by :class:`island.config.CampaignConfig`).
"""

from __future__ import annotations

import re
from typing import Any

import msgpack
import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.loops import LoopSet
from island.sealing import seal, unseal
from island.wire import (
    INT64_MAX,
    MAX_BYTES,
    MAX_TEXT,
    PROTOCOL_VERSION,
    MessageRejected,
    _array,
    _dumps,
    _get,
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
MAX_DIM = 256
"""Most parameters a candidate vector on the wire may hold."""
NONCE_BYTES = 16


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
