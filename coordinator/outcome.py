"""What a finished campaign leaves (Eq. 4.8-4.10's fit, from the islands' stored results).

:func:`campaign_outcome` takes what the coordinator knows as the campaign ends (:class:`CampaignEnd`,
which :meth:`coordinator.state.Coordinator.outcome` gives it) and its store, re-evaluates every
island run's best there (a claimed fitness is never trusted), polishes the global best as ``hysid fit``
does (widening bounds derived from the data when the best sits on one), and gathers the settings, the
islands, the migrations and the membership events as stored; :class:`hysid.campaigns.CampaignResult`
reports it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from coordinator.members import STATUS_AFTER
from coordinator.progress import algorithm_paths
from coordinator.queries import Queries
from coordinator.records import IslandRecord, StoredBest
from hysid_model.errors import HysidInputError
from hysid_model.loops import LoopSet
from hysid_model.model import MAX_WIDENINGS
from hysid_model.objective import Objective
from island.config import CampaignConfig
from island.memetic import BUDGET, WIDENED_SHARE, memetic_search, needs_islands
from island.run import RunResult, polish_run
from island.share import Move
from island.termination import Termination


@dataclass(frozen=True)
class CampaignEnd:
    """What the coordinator knows of a campaign as it ends, beyond its stored rows: the store it wrote, the
    configuration and loop set, the stop rules, the global best, why it stopped, each island's membership status
    as it holds it, every run that joined with the algorithm it joined with (in that order) and the share's moves."""

    store: Queries
    config: CampaignConfig
    loops: LoopSet
    termination: Termination
    best: StoredBest | None
    stop_reason: str | None
    status: dict[str, str]
    joined: list[tuple[tuple[str, str], str]]
    moves: list[Move]

    @property
    def name(self) -> str:
        return self.config.name


@dataclass
class CampaignOutcome:
    """What a finished campaign leaves: the objective, every island run (best re-evaluated, the global
    best polished), the settings, and the islands, migrations and membership events as stored."""

    objective: Objective
    runs: list[RunResult]
    settings: dict[str, Any]
    islands: list[dict[str, Any]]
    migrations: dict[str, Any]
    members: list[dict[str, Any]]
    stored: dict[str, Any]


def campaign_outcome(c: CampaignEnd, *, polish_best: bool = True) -> CampaignOutcome:
    """Every island run with its best re-evaluated here, the global best polished (as ``hysid fit`` does)."""
    objective = replace(c.config, objective_kind="closed_form").objective(c.loops)
    records = c.store.islands(c.name)
    history: dict[tuple[str, str], list[dict[str, float]]] = {}
    for island, run, it, f, ev, wall in c.store.history(c.name):
        history.setdefault((island, run), []).append({"iteration": it, "best_fitness": f, "evaluations": ev, "wall_s": wall})
    several = {r.island for r in records if sum(q.island == r.island for q in records) > 1}
    runs = []
    for rec in records:
        f = float(objective(rec.best_x[None, :])[0])
        rows = history.get((rec.island, rec.run), [])
        label = f"{rec.island}/{rec.run}" if rec.island in several else rec.island
        runs.append(RunResult.unpolished(label, rec.algo, rec.seed, rec.best_x, f, rec.evaluations, rows, rows[-1]["wall_s"] if rows else 0.0))
    best_stored = c.best
    global_best = None if best_stored is None else float(objective(best_stored.x[None, :])[0])
    if best_stored is not None and global_best is not None and (not runs or global_best < min(r.fitness for r in runs)):
        algo = runs[0].algo if runs else c.config.algos[0]
        runs.append(RunResult.unpolished(f"global best (from {best_stored.island})", algo, c.config.seed, best_stored.x, global_best, 0, []))
    if not runs:
        raise HysidInputError(f"campaign {c.name!r}: no island reported any result ({c.stop_reason or 'not run'})")
    best = int(np.argmin([r.fitness for r in runs]))
    widened: list[dict[str, Any]] = []
    if polish_best:
        objective, runs[best], widened = polished(objective, runs[best], c.config.seed)
    settings = {
        "campaign": c.name,
        "algo": "/".join(c.config.algos),
        "polish": polish_best,
        "algos": c.config.algos,
        "options": c.config.options,
        "migration": c.config.migration.as_dict(),
        "until_stopped": c.config.until_stopped,
        "share": c.config.share,
        "moves": [m.as_dict() for m in c.store.moves(c.name)],
        "seed": c.config.seed,
        "stop_rules": c.termination.as_dict(),
        "stop_reason": c.stop_reason or c.store.stop_reason(c.name),
        "db": c.store.path,
        "displacement": c.config.displacement,
        "bounds_from_data": list(c.config.soft),
        "bounds_widened": widened,
    }
    return CampaignOutcome(
        objective=objective,
        runs=runs,
        settings=settings,
        islands=island_summaries(c, records, runs),
        migrations=migration_summary(c, records),
        members=[{"island": i, "event": e, "t": t} for i, e, t in c.store.members(c.name)],
        stored=stored_summary(c),
    )


