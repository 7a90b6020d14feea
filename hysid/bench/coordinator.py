"""``hysid bench coordinator``: a coordinator and islands under load and under attack.

* **load**: 32 islands' traffic (history every 0.25 s, 50 rows each; a migrant message
  every 0.05 s) fed for ``seconds`` into an in-process coordinator on a real SQLite
  file: the longest gaps between commits, between stop-rule checks and between progress
  lines (targets: commits every 0.5 s, checks within 0.2 s plus one message, progress
  every second), rows stored per second and the deepest inbox;
* **backlog**: the same 32 islands with a backlog of 6400 messages queued at once and a
  budget spent after about a quarter of them: seconds from the start to the stop decision
  and how much was still queued (it must not drain the queue first);
* **flood**: one island over Zenoh on loopback (coordinator, island and flooder are three
  processes) running a fixed number of iterations, alone and while a joined island floods
  it with 1000 migrant messages of 256 migrants per second: its run time (ratio) and how
  many migrants it re-evaluated (at most ``k`` per in-neighbour and migration).
"""

from __future__ import annotations

import resource
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from coordinator.launch import free_port
from coordinator.links import MemoryLink
from coordinator.server import Coordinator
from coordinator.store import Store
from hysid_model.synth import synth_loops
from island.config import CampaignConfig, decode_config
from island.migration import Migration
from island.node import IslandNode, ZenohTransport, fetch_config, join
from island.protocol import Credentials, History, Migrants, encode_history, encode_migrants
from island.session import open_session, session_config
from island.termination import Termination

ISLANDS = 32
SIZES = {a: {"population": 20, "initial_population": 40, "iterations": 10**9} for a in ("ga", "pso")}


def coordinator(workdir: Path, name: str, termination: Termination | None = None) -> Coordinator:
    loops = synth_loops(n_points=30)
    config = CampaignConfig.create(loops, name=name, options=SIZES, migration=Migration(interval=5, k=2))
    return Coordinator(Store(workdir / f"{name}.sqlite"), config, loops, termination)


def feed(c: Coordinator, cred: Credentials, seed: int, stop: threading.Event) -> None:
    """One island's traffic: 200 iterations a second, history every 0.25 s, migrants every 0.05 s."""
    x = c.objective.bounds.mean(axis=1)
    f = float(c.objective(x[None, :])[0])
    stats = {"sent": 0, "received": 0, "taken": 0, "rejected": 0}
    it, seq, started = 0, 0, time.monotonic()
    next_history = started
    while not stop.is_set():
        now = time.monotonic()
        if now >= next_history:
            top = int((now - started) * 200)
            rows = np.array([[i, f, 40 + 35 * i, now - started] for i in range(it, max(top, it + 1))], dtype=float)
            c.receive(f"{c.prefix}/history/{cred.island}", encode_history(History(c.name, cred.island, cred.run, "pso", seed, rows, x, f, stats, seq=seq), cred))
            it, seq, next_history = int(rows[-1, 0]) + 1, seq + 1, next_history + 0.25
        c.receive(f"{c.prefix}/migrants/{cred.island}", encode_migrants(Migrants(c.name, cred.island, cred.run, it, np.tile(x, (2, 1)), np.full(2, f), time.time(), seq), cred))
        seq += 1
        stop.wait(0.05)


