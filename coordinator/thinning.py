"""Which history rows the coordinator keeps when its islands offer more than its storage holds.

Every island sends a row per iteration (:mod:`island.node`); a thousand fast
islands offer hundreds of thousands of rows a second, more than one SQLite
writer takes while it also checks every message. :class:`HistoryPolicy`
decides, per island run, which rows of a history message are stored:

* **always** every improvement (a row whose best fitness is below the row
  before it), the newest row of every message (where the island is), every
  row of a run's first message and every row asked for again (a backfill after
  a gap); so the course of every run's best is complete;
* of the other rows (a plateau of the best), all while the coordinator keeps
  up; when the rows offered exceed what storage holds, only those whose
  iteration is a multiple of the run's *stride* (a power of two, so that the
  rows kept stay on one grid as it changes).

What storage holds is measured every :data:`REVIEW_EVERY_S` (:meth:`HistoryPolicy.review`, a running estimate):
the time writing a row takes, and the time the rest of the coordinator's work
(checking messages, migrants, membership) leaves it, keeping
:data:`HEADROOM` of the time free; so many rows a second, shared alike between
the runs that offer rows (water-filling: a run offering less than its share
keeps every row, the others are thinned to their share by their stride). What a
run offers is measured on its own clock (iterations per second of its rows'
wall times). The rows not kept are counted, per message, in the ``thinned``
table (:meth:`coordinator.store.Store.queue_thinned`: the stretch of
iterations and how many of its rows were left out), which reports show and
with which the coordinator knows those iterations were handled, not lost.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

HEADROOM = 0.2
"""Share of the coordinator's time kept free of work: beyond it, rows are thinned."""
ACTIVE_S = 5.0
"""A run that sent no rows for this long offers none."""
SMOOTHING = 0.3
"""Weight of the newest measurement in the running estimates (of a run's rate, of the cost of a row, of what
storage holds): a second of unusual work (an algorithm's rate measured, a burst of joins) thins little."""
REVIEW_EVERY_S = 1.0
"""How often what storage holds is measured again (over the commits since)."""
MEASURE_ROWS = 1000
"""Rows written in a review's time that measure what writing one takes (fewer would mostly measure a flush's
fixed cost): until such a measurement, storage keeps up."""
MAX_STRIDE = 1 << 20


@dataclass
class Pace:
    """An island run as the policy sees it: its newest row handled, how fast it offers rows, its stride."""

    iteration: int
    wall_s: float
    best: float
    rate: float = 0.0
    """Rows per second, on the island's clock."""
    stride: int = 1
    seen_at: float = 0.0


class HistoryPolicy:
    """Which history rows of each island run to store (see the module docstring)."""

    def __init__(self) -> None:
        self.paces: dict[tuple[str, str], Pace] = {}
        self.row_s: float | None = None
        """Measured seconds to write one row."""
        self.holds: float = math.inf
        """Rows a second storage holds, as last measured (inf: it keeps up)."""
        self.thinned = 0
        """Rows not kept since this coordinator started."""

    def keep(self, key: tuple[str, str], rows: np.ndarray) -> np.ndarray:
        """Which ``rows`` (a history message's, ``(n, 4)``) of island run ``key`` to store (a boolean mask)."""
        pace = self.paces.get(key)
        now = time.monotonic()
        if not rows.size:
            return np.zeros(0, dtype=bool)
        if pace is None or rows[0, 0] <= pace.iteration:  # a run's first rows here, or rows asked for again
            mask = np.ones(rows.shape[0], dtype=bool)
        else:
            before = np.concatenate(([pace.best], rows[:-1, 1]))
            mask = (rows[:, 1] < before) | (rows[:, 0] % pace.stride == 0)
            mask[-1] = True
        if pace is None:
            self.paces[key] = Pace(int(rows[-1, 0]), float(rows[-1, 3]), float(rows[-1, 1]), seen_at=now)
        elif rows[-1, 0] > pace.iteration:
            seconds = float(rows[-1, 3]) - pace.wall_s
            if seconds > 0:
                rate = (float(rows[-1, 0]) - pace.iteration) / seconds
                pace.rate = rate if pace.rate == 0 else (1 - SMOOTHING) * pace.rate + SMOOTHING * rate
            pace.iteration, pace.wall_s, pace.best, pace.seen_at = int(rows[-1, 0]), float(rows[-1, 3]), float(rows[-1, 1]), now
        self.thinned += int(rows.shape[0] - mask.sum())
        return mask

    def review(self, seconds: float, busy_s: float, writing_s: float, written: int) -> None:
        """After ``seconds`` in which the coordinator was busy ``busy_s``, of which ``writing_s`` writing
        ``written`` history rows: what storage holds, and each run's stride."""
        if written >= MEASURE_ROWS and writing_s > 0:
            cost = writing_s / written
            self.row_s = cost if self.row_s is None else (1 - SMOOTHING) * self.row_s + SMOOTHING * cost
        if self.row_s is None or seconds <= 0:
            return
        left = (1 - HEADROOM) * seconds - (busy_s - writing_s)
        holds = max(left, 0.0) / seconds / self.row_s
        self.holds = holds if not np.isfinite(self.holds) else (1 - SMOOTHING) * self.holds + SMOOTHING * holds
        now = time.monotonic()
        active = [p for p in self.paces.values() if now - p.seen_at <= ACTIVE_S and p.rate > 0]
        level = water_level(np.array([p.rate for p in active]), self.holds)
        for p in self.paces.values():
            p.stride = 1 if p.rate <= level else min(MAX_STRIDE, 1 << math.ceil(math.log2(p.rate / level) - 1e-9))

    def forget(self, key: tuple[str, str]) -> None:
        """A run that ended offers no more rows."""
        self.paces.pop(key, None)


def water_level(rates: np.ndarray, capacity: float) -> float:
    """The most rows a second each run may store so that all together store ``capacity``: runs offering
    less keep all theirs, the rest share what is left alike (inf when everything fits)."""
    if not np.isfinite(capacity) or rates.sum() <= capacity:
        return math.inf
    ordered = np.sort(rates)
    left = capacity
    for i, r in enumerate(ordered):
        share = left / (len(ordered) - i)
        if r > share:
            return max(share, 1e-9)
        left -= r
    return math.inf
