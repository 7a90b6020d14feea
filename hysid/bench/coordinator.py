"""``hysid bench coordinator``: a coordinator and islands under load and under attack.

* **load**: 32 islands' traffic (history every 0.25 s, 50 rows each; a migrant message
  every 0.05 s) fed for ``seconds`` into an in-process coordinator on a real SQLite
  file: the longest gaps between commits, between stop-rule checks and between progress
  lines (targets: commits every 0.5 s, checks within 0.2 s plus one message, progress
  every second), rows stored per second and the deepest inbox;
* **sustain**: the same load for 3 minutes: the process's resident memory every second
  and its slope after the first 30 s (MB per minute: about 0 when nothing grows);
* **ramp**: the same traffic per island from 32, 64, 128, ... islands, 12 s each, until
  the coordinator lags (a row's p95 delay from sent to stored above 1 s, or fewer than
  90 % of the rows sent stored): the most islands it held and where it degrades;
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
from coordinator.loop import serve
from coordinator.state import Coordinator
from coordinator.store import Store
from hysid_model.synth import synth_loops
from island.config import CampaignConfig, decode_config
from island.migration import Migration
from island.node import IslandNode
from island.protocol import History, Migrants, encode_history, encode_migrants
from island.sealing import Credentials
from island.secret import CampaignSecret, secret_path
from island.session import open_session, session_config
from island.termination import Termination
from island.transports import ZenohTransport, fetch_config, join

ISLANDS = 32
SIZES = {a: {"population": 20, "initial_population": 40, "iterations": 10**9} for a in ("ga", "pso")}


def coordinator(workdir: Path, name: str, termination: Termination | None = None) -> Coordinator:
    loops = synth_loops(n_points=30)
    config = CampaignConfig.create(loops, name=name, options=SIZES, migration=Migration(interval=5, k=2))
    return Coordinator(Store(workdir / f"{name}.sqlite"), config, loops, termination)


def feed(c: Coordinator, cred: Credentials, seed: int, stop: threading.Event, sent: dict[str, Any]) -> None:
    """One island's traffic: 200 iterations a second, history every 0.25 s, migrants every 0.05 s.
    ``sent`` gets the island's start (unix time; its rows' ``wall_s`` count from there), the rows
    and the migrant messages it sent."""
    x = c.objective.bounds.mean(axis=1)
    f = float(c.objective(x[None, :])[0])
    stats = {"sent": 0, "received": 0, "taken": 0, "rejected": 0}
    it, seq, started = 0, 0, time.monotonic()
    sent.update(start=time.time(), rows=0, migrants=0)
    next_history = started
    while not stop.is_set():
        now = time.monotonic()
        if now >= next_history:
            top = int((now - started) * 200)
            rows = np.array([[i, f, 40 + 35 * i, now - started] for i in range(it, max(top, it + 1))], dtype=float)
            c.receive(f"{c.prefix}/history/{cred.island}", encode_history(History(c.name, cred.island, cred.run, "pso", seed, rows, x, f, stats, seq=seq), cred))
            it, seq, next_history = int(rows[-1, 0]) + 1, seq + 1, next_history + 0.25
            sent["rows"] += len(rows)
        c.receive(f"{c.prefix}/migrants/{cred.island}", encode_migrants(Migrants(c.name, cred.island, cred.run, it, np.tile(x, (2, 1)), np.full(2, f), time.time(), seq), cred))
        seq += 1
        sent["migrants"] += 1
        stop.wait(0.05)


def rss_now_mb() -> float:
    """This process's resident memory now (``VmRSS``)."""
    with open("/proc/self/status", encoding="utf-8") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmRSS:")) / 1024.0


