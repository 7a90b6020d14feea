"""What a live view shows of a running campaign: :class:`CampaignProgress`, a snapshot the coordinator
takes (:meth:`coordinator.state.Coordinator.progress`) or ``hysid watch`` reads back from a campaign's
database, with an :class:`IslandView` per island run."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from island.share import Move


@dataclass
class IslandView:
    """What progress shows of one island run."""

    algo: str
    iteration: int = 0
    best: float = np.inf
    final: bool = False
    algos: tuple[str, ...] = ()
    """The algorithms it searched with, in order: the one it joined with, then each the share moved it to
    (:func:`algorithm_paths`; empty: only ``algo`` is known)."""


def island_views(islands: dict[tuple[str, str], IslandView], joined: Iterable[tuple[tuple[str, str], str]], moves: Iterable[Move]) -> dict[str, IslandView]:
    """The ``islands`` runs' views by name (an island with several runs shows each as ``island/run``), each with
    its algorithms (:func:`algorithm_paths` of the runs ``joined`` and the share's ``moves``)."""
    runs = Counter(i for i, _ in islands)
    paths = algorithm_paths(joined, moves)
    return {f"{i}" if runs[i] == 1 else f"{i}/{r}": replace(v, algos=paths.get((i, r), ())) for (i, r), v in islands.items()}


def algorithm_paths(joined: Iterable[tuple[tuple[str, str], str]], moves: Iterable[Move]) -> dict[tuple[str, str], tuple[str, ...]]:
    """Per island run ``(island, run)``: the algorithm it ``joined`` with, then each one its share's ``moves``
    moved it to, in order (``("ga", "pso")``: the staged share moved a GA island to the PSO)."""
    paths = {key: [algo] for key, algo in joined}
    for move in moves:
        paths.setdefault((move.island, move.run), [move.src]).append(move.dst)
    return {key: tuple(path) for key, path in paths.items()}


@dataclass
class CampaignProgress:
    """A snapshot of a running campaign, for a live view."""

    elapsed_s: float
    evaluations: int
    best: float
    members: dict[str, str]
    islands: dict[str, IslandView]
    migrations: int
    """Migrant messages the coordinator handled."""
    rejected: int
    migrations_followed: bool = True
    """False once the coordinator stopped following migrant messages (:data:`coordinator.intake.FOLLOWS_MIGRANTS_UP_TO`)."""
    stopping: str | None = None
    """Why the campaign stops (``interrupted``: the user's Ctrl-C) once it does, while it waits for the islands'
    last rows and after; None while it runs."""
