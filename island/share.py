"""How a mixed campaign shares its islands between algorithms: credit for what each algorithm gains, and moves.

GA and PSO islands of one campaign do not search equally well on every model
(on ``thesis+coulomb_friction`` from scratch the thesis' GA stays three orders
of magnitude behind its PSO). With a fixed share, a half-GA campaign spends
half its budget on the weaker algorithm. The ``adaptive`` share follows
AMALGAM (Vrugt and Robinson, PNAS 104, 2007: each method of a multi-method
search breeds in proportion to its recent success), with an island as the unit:

* an algorithm is credited with what its own moves gain: each island counts
  the orders of magnitude, ``log10(old / new)``, by which its GA offspring or
  PSO particle moves improved its best
  (:attr:`~island.population.PopulationOptimizer.gain`). The additional
  population around the best (both algorithms have it) and migrants do not
  count: with migration every island soon holds the global best, and what
  then improves it near that best says nothing about the algorithm;
* a *round* is one migration interval of every island's evaluations; after
  each, every algorithm is due a share of the islands in proportion to its
  credit per island over the last :data:`WINDOW` rounds (AMALGAM's rule: a
  method breeds in proportion to its recent success), and an algorithm holding
  more islands than its share gives one of them to the leading algorithm. One
  island per round, and an island that moved stays where it went for
  :data:`WINDOW` rounds: its new algorithm needs a window to show what it
  does there (a swarm starts at rest), and a wrong call (early credit can
  favour the weaker algorithm) is undone by the same rule, island by island,
  rather than taking the whole campaign. Two algorithms that keep up with
  each other keep their islands; when nobody gains (converged, or stuck: less
  than :data:`LEADING`), nobody moves;
* the moved island carries its search on
  (:func:`island.algorithms.switch_algorithm`): its population becomes the
  leader's population or swarm, its counters and history go on.

The policy is data in, moves out; the coordinator feeds it and tells the
islands (:mod:`coordinator.sharing`).
"""

from __future__ import annotations

from collections import deque
from dataclasses import asdict, dataclass
from typing import Any

from hysid_model.errors import HysidInputError

SHARES = ("adaptive", "fixed")
"""``adaptive``: islands are shared between the algorithms in proportion to what their own moves gain;
``fixed``: every island keeps the algorithm it joined with (as the thesis compared GA and PSO)."""
WINDOW = 2
"""Rounds over which each algorithm's credit is summed before it is compared, and that a moved island
stays with its new algorithm."""
LEADING = 0.1
"""The least credit per island over the window (orders of magnitude: a best 21 % lower) that makes an
algorithm a leader to follow; below it nobody is gaining (a converged or stuck campaign), and noise
would decide."""


def check_share(share: Any) -> str:
    """``share`` if it names one of :data:`SHARES`, else a one-line error."""
    if share not in SHARES:
        raise HysidInputError(f"share must be one of {', '.join(SHARES)}", param="share", value=share)
    return str(share)


@dataclass(frozen=True)
class Move:
    """Island run ``island/run`` goes from algorithm ``src`` to ``dst`` after ``evaluations`` in all;
    ``credit``: each algorithm's credit over the window (orders of magnitude)."""

    island: str
    run: str
    src: str
    dst: str
    evaluations: int
    credit: dict[str, float]

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


class Share:
    """The ``adaptive`` share policy (module docstring) of one campaign."""

    def __init__(self, algos: list[str]) -> None:
        self.algos = list(dict.fromkeys(algos))
        self.rounds: deque[dict[str, float]] = deque([{}], maxlen=WINDOW)
        """Credit per algorithm in the current round (last) and the ones before it."""
        self.closed = 0
        """Rounds closed so far."""
        self.next_review = 0
        self.moved_at: dict[tuple[str, str], int] = {}
        """The round after which each island run last moved."""

    def credit(self, algo: str, orders: float) -> None:
        """An island of ``algo`` reports ``orders`` of magnitude more gained by its own moves."""
        if orders > 0:
            self.rounds[-1][algo] = self.rounds[-1].get(algo, 0.0) + float(orders)

    def review(self, evaluations: int, round_evaluations: int, islands: dict[tuple[str, str], str]) -> list[Move]:
        """After ``evaluations`` in all: if a round (``round_evaluations``) is over, close it and return
        the moves (of each algorithm above its share, its first island by name that may move, to the
        leader). ``islands``: the algorithm of each alive island run ``(island, run)``."""
        if evaluations < self.next_review:
            return []
        self.next_review = evaluations + max(int(round_evaluations), 1)
        self.closed += 1
        window = self.rounds
        self.rounds = deque(list(window) + [{}], maxlen=WINDOW)
        if self.closed < WINDOW:
            return []
        credit = {a: sum(r.get(a, 0.0) for r in window) for a in self.algos}
        own = {a: sorted(k for k, b in islands.items() if b == a) for a in self.algos}
        per_island = {a: credit[a] / len(own[a]) if own[a] else 0.0 for a in self.algos}
        lead = max(self.algos, key=lambda a: per_island[a])
        if per_island[lead] < LEADING:
            return []
        total = sum(per_island.values())
        said = {a: round(c, 3) for a, c in credit.items()}
        moves = []
        for algo in self.algos:
            if algo == lead or len(own[algo]) <= int(len(islands) * per_island[algo] / total + 0.5):
                continue  # the leader, or an algorithm within its share
            free = [k for k in own[algo] if self.closed - self.moved_at.get(k, -WINDOW - 1) > WINDOW]
            if free:
                island, run = free[0]
                self.moved_at[(island, run)] = self.closed
                moves.append(Move(island, run, algo, lead, int(evaluations), said))
        return moves
