"""What a live view shows of a running campaign: :class:`CampaignProgress`, a snapshot the coordinator
takes (:meth:`coordinator.state.Coordinator.progress`) or ``hysid watch`` reads back from a campaign's
database, with an :class:`IslandView` per island run."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class IslandView:
    """What progress shows of one island run."""

    algo: str
    iteration: int = 0
    best: float = np.inf
    final: bool = False


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
    """False once the coordinator stopped following migrant messages (:data:`coordinator.state.FOLLOWS_MIGRANTS_UP_TO`)."""
    stopping: str | None = None
    """Why the campaign stops (``interrupted``: the user's Ctrl-C) once it does, while it waits for the islands'
    last rows and after; None while it runs."""