def load(seconds: float = 10.0) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="hysid-bench-") as tmp:
        c = coordinator(Path(tmp), "load", Termination(time_limit_s=seconds))
        creds = [c.admit(f"pso-{i}", "pso", i) for i in range(ISLANDS)]
        commits: list[float] = []
        commit = c.store.commit

        def timed_commit(campaign: str | None = None) -> None:
            commit(campaign)
            commits.append(time.monotonic())

        c.store.commit = timed_commit  # type: ignore[method-assign]
        checks: list[float] = []
        deepest = [0]

        def shown(p: Any) -> None:
            checks.append(time.monotonic())
            deepest[0] = max(deepest[0], len(c.inbox))

        stop = threading.Event()
        feeders = [threading.Thread(target=feed, args=(c, cred, i, stop), daemon=True) for i, cred in enumerate(creds)]
        for t in feeders:
            t.start()
        started = time.monotonic()
        c.serve(MemoryLink(threading.Event()), shown, progress_every_s=0.0)
        stop.set()
        for t in feeders:
            t.join()
        rows = c.store.count("history", "load")
        window = [t for t in commits if started <= t <= started + seconds]
        checks = checks[:-1]  # the last progress line comes after the islands were told to stop
        return {
            "islands": ISLANDS, "seconds": seconds, "history_rows": rows, "rows_per_s": rows / seconds,
            "migrations": c.migrations, "commits": len(window),
            "max_commit_gap_s": float(np.max(np.diff(window))) if len(window) > 1 else None,
            "max_stop_check_gap_s": float(np.max(np.diff(checks))) if len(checks) > 1 else None,
            "deepest_inbox": deepest[0], "rejected": c.rejected,
            "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        }


def backlog(rounds: int = 200, budget: int = 400_000) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="hysid-bench-") as tmp:
        c = coordinator(Path(tmp), "backlog", Termination(budget=budget))
        x = c.objective.bounds.mean(axis=1)
        f = float(c.objective(x[None, :])[0])
        creds = [c.admit(f"pso-{i}", "pso", i) for i in range(ISLANDS)]
        for cred in creds:
            c.member(cred.island, False)
        stats = {"sent": 0, "received": 0, "taken": 0, "rejected": 0}
        for m in range(rounds):
            for i, cred in enumerate(creds):
                rows = np.array([[it, f, 20 + 25 * it, 0.0] for it in range(m * 10, m * 10 + 10)], dtype=float)
                c.receive(f"{c.prefix}/history/{cred.island}", encode_history(History(c.name, cred.island, cred.run, "pso", i, rows, x, f, stats, seq=m), cred))
        queued = len(c.inbox)
        seen: list[tuple[float, int, int]] = []
        started = time.monotonic()
        reason = c.serve(MemoryLink(threading.Event()), lambda p: seen.append((time.monotonic() - started, p.evaluations, len(c.inbox))), progress_every_s=0.0)
        decided_s, _, left = next(s for s in seen if s[1] >= budget)
        return {"queued": queued, "budget": budget, "stop_reason": reason, "stop_decided_s": decided_s, "still_queued_at_stop": left,
                "stop_checks_before": sum(1 for s in seen if s[1] < budget)}


def flooder(endpoint: str, campaign: str, per_s: float = 1000.0) -> None:
    """A joined island that floods ``migrants/flooder`` until killed (run in its own process)."""
    session = open_session(session_config("client", connect=[endpoint]), endpoint)
    cred = join(session, campaign, "flooder", "pso", 9, 30)
    token = session.liveliness().declare_token(f"hysid/{campaign}/members/flooder")
    publisher = session.declare_publisher(f"hysid/{campaign}/migrants/flooder")
    x = np.tile(np.array([0.05, 0.0, 300.0, 0.0]), (256, 1))
    print("ready", flush=True)
    seq, started = 0, time.monotonic()
    while token is not None:
        publisher.put(encode_migrants(Migrants(campaign, "flooder", cred.run, 1, x, np.zeros(256), 0.0, seq), cred))
        seq += 1
        time.sleep(max(0.0, started + seq / per_s - time.monotonic()))


