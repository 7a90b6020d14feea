"""How a mixed campaign shares its islands between algorithms: moves of islands from one algorithm to another.

GA and PSO islands of one campaign do not search equally well at every stage
(on ``thesis+coulomb_friction`` from scratch, a PSO-only campaign ends three
orders of magnitude below a GA-only one, while early on the GA islands often
hold the lower best). With a fixed share, a half-GA campaign spends half its
budget on the GA long after it stopped helping. Two policies move islands:

``staged`` (the default): the GA explores, the PSO converges
(:data:`island.algorithms.ROLES`, with the thesis' and hysid's evidence). Every
island starts with the algorithm it joined with; once it has searched one
full round (its first migrations), an island of an exploring algorithm moves
to the campaign's converging one. On the bench (``hysid bench islands
mixed``) this beats PSO-only campaigns: the GA's first round is worth its
evaluations, its later ones are not.

``adaptive``: learned from the search, for algorithms whose strengths are not
known (other settings than the thesis', other models), following AMALGAM
(Vrugt and Robinson, PNAS 104, 2007: each method of a multi-method search
breeds in proportion to its recent success), with an island as the unit:

* an algorithm is credited with what its own moves gain: each island counts
  the orders of magnitude, ``log10(old / new)``, by which its GA offspring or
  PSO particle moves improved its best
  (:attr:`~island.population.PopulationOptimizer.gain`). The additional
  population around the best (both algorithms have it) and migrants do not
  count: with migration every island soon holds the global best, and what
  then improves it near that best says nothing about the algorithm;
* after each round, every algorithm is due a share of the islands in
  proportion to its credit per island over the last :data:`WINDOW` rounds
  (AMALGAM's rule), and an algorithm holding more islands than its share gives
  one of them to the leading algorithm. One island per round, and an island
  that moved stays where it went for :data:`WINDOW` rounds: its new algorithm
  needs a window to show what it does there (a swarm starts at rest), and a
  wrong call (early credit can favour the weaker algorithm) is undone by the
  same rule, island by island, rather than taking the whole campaign. Two
  algorithms that keep up with each other keep their islands; when nobody
  gains (converged, or stuck: less than :data:`LEADING`), nobody moves.
  Measured on the bench it loses to the staged share: a GA island's own gains
  around the migrated best keep it longer than it helps.

A *round* is one migration interval of every island's evaluations. A moved
island carries its search on (:func:`island.algorithms.switch_algorithm`): its
population becomes the new algorithm's population or swarm, its counters and
history go on. Every move records each algorithm's credit over the last
rounds. The policies are data in, moves out; the coordinator feeds them and
tells the islands (:mod:`coordinator.sharing`).
"""

from __future__ import annotations

from collections import deque
from dataclasses import asdict, dataclass
from typing import Any

from hysid_model.errors import HysidInputError
from island.algorithms import ROLES

SHARES = ("staged", "adaptive", "fixed")
"""``staged``: the exploring algorithm's islands move to the converging one after their first round;
``adaptive``: islands are shared between the algorithms in proportion to what their own moves gain;
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
    """The ``adaptive`` share policy (module docstring) of one campaign; :class:`Staged` decides otherwise."""

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
        the moves. ``islands``: the algorithm of each alive island run ``(island, run)``."""
        if evaluations < self.next_review:
            return []
        self.next_review = evaluations + max(int(round_evaluations), 1)
        self.closed += 1
        window = self.rounds
        self.rounds = deque(list(window) + [{}], maxlen=WINDOW)
        credit = {a: sum(r.get(a, 0.0) for r in window) for a in self.algos}
        return self._moves(credit, int(evaluations), islands)

    def _moves(self, credit: dict[str, float], evaluations: int, islands: dict[tuple[str, str], str]) -> list[Move]:
        """Of each algorithm above its share, its first island by name that may move, to the leader."""
        if self.closed < WINDOW:
            return []
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
                moves.append(Move(island, run, algo, lead, evaluations, said))
        return moves


class Staged(Share):
    """The ``staged`` share policy (module docstring) of one campaign: rounds and credit as
    :class:`Share`, moves by the algorithms' :data:`~island.algorithms.ROLES`."""

    def __init__(self, algos: list[str]) -> None:
        super().__init__(algos)
        self.converger = next((a for a in self.algos if ROLES[a] == "converge"), None)
        """The campaign's converging algorithm (None: nobody to hand over to, nobody moves)."""
        self.listed: dict[tuple[str, str], int] = {}
        """The round at whose close each island run was first listed alive."""

    def _moves(self, credit: dict[str, float], evaluations: int, islands: dict[tuple[str, str], str]) -> list[Move]:
        """Every exploring island listed at an earlier close (it searched a full round since) moves to
        the converger."""
        for key in islands:
            self.listed.setdefault(key, self.closed)
        if self.converger is None:
            return []
        said = {a: round(c, 3) for a, c in credit.items()}
        return [
            Move(island, run, algo, self.converger, evaluations, said)
            for (island, run), algo in sorted(islands.items())
            if ROLES[algo] == "explore" and self.listed[(island, run)] < self.closed
        ]