class Gaps:
    """The longest gap between calls of :meth:`tick` from ``start`` to ``end`` (monotonic time), kept
    as it goes: no list grows with the run, so the process's memory is the coordinator's."""

    def __init__(self, start: float, end: float) -> None:
        self.start, self.end = start, end
        self.last: float | None = None
        self.longest: float | None = None
        self.ticks = 0

    def tick(self) -> None:
        now = time.monotonic()
        if self.start <= now <= self.end:
            if self.last is not None:
                self.longest = max(self.longest or 0.0, now - self.last)
            self.last, self.ticks = now, self.ticks + 1


def drive(islands: int, seconds: float, rss_every_s: float = 1.0) -> dict[str, Any]:
    """``islands`` joined islands, each alive (its token seen) and sending :func:`feed`'s traffic to an
    in-process coordinator on a real SQLite file for ``seconds`` (its time limit); the coordinator's
    thread handles every message as it would from Zenoh. Measured: rows and migrant messages sent and
    stored per second (over the time limit plus the coordinator's wait for the islands' final rows),
    the lag of each stored row (stored at - sent at: p50, p95, max), the longest gaps between commits
    and between stop-rule checks, the deepest inbox and this process's RSS every ``rss_every_s``."""
    with tempfile.TemporaryDirectory(prefix="hysid-bench-") as tmp:
        c = coordinator(Path(tmp), "load", Termination(time_limit_s=seconds))
        creds = [c.join(f"pso-{i}", "pso", i) for i in range(islands)]
        for cred in creds:
            c.member(cred.island, True)
        stop, sampled = threading.Event(), threading.Event()
        rss: list[tuple[float, float]] = []
        started = time.monotonic()
        commits, checks = Gaps(started, started + seconds), Gaps(started, started + seconds)
        commit = c.store.commit

        def timed_commit(campaign: str | None = None) -> None:
            commit(campaign)
            commits.tick()

        c.store.commit = timed_commit  # type: ignore[method-assign]
        deepest = [0]

        def shown(p: Any) -> None:
            checks.tick()
            deepest[0] = max(deepest[0], len(c.inbox))

        def sample() -> None:
            while not sampled.is_set():
                rss.append((time.monotonic() - started, rss_now_mb()))
                sampled.wait(rss_every_s)

        sent: list[dict[str, Any]] = [{} for _ in creds]
        threads = [threading.Thread(target=sample, daemon=True)]
        threads += [threading.Thread(target=feed, args=(c, cred, i, stop, sent[i]), daemon=True) for i, cred in enumerate(creds)]
        for t in threads:
            t.start()
        serve(c, MemoryLink(threading.Event()), shown, progress_every_s=0.0)
        elapsed = time.monotonic() - started  # the time limit plus the wait for the islands' final rows
        stop.set()
        sampled.set()
        for t in threads:
            t.join()
        starts = {cred.island: sent[i]["start"] for i, cred in enumerate(creds)}
        stored = c.store.db.execute("SELECT island, wall_s, t FROM history WHERE campaign = 'load'").fetchall()
        lag = np.array([t - starts[island] - wall for island, wall, t in stored]) if stored else np.zeros(1)
        return {
            "islands": islands, "seconds": seconds, "elapsed_s": elapsed, "history_rows": len(stored), "rows_per_s": len(stored) / elapsed,
            "rows_sent_per_s": sum(s["rows"] for s in sent) / elapsed, "migrations": c.migrations,
            "migrant_messages_per_s": c.migrations / elapsed, "migrant_messages_sent_per_s": sum(s["migrants"] for s in sent) / elapsed,
            "row_lag_s": {"p50": float(np.percentile(lag, 50)), "p95": float(np.percentile(lag, 95)), "max": float(np.max(lag))},
            "commits": commits.ticks, "max_commit_gap_s": commits.longest, "max_stop_check_gap_s": checks.longest,
            "deepest_inbox": deepest[0], "rejected": c.rejected,
            "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "rss_samples": rss,
        }


def load(seconds: float = 10.0) -> dict[str, Any]:
    """32 islands for ``seconds``: what :func:`drive` measures, without the RSS samples."""
    r = drive(ISLANDS, seconds)
    del r["rss_samples"]
    return r