def flood_run(iterations: int, flood: bool) -> dict[str, Any]:
    """One island run (in this process) against a coordinator process; optionally flooded by a
    joined island in a third process."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with tempfile.TemporaryDirectory(prefix="hysid-bench-") as tmp:
        coordinator_process = subprocess.Popen(
            [sys.executable, "-m", "hysid", "coordinator", "--listen", endpoint, "--campaign", "flood", "--db", f"{tmp}/f.sqlite",
             "--out", f"{tmp}/out", "--quiet", "--algos", "pso", "--population", "20", "--initial", "40", "--iterations", str(iterations),
             "--interval", "1", "--topology", "full", "--no-polish"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )
        flooding = None
        client = open_session(session_config("client", connect=[endpoint], connect_timeout_s=30), endpoint)
        try:
            config, loops = decode_config(fetch_config(client, "flood", 30), "flood")
            if flood:
                flooding = subprocess.Popen([sys.executable, "-c", f"from hysid.bench.coordinator import flooder; flooder({endpoint!r}, 'flood')"],
                                            stdout=subprocess.PIPE, text=True)
                assert flooding.stdout is not None and flooding.stdout.readline().strip() == "ready"
            node = IslandNode("target", "pso", 1, config, config.objective(loops))
            transport = ZenohTransport(client, node, 10)
            started, cpu, own = time.perf_counter(), resource.getrusage(resource.RUSAGE_SELF), time.thread_time()
            node.run(transport)
            elapsed, own = time.perf_counter() - started, time.thread_time() - own
            after = resource.getrusage(resource.RUSAGE_SELF)
            process_cpu = after.ru_utime + after.ru_stime - cpu.ru_utime - cpu.ru_stime
            transport.close()
        finally:
            for p in (flooding, coordinator_process):
                if p is not None:
                    p.kill()
                    p.wait()
            client.close()
        return {"run_s": elapsed, "evolution_cpu_s": own, "process_cpu_s": process_cpu, "iterations": iterations,
                "migrants_evaluated": node.migrant_evaluations, "rejected": node.stats["rejected"], "received": node.stats["received"]}


def flood(iterations: int = 1000) -> dict[str, Any]:
    quiet, flooded = flood_run(iterations, False), flood_run(iterations, True)
    return {"quiet": quiet, "flooded": flooded, "run_time_ratio": flooded["run_s"] / quiet["run_s"], "flood_messages_per_s": 1000,
            "most_migrants_allowed": 2 * iterations + 1}  # k = 2 from its one in-neighbour per migration, plus the global best


def run(seconds: float = 10.0) -> dict[str, Any]:
    """A coordinator with 32 islands (commit, stop-check and progress gaps), a backlog, an island under a migrant flood."""
    return {"load": load(seconds), "backlog": backlog(), "flood": flood()}


def to_text(r: dict[str, Any]) -> str:
    lo, bl, fl = r["load"], r["backlog"], r["flood"]
    return "\n".join([
        f"load: {lo['islands']} islands for {lo['seconds']:g} s: {lo['history_rows']:,} rows ({lo['rows_per_s']:,.0f}/s), "
        f"{lo['migrations']:,} migrant messages, {lo['commits']} commits; longest gap between commits {lo['max_commit_gap_s']:.3f} s, "
        f"between stop-rule checks {lo['max_stop_check_gap_s']:.3f} s; deepest inbox {lo['deepest_inbox']}; RSS {lo['rss_mb']:.0f} MB",
        f"backlog: {bl['queued']} messages queued; {bl['stop_reason']} decided after {bl['stop_decided_s']:.2f} s "
        f"with {bl['still_queued_at_stop']} still queued ({bl['stop_checks_before']} checks before)",
        f"flood: an island of {fl['quiet']['iterations']} iterations ran {fl['quiet']['run_s']:.2f} s alone and "
        f"{fl['flooded']['run_s']:.2f} s under {fl['flood_messages_per_s']:,} migrant messages/s of 256 migrants each "
        f"(ratio {fl['run_time_ratio']:.2f}); CPU of its evolution thread {fl['quiet']['evolution_cpu_s']:.2f} -> "
        f"{fl['flooded']['evolution_cpu_s']:.2f} s, of the whole island process {fl['quiet']['process_cpu_s']:.2f} -> "
        f"{fl['flooded']['process_cpu_s']:.2f} s; it re-evaluated {fl['flooded']['migrants_evaluated']} migrants "
        f"(at most {fl['most_migrants_allowed']} allowed)",
    ])
