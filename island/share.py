"""How a mixed campaign shares its islands between algorithms: moves of islands from one algorithm to another.

GA and PSO islands of one campaign do not search equally well at every stage
(on ``thesis+coulomb_friction`` from scratch, a PSO-only campaign ends three
orders of magnitude below a GA-only one, while early on the GA islands often
hold the lower best). With a fixed share, a half-GA campaign spends half its
budget on the GA long after it stopped helping. Two policies move islands:

``staged`` (the default): the GA explores, the PSO converges
(:data:`island.algorithms.ROLES`: the thesis' finding that its PSO converges
much faster, and hysid's measurements of the GA early on). Every island starts
with the algorithm it joined with; once a run of an exploring algorithm has
searched its first migration interval of iterations, it moves to the
campaign's converging one. On the bench (``hysid bench islands mixed``) this
matches PSO-only campaigns, where a fixed half-GA share falls far behind: the
GA's first iterations cost nothing there, its later ones do.

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

A *round* of the adaptive share is one migration interval of every island's
evaluations. A moved island carries its search on (:func:`island.algorithms.switch_algorithm`): its
population becomes the new algorithm's population or swarm, its counters and
history go on. Every move records each algorithm's credit (over the last
rounds, or so far with the staged share). The policies are data in, moves out; the coordinator feeds them and
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
SHARE_ROUND_ITERATIONS = 10
"""When islands do not migrate: iterations per island in one round of the adaptive share, and those an
exploring run searches before the staged share moves it."""
LEADING = 0.1
"""The least credit per island over the window (orders of magnitude: a best 21 % lower) that makes an
algorithm a leader to follow; below it nobody is gaining (a converged or stuck campaign), and noise
would decide."""


def check_share(share: Any) -> str:
    """``share`` if it names one of :data:`SHARES`, else a one-line error."""
    if share not in SHARES:
        raise HysidInputError(f"share must be one of {', '.join(SHARES)}", param="share", value=share)
    return str(share)


def round_iterations(interval: int) -> int:
    """A run's iterations in one round of the adaptive share, and the survey of the staged share: its
    migration ``interval`` (:data:`SHARE_ROUND_ITERATIONS` when islands do not migrate)."""
    return interval or SHARE_ROUND_ITERATIONS


def handover_iteration(algos: list[str], share: str, interval: int, algo: str) -> int | None:
    """The iteration after which the staged share moves a run of ``algo`` in a campaign of ``algos``
    (migration ``interval``) to the converging algorithm: the end of its first round (:class:`Staged`);
    None if it never does (another share, one algorithm, or ``algo`` converges)."""
    mixed = len(set(algos)) > 1 and any(ROLES.get(a) == "converge" for a in algos)
    if share != "staged" or not mixed or ROLES.get(algo) != "explore":
        return None
    return round_iterations(interval)


@dataclass(frozen=True)
class Move:
    """Island run ``island/run`` goes from algorithm ``src`` to ``dst`` after ``evaluations`` in all;
    ``credit``: each algorithm's credit (orders of magnitude) over the window, or so far (staged)."""

    island: str
    run: str
    src: str
    dst: str
    evaluations: int
    credit: dict[str, float]

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


class Policy:
    """What both share policies keep: the campaign's algorithms, the credit their own moves earn
    (per round, the current one last), and the evaluations at which to review next."""

    def __init__(self, algos: list[str]) -> None:
        self.algos = list(dict.fromkeys(algos))
        self.rounds: deque[dict[str, float]] = deque([{}], maxlen=WINDOW)
        """Credit per algorithm in the current round (last) and the ones before it."""
        self.next_review = 0

    def credit(self, algo: str, orders: float) -> None:
        """An island of ``algo`` reports ``orders`` of magnitude more gained by its own moves."""
        if orders > 0:
            self.rounds[-1][algo] = self.rounds[-1].get(algo, 0.0) + float(orders)

    def gained(self) -> dict[str, float]:
        """Each algorithm's credit over the rounds kept."""
        return {a: sum(r.get(a, 0.0) for r in self.rounds) for a in self.algos}

    def said(self) -> dict[str, float]:
        """:meth:`gained` as a move records it."""
        return {a: round(c, 3) for a, c in self.gained().items()}


class Share(Policy):
    """The ``adaptive`` share policy (module docstring) of one campaign."""

    def __init__(self, algos: list[str]) -> None:
        super().__init__(algos)
        self.closed = 0
        """Rounds closed so far."""
        self.moved_at: dict[tuple[str, str], int] = {}
        """The round after which each island run last moved."""

    def review(self, evaluations: int, round_evaluations: int, islands: dict[tuple[str, str], str], iterations: dict[tuple[str, str], int]) -> list[Move]:
        """After ``evaluations`` in all: if a round (``round_evaluations``) is over, close it and return
        the moves (of each algorithm above its share, its first island by name that may move, to the
        leader). ``islands``: the algorithm of each alive island run ``(island, run)``; ``iterations``
        (each run's, not needed here) as :meth:`Staged.review`."""
        if evaluations < self.next_review:
            return []
        self.next_review = evaluations + max(int(round_evaluations), 1)
        self.closed += 1
        credit, said = self.gained(), self.said()
        self.rounds = deque(list(self.rounds) + [{}], maxlen=WINDOW)
        if self.closed < WINDOW:
            return []
        own = {a: sorted(k for k, b in islands.items() if b == a) for a in self.algos}
        per_island = {a: credit[a] / len(own[a]) if own[a] else 0.0 for a in self.algos}
        lead = max(self.algos, key=lambda a: per_island[a])
        if per_island[lead] < LEADING:
            return []
        total = sum(per_island.values())
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


class Staged(Policy):
    """The ``staged`` share policy (module docstring) of one campaign: a run of an exploring algorithm
    moves to the converging one once it has searched ``survey`` iterations. Its credit is kept (in one
    round, never closed) for the record of the moves."""

    def __init__(self, algos: list[str], survey: int) -> None:
        super().__init__(algos)
        self.survey = int(survey)
        self.converger = next(a for a in self.algos if ROLES[a] == "converge")
        """The campaign's converging algorithm (a mixed campaign of :data:`~island.algorithms.ALGORITHMS` has one)."""

    def review(self, evaluations: int, round_evaluations: int, islands: dict[tuple[str, str], str], iterations: dict[tuple[str, str], int]) -> list[Move]:
        """The moves after ``evaluations`` in all: every run of ``islands`` (the algorithm of each alive
        island run) whose algorithm explores and whose ``iterations`` (each run's, as its histories
        said) reached :attr:`survey`. Reviewed at every history (``round_evaluations`` is not needed)."""
        said = self.said()
        return [
            Move(island, run, algo, self.converger, int(evaluations), said)
            for (island, run), algo in sorted(islands.items())
            if ROLES[algo] == "explore" and iterations.get((island, run), 0) >= self.survey
        ]
