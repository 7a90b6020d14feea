"""Simulated islands for the coordinator bench: any number of island sessions in one process, speaking the real protocol.

Each simulated island joins through the real handshake (:func:`island.joining.join`: its own run and signing
key), holds its liveliness token and sends what an island of the campaign's size sends (:func:`traffic`): a
history row per iteration at ``rate`` iterations a second, in messages every
:func:`island.node.history_period` (with improvements of its best now and then), a migrant message every
``interval`` iterations, and a final history at the end; everything sealed with its key. No optimizer runs:
the messages of the whole run are made and signed *before* it starts (so that signing them does not take
the coordinator's machine away from the coordinator), then published at their times over one Zenoh session.

Run as ``python -m hysid.bench.simulated ENDPOINT SECRET_FILE ISLANDS SECONDS RATE INTERVAL``: it prints one
JSON line when every island joined and its messages are ready (``ready``: the Unix time the run starts), one
when it has published everything (``done``: what it sent, how late it was, each island's start and the last
iteration of each of its history messages), then leaves.
"""

from __future__ import annotations

import heapq
import json
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
import zenoh

from hysid_model.synth import synth_loops
from island.config import decode_config
from island.island_messages import STAT_NAMES, History, Migrants, encode_history, encode_migrants
from island.joining import fetch_config, join, key_prefix
from island.node import HISTORY_EVERY_S, history_period
from island.sealing import Credentials
from island.secret import CampaignSecret
from island.session import open_session, session_config

IMPROVES = 0.02
"""Chance that an iteration improves a simulated island's best (by 1 %)."""
LEAD_S = 1.0
"""Seconds between the ready line and the first message."""


@dataclass
class Planned:
    """The messages of one simulated island: ``(send time from the start, key, payload)``."""

    island: str
    offset_s: float
    messages: list[tuple[float, str, bytes]]
    rows: int
    ends: list[int]
    """Last iteration of each history message."""


def evaluations(iterations: np.ndarray) -> np.ndarray:
    """What a PSO island of the bench's size (:data:`hysid.bench.processes.SIZES`) has evaluated after each iteration."""
    return 40 + 20 * iterations


def traffic(
    cred: Credentials,
    campaign: str,
    seed: int,
    x: np.ndarray,
    f: float,
    bounds: np.ndarray,
    members: int,
    seconds: float,
    rate: float,
    interval: int,
    start: float,
) -> Planned:
    """Island ``cred``'s messages for ``seconds`` of a campaign of ``members`` islands (its clock starting at the
    Unix time ``start``): rows at ``rate`` iterations a second, history every :func:`history_period`, migrants
    every ``interval`` iterations, the last history final."""
    rng = np.random.default_rng(seed)
    period = history_period(HISTORY_EVERY_S, members)
    offset = float(rng.uniform(0, period))
    n = int(seconds * rate)
    its = np.arange(n + 1)
    best = np.maximum(f, 10 * f * 0.99 ** np.cumsum(rng.random(n + 1) < IMPROVES))
    rows = np.column_stack([its, best, evaluations(its), its / rate]).astype(float)
    stats = dict.fromkeys(STAT_NAMES, 0)
    events: list[tuple[float, str, Any]] = [(float(j * period), "history", None) for j in range(1, int(seconds / period) + 1)]
    events += [(float(m * interval / rate), "migrants", m * interval) for m in range(1, int(n / interval) + 1)]
    events.sort(key=lambda e: e[0])
    prefix = key_prefix(campaign)
    messages, ends, sent_rows, seq = [], [], 0, 0
    for k, (at, kind, what) in enumerate(events):
        last = k == len(events) - 1
        if kind == "history" or last:
            top = n if last else min(int(at * rate), n)
            if top < sent_rows and not last:
                continue
            chunk = rows[sent_rows : top + 1]
            payload = encode_history(History(campaign, cred.island, cred.run, "pso", seed, chunk, x, float(best[top]), stats, last, seq), cred)
            messages.append((offset + at, f"{prefix}/history/{cred.island}", payload))
            ends.append(top)
            sent_rows = top + 1
        else:
            moved = np.clip(x + rng.normal(0, 1e-6, (2, x.size)) * np.abs(x), bounds[:, 0], bounds[:, 1])
            m = Migrants(campaign, cred.island, cred.run, what, moved, np.full(2, float(best[what])), start + offset + at, seq)
            messages.append((offset + at, f"{prefix}/migrants/{cred.island}", encode_migrants(m, cred)))
        seq += 1
    return Planned(cred.island, offset, messages, sent_rows, ends)


def main(argv: list[str]) -> int:
    endpoint, secret_file, count, seconds, rate, interval = argv[0], argv[1], int(argv[2]), float(argv[3]), float(argv[4]), int(argv[5])
    secret = CampaignSecret.read(secret_file)
    session = open_session(session_config("client", connect=[endpoint], connect_timeout_s=60), endpoint)
    config, _ = decode_config(fetch_config(session, secret, 60), secret.campaign)
    objective = config.objective(synth_loops(n_points=30))
    x = objective.bounds.mean(axis=1)
    f = float(objective(x[None, :])[0])
    names = [f"sim-{i}" for i in range(count)]
    with ThreadPoolExecutor(8) as pool:
        creds = list(pool.map(lambda name: join(session, secret.campaign, name, "pso", int(name[4:]), secret, 60), names))
    prefix = key_prefix(secret.campaign)
    tokens = [session.liveliness().declare_token(f"{prefix}/members/{c.island}") for c in creds]
    planned = time.time()  # migrants say when they were sent; being off by the time it takes to make them all changes nothing
    plans = [traffic(c, secret.campaign, i, x, f, objective.bounds, count, seconds, rate, interval, planned) for i, c in enumerate(creds)]
    publishers = {}
    for c in creds:
        publishers[f"{prefix}/history/{c.island}"] = session.declare_publisher(f"{prefix}/history/{c.island}", congestion_control=zenoh.CongestionControl.BLOCK)
        publishers[f"{prefix}/migrants/{c.island}"] = session.declare_publisher(f"{prefix}/migrants/{c.island}")
    start = time.time() + LEAD_S
    print(json.dumps({"ready": start}), flush=True)
    late = []
    queue = heapq.merge(*(p.messages for p in plans), key=lambda m: m[0])
    for at, key, payload in queue:
        wait = start + at - time.time()
        if wait > 0:
            time.sleep(wait)
        else:
            late.append(-wait)
        publishers[key].put(payload)
    counts = {"history": 0, "migrants": 0}
    for p in plans:
        for _, key, _ in p.messages:
            counts[key.rsplit("/", 2)[-2]] += 1
    print(
        json.dumps(
            {
                "done": True,
                "rows": sum(p.rows for p in plans),
                "history_messages": counts["history"],
                "migrant_messages": counts["migrants"],
                "late_p95_s": float(np.percentile(late, 95)) if late else 0.0,
                "late_share": len(late) / max(sum(counts.values()), 1),
                "islands": {p.island: {"start": start + p.offset_s, "ends": p.ends} for p in plans},
            }
        ),
        flush=True,
    )
    sys.stdin.readline()  # the bench says when to leave (after the coordinator took the final histories)
    for token in tokens:
        token.undeclare()
    session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