def sustain(seconds: float = 180.0, settle_s: float = 30.0) -> dict[str, Any]:
    """32 islands for ``seconds``: RSS at the start, after ``settle_s`` and at the end, and its slope
    (MB per minute, least squares over the samples after ``settle_s``; about 0 when nothing grows)."""
    r = drive(ISLANDS, seconds)
    samples = np.array(r.pop("rss_samples"))
    late = samples[samples[:, 0] >= settle_s]
    return {**r, "settle_s": settle_s, "rss_first_mb": float(samples[0, 1]), "rss_settled_mb": float(late[0, 1]),
            "rss_last_mb": float(samples[-1, 1]), "rss_slope_mb_per_min": float(np.polyfit(late[:, 0], late[:, 1], 1)[0] * 60.0),
            "rss_every_10_s": [[round(t), round(m, 1)] for t, m in samples[::10]]}


RAMP = (32, 64, 128, 256, 512)
LAG_LIMIT_S = 1.0
"""A row stored more than this after it was sent (p95) means the coordinator lags."""


def lags(r: dict[str, Any]) -> bool:
    """Whether the coordinator fell behind: p95 row lag above ``LAG_LIMIT_S``, or under 90 % of the rows sent stored."""
    return r["row_lag_s"]["p95"] > LAG_LIMIT_S or r["rows_per_s"] < 0.9 * r["rows_sent_per_s"]


def ramp(steps: tuple[int, ...] = RAMP, seconds: float = 12.0) -> dict[str, Any]:
    """The same traffic from more and more islands, up to the first step where the coordinator lags."""
    results = []
    for n in steps:
        r = drive(n, seconds)
        del r["rss_samples"]
        results.append(r)
        if lags(r):
            break
    held = [r["islands"] for r in results if not lags(r)]
    return {"steps": results, "lag_limit_s": LAG_LIMIT_S, "held_at_islands": max(held, default=None),
            "degrades_at_islands": results[-1]["islands"] if lags(results[-1]) else None}


def backlog(rounds: int = 200, budget: int = 400_000) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="hysid-bench-") as tmp:
        c = coordinator(Path(tmp), "backlog", Termination(budget=budget))
        x = c.objective.bounds.mean(axis=1)
        f = float(c.objective(x[None, :])[0])
        creds = [c.join(f"pso-{i}", "pso", i) for i in range(ISLANDS)]
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
        reason = serve(c, MemoryLink(threading.Event()), lambda p: seen.append((time.monotonic() - started, p.evaluations, len(c.inbox))), progress_every_s=0.0)
        decided_s, _, left = next(s for s in seen if s[1] >= budget)
        return {"queued": queued, "budget": budget, "stop_reason": reason, "stop_decided_s": decided_s, "still_queued_at_stop": left,
                "stop_checks_before": sum(1 for s in seen if s[1] < budget)}


def flooder(endpoint: str, secret_file: str, per_s: float = 1000.0) -> None:
    """A joined island that floods ``migrants/flooder`` until killed (run in its own process)."""
    secret = CampaignSecret.read(secret_file)
    campaign = secret.campaign
    session = open_session(session_config("client", connect=[endpoint]), endpoint)
    cred = join(session, campaign, "flooder", "pso", 9, secret, 30)
    token = session.liveliness().declare_token(f"hysid/{campaign}/members/flooder")
    publisher = session.declare_publisher(f"hysid/{campaign}/migrants/flooder")
    x = np.tile(np.array([0.05, 0.0, 300.0, 0.0]), (256, 1))
    print("ready", flush=True)
    seq, started = 0, time.monotonic()
    while token is not None:
        publisher.put(encode_migrants(Migrants(campaign, "flooder", cred.run, 1, x, np.zeros(256), time.time(), seq), cred))
        seq += 1
        time.sleep(max(0.0, started + seq / per_s - time.monotonic()))


