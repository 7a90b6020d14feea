"""What a live view of a campaign shows, read from its database while the coordinator writes it.

``hysid watch CAMPAIGN_DB`` draws :func:`snapshot` again and again: the
campaign's status, the global best, and per island run its algorithm,
membership status, iterations, evaluations, best fitness (with its course
over the iterations), and the migrants it sent, received and took in. The
database is opened read-only (:meth:`coordinator.store.Store.read_only`), so
watching never disturbs the campaign.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from coordinator.members import STATUS_AFTER
from coordinator.progress import CampaignProgress, IslandView, algorithm_paths
from coordinator.store import Store

TREND_POINTS = 24
"""Iterations shown in each island's best-fitness trend."""


@dataclass
class CampaignSnapshot:
    """A campaign as its database holds it at one moment."""

    name: str
    dataset: str
    status: str
    """running, stopping, stopped or interrupted (also a campaign stored running or stopping whose coordinator is
    gone: :meth:`coordinator.queries.Queries.state`)."""
    stop_reason: str | None
    progress: CampaignProgress
    best_island: str | None
    islands: list[dict[str, Any]]
    """Per island run: ``island``, ``run``, ``algo`` (its last), ``algorithms`` (in order), ``status``, ``iterations``, ``evaluations``,
    ``best_fitness``, ``sent``, ``received``, ``taken``, ``messages`` (migrant messages the coordinator saw)
    and ``trend`` (best fitness at up to :data:`TREND_POINTS` iterations)."""
    events: list[tuple[str, str, float]]
    """The latest membership events ``(island, event, unix time)``."""
    gone_since: float | None = None
    """Unix time of the coordinator's last sign of life if it is gone while the campaign did not stop (its heartbeat
    stale, or its process ended: :meth:`coordinator.queries.Queries.gone_since`); the islands it saw alive are then
    unknown."""

    @property
    def over(self) -> bool:
        """Nothing more will come: the campaign stopped, or was interrupted (its coordinator is gone)."""
        return self.status in ("stopped", "interrupted") or self.gone_since is not None


def trend(values: list[float], points: int = TREND_POINTS) -> list[float]:
    """``values`` thinned to at most ``points``, always keeping the last."""
    if len(values) <= points:
        return list(values)
    idx = np.unique(np.round(np.linspace(0, len(values) - 1, points)).astype(int))
    return [values[i] for i in idx]


def snapshot(store: Store, name: str | None = None) -> CampaignSnapshot:
    """Read campaign ``name`` (default: the latest) from ``store`` as it is now."""
    name = store.pick_campaign(name)
    meta = next(c for c in store.campaign_list() if c["name"] == name)
    status, reason = store.state(name)
    records = store.islands(name)
    by_run: dict[tuple[str, str], list[float]] = {}
    for island, run, _, fitness, _, _ in store.history(name):
        by_run.setdefault((island, run), []).append(fitness)
    gone = store.gone_since(name)
    members: dict[str, str] = {}
    events = store.members(name)
    for island, event, _ in events:
        members[island] = "unknown" if gone is not None and STATUS_AFTER[event] == "alive" else STATUS_AFTER[event]
    sent = store.migrations_by_island(name)
    best = store.best(name)
    several = {r.island for r in records if sum(q.island == r.island for q in records) > 1}
    paths = algorithm_paths((((run[0], run[1]), run[3]) for run in store.runs(name)), store.moves(name))  # (island, run), algo
    islands = [
        {
            **r.as_dict(),
            "algorithms": list(paths.get((r.island, r.run), (r.algo,))),
            "status": members.get(r.island, "unknown"),
            "messages": sent.get(r.island, 0),
            "trend": trend(by_run.get((r.island, r.run), [])),
        }
        for r in records
    ]
    ended = meta["ended"] if meta["status"] == "stopped" and meta["ended"] else gone or time.time()
    progress = CampaignProgress(
        elapsed_s=ended - meta["created"],
        evaluations=store.total_evaluations(name),
        best=np.inf if best is None else best.fitness,
        members=members,
        islands={
            f"{r.island}/{r.run}" if r.island in several else r.island: IslandView(
                r.algo, r.iterations, r.best_fitness, r.final, paths.get((r.island, r.run), ())
            )
            for r in records
        },
        migrations=store.count("migrations", name),
        migrations_followed=store.unfollowed(name) is None,
        rejected=store.count("rejected", name),
    )
    return CampaignSnapshot(name, meta["dataset"], status, reason, progress, None if best is None else best.island, islands, events[-5:], gone)