def polished(objective: Objective, run: RunResult, seed: int = 0) -> tuple[Objective, RunResult, list[dict[str, Any]]]:
    """``run`` polished on ``objective`` (as ``hysid fit`` polishes its best); a best on a search bound that is not
    physical (from the data, or a term's default) widens it and is searched again, up to ``MAX_WIDENINGS`` times,
    as ``hysid fit`` does: memetic islands from the best (``WIDENED_SHARE`` of their budget, seed ``seed``) on a
    model that needs them (:func:`island.memetic.needs_islands`), else a polish. Returns the objective it ends
    on, the run, and each bound widened (``param``, ``from``, ``to``)."""
    widened: list[dict[str, Any]] = []
    run = polish_run(objective, run)
    for _ in range(MAX_WIDENINGS):
        wider, changed = objective.model.widen_at(run.theta)
        if not changed:
            break
        old = dict(zip(objective.model.names, objective.model.bounds.tolist()))
        widened += [{"param": n, "from": old[n], "to": [float(b) for b in pair]} for n, pair in changed.items()]
        objective = Objective(objective.loops, wider, weights=objective.weights)
        if needs_islands(wider):
            found = memetic_search(objective, [run.theta], seed, budget=int(WIDENED_SHARE * BUDGET), label=f"{run.label}, searched again")
            if found.fitness < run.fitness:
                run = replace(run, theta=found.theta, fitness=found.fitness, evaluations=run.evaluations + found.evaluations)
            continue
        run = polish_run(objective, run)
    return objective, run, widened


def island_summaries(c: CampaignEnd, records: list[IslandRecord], runs: list[RunResult]) -> list[dict[str, Any]]:
    """Each island run's record with its re-evaluated best, its membership status (as last recorded) and the
    ``algorithms`` it searched with, in order (``algo`` is the last)."""
    recorded = {island: STATUS_AFTER[event] for island, event, _ in c.store.members(c.name)}
    status = recorded | c.status
    thinned = c.store.thinned(c.name)
    paths = algorithm_paths(c.joined, c.moves)
    return [
        {
            **rec.as_dict(),
            "algorithms": list(paths.get((rec.island, rec.run), (rec.algo,))),
            "best_fitness": run.search_fitness,
            "status": status.get(rec.island, "unknown"),
            "thinned": thinned.get((rec.island, rec.run), 0),
        }
        for rec, run in zip(records, runs)
    ]


def stored_summary(c: CampaignEnd) -> dict[str, Any]:
    """History rows stored, those the coordinator did not keep over capacity (:mod:`coordinator.thinning`), and
    migrant messages superseded before it handled them."""
    return {
        "history_rows": c.store.count("history", c.name),
        "thinned_rows": sum(c.store.thinned(c.name).values()),
        "superseded_migrant_messages": c.store.superseded(c.name),
    }


def migration_summary(c: CampaignEnd, records: list[IslandRecord]) -> dict[str, Any]:
    """The migration settings; migrant messages the coordinator handled (``messages``) and, if it stopped following
    them (:data:`coordinator.intake.FOLLOWS_MIGRANTS_UP_TO`), with how many islands alive and how long after the
    campaign's start (``unfollowed``); what the islands counted: messages ``sent``, migrants ``received``
    (re-evaluated) and ``taken`` in, and those that waited in vain for the roster to list their run (``unlisted``, apart
    from any rejected); messages the coordinator ``rejected`` and why."""
    unfollowed = c.store.unfollowed(c.name)
    created = next((k["created"] for k in c.store.campaign_list() if k["name"] == c.name), None)
    return {
        **c.config.migration.as_dict(),
        "messages": c.store.count("migrations", c.name),
        "unfollowed": None
        if unfollowed is None
        else {"islands": unfollowed["islands"], "follows_up_to": unfollowed["up_to"], "after_s": unfollowed["t"] - (created or unfollowed["t"])},
        "sent": sum(r.sent for r in records),
        "received": sum(r.received for r in records),
        "taken": sum(r.taken for r in records),
        "unlisted": sum(r.unlisted for r in records),
        "rejected": c.store.count("rejected", c.name),
        "rejected_reasons": c.store.rejected_reasons(c.name),
    }