def wait_for_secret(path: Path, timeout_s: float) -> CampaignSecret:
    """The secret a coordinator process writes when it starts."""
    deadline = time.monotonic() + timeout_s
    while not path.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    return CampaignSecret.read(path)


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
            secret = wait_for_secret(secret_path(f"{tmp}/f.sqlite", "flood"), 30)
            config, loops = decode_config(fetch_config(client, secret, 30), "flood")
            if flood:
                flooding = subprocess.Popen(
                    [sys.executable, "-c", f"from hysid.bench.coordinator import flooder; flooder({endpoint!r}, {str(secret_path(f'{tmp}/f.sqlite', 'flood'))!r})"],
                    stdout=subprocess.PIPE, text=True,
                )
                assert flooding.stdout is not None and flooding.stdout.readline().strip() == "ready"
            node = IslandNode("target", "pso", 1, config, config.objective(loops))
            transport = ZenohTransport(client, node, secret, 10)
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


def run(seconds: float = 10.0, sustain_s: float = 180.0, ramp_s: float = 12.0) -> dict[str, Any]:
    """A coordinator with 32 islands (gaps, memory over 3 minutes), more islands until it lags, a backlog, an island under a migrant flood."""
    return {"load": load(seconds), "sustain": sustain(sustain_s), "ramp": ramp(seconds=ramp_s), "backlog": backlog(), "flood": flood()}


def to_text(r: dict[str, Any]) -> str:
    lo, su, ra, bl, fl = r["load"], r["sustain"], r["ramp"], r["backlog"], r["flood"]

    def traffic(x: dict[str, Any]) -> str:
        return (f"{x['islands']} islands for {x['elapsed_s']:.1f} s: {x['rows_per_s']:,.0f} rows/s stored of {x['rows_sent_per_s']:,.0f} sent, "
                f"{x['migrant_messages_per_s']:,.0f} migrant messages/s of {x['migrant_messages_sent_per_s']:,.0f}; row lag p50 "
                f"{x['row_lag_s']['p50']:.3f} s, p95 {x['row_lag_s']['p95']:.3f} s; longest gap between commits {x['max_commit_gap_s']:.3f} s, "
                f"between stop-rule checks {x['max_stop_check_gap_s']:.3f} s; deepest inbox {x['deepest_inbox']}")

    return "\n".join([
        f"load: {traffic(lo)}; RSS {lo['rss_mb']:.0f} MB",
        f"sustain: {traffic(su)}; RSS {su['rss_first_mb']:.0f} MB at the start, {su['rss_settled_mb']:.0f} MB after {su['settle_s']:g} s, "
        f"{su['rss_last_mb']:.0f} MB at the end: slope {su['rss_slope_mb_per_min']:+.2f} MB/min",
        *(f"ramp: {traffic(x)}{' <- lags' if lags(x) else ''}" for x in ra["steps"]),
        f"ramp: held {ra['held_at_islands']} islands; degrades at {ra['degrades_at_islands'] or 'none of the steps'}",
        f"backlog: {bl['queued']} messages queued; {bl['stop_reason']} decided after {bl['stop_decided_s']:.2f} s "
        f"with {bl['still_queued_at_stop']} still queued ({bl['stop_checks_before']} checks before)",
        f"flood: an island of {fl['quiet']['iterations']} iterations ran {fl['quiet']['run_s']:.2f} s alone and "
        f"{fl['flooded']['run_s']:.2f} s under {fl['flood_messages_per_s']:,} migrant messages/s of 256 migrants each "
        f"(ratio {fl['run_time_ratio']:.2f}); CPU of its evolution thread {fl['quiet']['evolution_cpu_s']:.2f} -> "
        f"{fl['flooded']['evolution_cpu_s']:.2f} s, of the whole island process {fl['quiet']['process_cpu_s']:.2f} -> "
        f"{fl['flooded']['process_cpu_s']:.2f} s; it re-evaluated {fl['flooded']['migrants_evaluated']} migrants "
        f"(at most {fl['most_migrants_allowed']} allowed)",
    ])
