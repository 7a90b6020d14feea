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

from collections.abc import Callable

from coordinator.members import Member
from coordinator.store import Store
from island.config import CampaignConfig
from island.population import PopulationOptimizer
from island.share import Move, Share, Staged

SHARE_ROUND_ITERATIONS = 10
"""Iterations per island in one round of the share when islands do not migrate."""
POLICIES = {"staged": Staged, "adaptive": Share}
"""The share policy of each :data:`island.share.SHARES` that moves islands."""


class Sharing:
    """The share of one campaign: ``joined`` maps each run that joined to the algorithm it joined
    with; ``optimizer(algo)`` is an (unused) optimizer with an island's settings (its batch sizes
    make a round's evaluations)."""

    def __init__(
        self, store: Store, config: CampaignConfig, joined: dict[tuple[str, str], str], optimizer: Callable[[str], PopulationOptimizer]
    ) -> None:
        self.store = store
        self.name = config.name
        moving = POLICIES.get(config.share) if len(set(config.algos)) > 1 else None
        self.policy = moving(config.algos) if moving is not None else None
        """The staged or adaptive share of a mixed campaign (None: every island keeps its algorithm)."""
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
        self._round_iterations = config.migration.interval or SHARE_ROUND_ITERATIONS
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

    def review(self, evaluations: int, members: dict[str, Member]) -> list[Move]:
        """After ``evaluations`` in all, once a round of every alive island's migration interval is over:
        the policy's moves, stored (committed with the next commit) and assigned."""
        if self.policy is None or evaluations < self.policy.next_review:
            return []
        alive = {(island, m.run): self.assigned[(island, m.run)] for island, m in members.items() if m.status == "alive" and (island, m.run) in self.assigned}
        moves = self.policy.review(evaluations, len(alive) * self._round_iterations * self._per_iteration, alive)
        for move in moves:
            self.store.add_move(self.name, move)
            self.moves.append(move)
            self._follow(move)
        return moves
