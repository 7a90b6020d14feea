"""One campaign of the island benches (``hysid bench islands``, :mod:`hysid.bench.islands`) on the noiseless Synth
set (section 5.2), islands as processes over Zenoh or as threads, and the time its global best took to reach a
target."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

from coordinator.launch import island_specs, run_campaign
from coordinator.state import Coordinator
from coordinator.store import Store
from hysid_model.synth import synth_loops
from island.config import CampaignConfig
from island.migration import Migration
from island.termination import Termination


def campaign(
    workdir: Path,
    name: str,
    algo: str | list[str],
    islands: int,
    options: dict[str, Any],
    migration: Migration,
    rules: Termination,
    seed: int,
    *,
    model: str = "thesis",
    objective_kind: str = "closed_form",
    single_node: bool = False,
    start: bool = True,
    share: str = "fixed",
) -> Coordinator:
    """One campaign on the noiseless Synth set (islands as processes over Zenoh, or threads) of one
    algorithm or a mix (island i runs ``algo[i % len(algo)]``, each with ``options``); without
    ``iterations`` in ``options`` the islands search until the coordinator stops; ``start=False`` leaves the
    survey's linear estimate out of the islands' populations (a search from scratch); ``share`` is the
    mix's :mod:`island.share` policy. Returns its finished coordinator."""
    loops = synth_loops()
    algos = [algo] if isinstance(algo, str) else list(algo)
    config = CampaignConfig.create(
        loops,
        name=name,
        model=model,
        algos=algos,
        options={a: options for a in algos},
        migration=migration,
        seed=seed,
        min_islands=islands,
        objective_kind=objective_kind,
        until_stopped="iterations" not in options,
        share=share,
    )
    if not start:
        config = replace(config, start=None)
    coordinator = Coordinator(Store(workdir / f"{name}.sqlite"), config, loops, rules)
    run_campaign(coordinator, island_specs(islands, algos, seed * 100), single_node=single_node, polish=False)
    coordinator.store.close()
    return coordinator


def time_to(coordinator: Coordinator, target: float) -> float | None:
    """Seconds from the islands' start to the global best reaching ``target`` (None if it never did)."""
    assert coordinator.full_at is not None
    return next((t - coordinator.full_at for t, f, _, _ in coordinator.best_trace if f <= target), None)
