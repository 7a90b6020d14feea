"""The coordinator's bookkeeping of how a mixed campaign shares its islands between algorithms.

The policy (credit, rounds, which island moves where) is :class:`island.share.Staged` or
:class:`island.share.Share` (the ``staged`` and ``adaptive`` shares);
:class:`Sharing` feeds it and keeps what follows from it: the algorithm each
run is to run (told to the islands in the roster of the ``control``
message), every algorithm a run has been told to run (what its histories may
say, :class:`coordinator.histories.HistoryChecks`), and the moves, stored in
the campaign database as they are made and read back on ``--resume``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from typing import Protocol

from coordinator.members import Member
from coordinator.store import Store
from island.config import CampaignConfig
from island.population import PopulationOptimizer
from island.share import Move, Share, Staged, round_iterations


class RunView(Protocol):
    """What the coordinator knows of an island run from its histories."""

    iteration: int
    final: bool


class Sharing:
    """The share of one campaign: ``joined`` maps each run that joined to the algorithm it joined
    with; ``optimizer(algo)`` is an (unused) optimizer with an island's settings (its batch sizes
    make a round's evaluations)."""

    def __init__(self, store: Store, config: CampaignConfig, joined: dict[tuple[str, str], str], optimizer: Callable[[str], PopulationOptimizer]) -> None:
        self.store = store
        self.name = config.name
        self._round_iterations = round_iterations(config.migration.interval)
        """A run's migration interval: its iterations in a round (adaptive), its survey (staged)."""
        mixed = len(set(config.algos)) > 1
        self.policy: Share | Staged | None = None
        """The staged or adaptive share of a mixed campaign (None: every island keeps its algorithm)."""
        if mixed and config.share == "staged":
            self.policy = Staged(config.algos, survey=self._round_iterations)
        elif mixed and config.share == "adaptive":
            self.policy = Share(config.algos)
        self.assigned: dict[tuple[str, str], str] = {}
        """The algorithm each run is to run: the one it joined with, unless the share moved it."""
        self.algos: dict[tuple[str, str], set[str]] = {}
        """Every algorithm each run has been told to run: the one it joined with and where it was moved."""
        self.gains: dict[tuple[str, str], float] = {}
        """Per run, the gain of its own moves its last history message reported (:mod:`island.share`)."""
        for key, algo in joined.items():
            self.joined(key, algo)
        self.moves: list[Move] = store.moves(self.name)
        for move in self.moves:
            self._follow(move)
        self._per_iteration = 0 if self.policy is None else max(optimizer(a).population + optimizer(a).addpop_number for a in config.algos)
        """Evaluations of one island's iteration (the largest of the campaign's algorithms)."""

    def joined(self, key: tuple[str, str], algo: str) -> None:
        """Run ``key`` joined with ``algo``."""
        self.assigned[key] = algo
        self.algos[key] = {algo}

    def _follow(self, move: Move) -> None:
        key = (move.island, move.run)
        self.assigned[key] = move.dst
        self.algos[key].add(move.dst)

    def credit(self, key: tuple[str, str], algo: str, gain: float) -> None:
        """Run ``key`` (running ``algo``) reports ``gain``, what its own moves gained so far: the policy
        is credited with the increase (the first message after a join or a restart sets the baseline)."""
        if self.policy is not None and key in self.gains:
            self.policy.credit(algo, gain - self.gains[key])
        self.gains[key] = max(self.gains.get(key, 0.0), gain)

    def review(
        self, evaluations: int, members: dict[str, Member], runs: Mapping[tuple[str, str], RunView], sender: tuple[str, str] | None = None
    ) -> list[Move]:
        """After ``evaluations`` in all (the adaptive share: once a round of every alive island's
        migration interval is over): the policy's moves, stored (committed with the next commit) and
        assigned. Only runs that can still move are offered: alive members whose liveliness token was
        seen (a run taken up after a restart may never come back) and whose history was not final. With
        the staged share, after a history of run ``sender``, only that run is offered (only its progress
        is new: a campaign of thousands of islands is not gone through at every message)."""
        if self.policy is None or evaluations < self.policy.next_review:
            return []
        alive: dict[tuple[str, str], str] = {}
        iterations: dict[tuple[str, str], int] = {}
        offered: Iterable[tuple[str, Member]] = members.items()
        if sender is not None and isinstance(self.policy, Staged):
            offered = [(sender[0], members[sender[0]])] if sender[0] in members else []
        for island, m in offered:
            key, view = (island, m.run), runs.get((island, m.run))
            if m.status == "alive" and m.token and key in self.assigned and not (view is not None and view.final):
                alive[key] = self.assigned[key]
                iterations[key] = view.iteration if view is not None else 0
        moves = self.policy.review(evaluations, len(alive) * self._round_iterations * self._per_iteration, alive, iterations)
        for move in moves:
            self.store.add_move(self.name, move)
            self.moves.append(move)
            self._follow(move)
        return moves
