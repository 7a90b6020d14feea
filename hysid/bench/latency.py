"""``hysid bench islands latency``: migrant messages between two island sessions through a Zenoh router on
loopback, the rate of a burst and the one-way latency of paced messages, also in units of one thesis GA
iteration (what a migration costs an island)."""

from __future__ import annotations

import secrets
import threading
import time
from typing import Any

import numpy as np
import zenoh

from coordinator.launch import free_port
from hysid_model.problem import build_objective
from hysid_model.synth import synth_loops
from island.ga import GA
from island.island_messages import Migrants, decode_migrants, encode_migrants
from island.run import run as run_optimizer
from island.sealing import Credentials
from island.session import open_session, session_config


def ga_iteration_s(population: int = 500) -> float:
    """Median wall time of one thesis GA iteration on the closed-form Synth objective."""
    objective = build_objective(synth_loops())
    ga = GA(objective.bounds, 0, population=population, initial_population=population, iterations=20)
    rows = run_optimizer(ga, objective)
    return float(np.median(np.diff([r.wall_s for r in rows])))


def latency(messages: int = 5000, paced: int = 500, k: int = 2) -> dict[str, Any]:
    """Part (d): migrant messages between two island sessions through a router on loopback.

    A burst of ``messages`` gives the rate; then ``paced`` messages, one every 5 ms,
    give the one-way latency of a migration on an idle link.
    """
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    bounds = build_objective(synth_loops()).bounds
    router = open_session(session_config("router", listen=[endpoint]), endpoint)
    sender = open_session(session_config("client", connect=[endpoint]), endpoint)
    receiver = open_session(session_config("client", connect=[endpoint]), endpoint)
    delays: list[float] = []
    arrived = threading.Semaphore(0)
    credentials = Credentials.issue("a", secrets.token_bytes(32))
    public = credentials.public

    def on_sample(sample: zenoh.Sample) -> None:
        m = decode_migrants(sample.payload.to_bytes(), "bench", bounds, key_for=lambda s, r: public, sender="a")  # as an island would
        delays.append(time.time() - m.sent_at)
        arrived.release()

    rng = np.random.default_rng(0)
    x = bounds[:, 0] + rng.random((k, bounds.shape[0])) * (bounds[:, 1] - bounds[:, 0])

    def send(i: int) -> None:
        publisher.put(encode_migrants(Migrants("bench", "a", credentials.run, i, x, np.arange(k, dtype=float), time.time(), i), credentials))

    def wait_all(n: int) -> None:
        for _ in range(n):
            if not arrived.acquire(timeout=30):
                raise RuntimeError(f"latency bench: only {len(delays)} messages arrived")

    try:
        subscriber = receiver.declare_subscriber("hysid/bench/migrants/a", on_sample)
        publisher = sender.declare_publisher("hysid/bench/migrants/a", congestion_control=zenoh.CongestionControl.BLOCK)
        time.sleep(0.5)  # let the subscription reach the router
        start = time.perf_counter()
        for i in range(messages):
            send(i)
        wait_all(messages)
        elapsed = time.perf_counter() - start
        delays.clear()
        for i in range(paced):
            send(i)
            time.sleep(0.005)
        wait_all(paced)
        subscriber.undeclare()
    finally:
        for s in (receiver, sender, router):
            s.close()
    iteration = ga_iteration_s()
    median = float(np.median(delays))
    return {
        "messages": messages,
        "migrants_per_message": k,
        "messages_per_s": messages / elapsed,
        "migrants_per_s": k * messages / elapsed,
        "paced_messages": paced,
        "latency_median_ms": 1e3 * median,
        "latency_p99_ms": 1e3 * float(np.percentile(delays, 99)),
        "ga_iteration_ms": 1e3 * iteration,
        "latency_in_ga_iterations": median / iteration,
    }
