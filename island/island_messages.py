"""The island's messages (protocol version 5, :mod:`island.protocol`): ``migrants`` (its ``k`` best candidates with
the fitness it claims and its clock's send time; receivers always re-evaluate) and ``history`` (its convergence
rows, current best, own gain and migration counters), each sealed with its run's key (:mod:`island.sealing`) and
checked strictly as it is decoded (:mod:`island.wire`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from island.protocol import MAX_DIM, _algo
from island.sealing import Credentials, KeyLookup, Sealed, seal, unseal
from island.wire import (
    EPOCH_2020,
    MAX_COUNT,
    MAX_FITNESS,
    MessageRejected,
    _array,
    _finite,
    _get,
    _in_bounds,
    _int,
    _number,
    pack_array,
)

MAX_MIGRANTS = 256
MAX_ROWS = 100_000
MAX_CLOCK_SKEW_S = 86400.0
"""How far a migrant's send time may be from the receiver's clock (machines' clocks differ, not by a day)."""
MAX_GAIN = 1e6
"""Most orders of magnitude an island's own moves can have gained (a float64 best spans about 630 per
fall from its largest to its smallest value; a campaign of a million falls is beyond any budget)."""


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
