"""The staged hand-over under a coordinator that lags behind its islands (island/handover.py): the coordinator is
the real one, in this process on a real SQLite file, the islands speak to it over Zenoh on loopback."""

from __future__ import annotations

import threading

import pytest

from coordinator.intake import Intake
from coordinator.store import Store
from island.node import IslandNode
from island.termination import Termination
from island.transports import ZenohTransport
from support import wait_for
from test_host import LOOPS, Campaign, config

INTERVAL = 2
"""The campaign's migration interval: a GA island's first round, after which the staged share moves it."""
AHEAD = 6
"""Rounds the PSO islands search on before the stalled coordinator is let go."""


@pytest.mark.slow  # over 3 s (fast lane, 2 cores, 2026-11-29)
def test_a_staged_ga_island_hands_over_after_its_first_round_however_far_behind_the_coordinator_is(tmp_path, monkeypatch):
    """The coordinator stalls on the first history that holds rows and is let go only once every GA island has
    searched its first round and the PSO islands are six rounds on: the GA islands still search one round as GA,
    then PSO (before the mend they ran on as GA while the coordinator lagged, and took its order rounds late, or
    with the budget's stop and not at all), and the campaign ends at its budget with their moves recorded."""
    stalled, released = threading.Event(), threading.Event()
    handle = Intake._history

    def stalling(self, link, h, arrived):
        if len(h.rows) and not stalled.is_set():
            stalled.set()
            released.wait(120)
        handle(self, link, h, arrived)

    monkeypatch.setattr(Intake, "_history", stalling)
    cfg = config("ho", interval=INTERVAL, min_islands=4, iterations=10**6)
    assert cfg.share == "staged" and cfg.algos == ["ga", "pso"]
    campaign = Campaign(tmp_path, cfg, Termination(budget=6_000))
    c = campaign.c
    algos = ["ga", "pso", "ga", "pso"]
    nodes = [IslandNode(f"island-{k}", algo, 10 + k, cfg, cfg.objective(LOOPS), history_every_s=0.05) for k, algo in enumerate(algos)]
    threads = [threading.Thread(target=lambda n=n: n.run(ZenohTransport(campaign.client, n, c.secret, wait_s=20.0))) for n in nodes]
    try:
        for t in threads:
            t.start()

        def reached(node: IslandNode, iteration: int) -> bool:
            rows = list(node.rows)
            return bool(rows) and rows[-1][0] >= iteration

        wait_for(
            lambda: stalled.is_set() and all(reached(n, INTERVAL if algo == "ga" else AHEAD * INTERVAL) for n, algo in zip(nodes, algos)),
            120,
            "the coordinator to stall with every GA island at its round boundary and the PSO islands six rounds on",
        )
        released.set()
        for t in threads:
            t.join(120)
        assert not any(t.is_alive() for t in threads)
    finally:
        released.set()
        campaign.end()
    seen = {n.island: (n.moves, n.rows[-1][0], n.stop_reason) for n in nodes}  # shown if it fails
    assert {n.island: n.moves for n in nodes} == {
        "island-0": [(INTERVAL, "ga", "pso")],
        "island-1": [],
        "island-2": [(INTERVAL, "ga", "pso")],
        "island-3": [],
    }, seen
    assert all(n.algo == "pso" and n.rows[-1][0] > INTERVAL for n in nodes), seen  # the moved ones searched on as PSO
    assert c.stop_reason is not None and c.stop_reason.startswith("budget"), c.stop_reason
    store = Store(tmp_path / "ho.sqlite")
    try:
        assert sorted((m.island, m.src, m.dst) for m in store.moves("ho")) == [("island-0", "ga", "pso"), ("island-2", "ga", "pso")]
    finally:
        store.close()
