"""``hysid bench coordinator``: a coordinator and islands under load and under attack, and islands many to a process.

The load comes from simulated islands (:mod:`hysid.bench.simulated`: real joins, keys, signatures and Zenoh
traffic from a process of their own, no optimizer): each at :data:`RATE` iterations a second (a PSO island
of the default size on the Synth set runs about 45), a history row per iteration sent in messages every
0.25 s (less often beyond 250 islands: :func:`island.node.history_period`), a migrant message every
:data:`INTERVAL` iterations. The coordinator runs in this process, on a real SQLite file, listening on
loopback.

* **load**: 32 islands for ``seconds``: the longest gaps between commits and between stop-rule checks
  (targets: commits every 0.5 s, checks within 0.2 s plus one message), rows stored per second, the lag of a
  row from its message's sending to its storing (p50, p95, max), the deepest inbox;
* **sustain**: the same load for 3 minutes: the process's resident memory every second and its slope after
  the first 30 s (MB per minute: about 0 when nothing grows);
* **ramp**: 32, 64, 128, ... islands, ``ramp_s`` each, until the coordinator lags (a row's p95 lag above 1 s,
  or a row sent neither stored nor counted as thinned): the most islands it held, what it stored and thinned
  (:mod:`coordinator.thinning`), migrant messages handled and superseded (none beyond
  :data:`coordinator.state.FOLLOWS_MIGRANTS_UP_TO` islands: then it no longer follows them), and the coordinator's memory
  (this process's resident memory over the islands: target 1 MB per island at most);
* **backlog**: 32 islands with a backlog of 6400 messages queued at once and a budget spent after about a
  quarter of them: seconds from the start to the stop decision and how much was still queued (it must not
  drain the queue first);
* **flood**: one island over Zenoh on loopback (coordinator, island and flooder are three processes) running a
  fixed number of iterations, alone and while a joined island floods it with 1000 migrant messages of 256
  migrants per second: its run time (ratio) and how many migrants it re-evaluated (at most ``k`` per
  in-neighbour and migration);
* **host**: :data:`HOST_ISLANDS` islands in one process (``hysid island --count``) against a coordinator
  process: the process's peak resident memory per island (target: 25 MB at most), against one island
  process's; and the same islands (isolated, seeded) as separate processes: the same answers (iterations,
  evaluations, best fitness and vector) and rows, island by island.
"""

from __future__ import annotations

import json
import os
import resource
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from coordinator.launch import free_port
from coordinator.links import MemoryLink, ZenohLink
from coordinator.loop import pump, serve
from coordinator.state import Coordinator
from coordinator.store import Store
from hysid_model.synth import synth_loops
from island.config import CampaignConfig, decode_config
from island.migration import Migration
from island.node import HISTORY_EVERY_S, IslandNode, history_period
from island.protocol import History, Migrants, encode_history, encode_migrants
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


RATE = 50.0
"""Iterations a second of a simulated island."""
INTERVAL = 5
"""Iterations between its migrant messages (the default ``--interval``)."""


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


def simulated(endpoint: str, secret_file: Path, islands: int, seconds: float) -> subprocess.Popen:
    """A process of ``islands`` simulated islands (:mod:`hysid.bench.simulated`) for ``seconds``."""
    return subprocess.Popen(
        [sys.executable, "-m", "hysid.bench.simulated", endpoint, str(secret_file), str(islands), f"{seconds:g}", f"{RATE:g}", str(INTERVAL)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )


def line(process: subprocess.Popen, key: str) -> dict[str, Any]:
    """The next JSON line of a simulated-islands process, which must hold ``key``."""
    assert process.stdout is not None
    text = process.stdout.readline()
    if not text:
        raise RuntimeError(f"the simulated islands ended ({process.wait()}): {process.stderr.read().strip()[-500:] if process.stderr else ''}")
    doc = json.loads(text)
    if key not in doc:
        raise RuntimeError(f"the simulated islands said {text.strip()[:200]}")
    return doc


def row_lags(stored: list[tuple[str, int, float]], islands: dict[str, Any]) -> np.ndarray:
    """Each stored row's lag: stored at, less when the history message holding it was sent (its island's start
    plus the wall time of the message's last row: ``ends`` are the last iterations of its messages)."""
    by_island: dict[str, list[tuple[int, float]]] = {}
    for island, iteration, t in stored:
        by_island.setdefault(island, []).append((iteration, t))
    lags = []
    for island, got in by_island.items():
        its, ts = np.array(got).T
        ends = np.array(islands[island]["ends"])
        sent = islands[island]["start"] + ends[np.minimum(np.searchsorted(ends, its), ends.size - 1)] / RATE
        lags.append(ts - sent)
    return np.concatenate(lags) if lags else np.zeros(1)


def drive(islands: int, seconds: float, rss_every_s: float = 1.0) -> dict[str, Any]:
    """``islands`` simulated islands (:func:`simulated`) joined to a coordinator in this process and sending
    for ``seconds``; the coordinator handles everything as it arrives over Zenoh. Measured: rows and migrant
    messages sent, stored (thinned, superseded) and per second, each stored row's lag, the longest gaps
    between commits and between stop-rule checks, the deepest inbox and this process's RSS every ``rss_every_s``
    (from before the islands joined)."""
    with tempfile.TemporaryDirectory(prefix="hysid-bench-") as tmp:
        c = coordinator(Path(tmp), "load")
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        session = open_session(session_config("router", listen=[endpoint]), endpoint)
        link = ZenohLink(session, c)
        secret = c.secret.write(Path(tmp) / "load.secret")
        rss: list[tuple[float, float]] = []
        baseline = rss_now_mb()
        feeder = simulated(endpoint, secret, islands, seconds)
        sampled = threading.Event()
        try:
            ready: dict[str, Any] = {}
            reader = threading.Thread(target=lambda: ready.update(line(feeder, "ready")), daemon=True)
            reader.start()
            while reader.is_alive():  # the islands join, then make their messages
                pump(c, link, 0.2)
            if not ready:
                raise RuntimeError("the simulated islands did not get ready")
            start = ready["ready"]
            started = time.monotonic() + start - time.time()
            commits, checks = Gaps(started, started + seconds), Gaps(started, started + seconds)
            commit = c.store.commit

            def timed_commit(campaign: str | None = None, elapsed_s: float = 0.0) -> None:
                commit(campaign, elapsed_s)
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

            threading.Thread(target=sample, daemon=True).start()
            reason = serve(c, link, shown, progress_every_s=0.0)
            elapsed = time.monotonic() - started
            done = line(feeder, "done")
        finally:
            sampled.set()
            if feeder.poll() is None:
                assert feeder.stdin is not None
                feeder.stdin.write("\n")
                feeder.stdin.flush()
                try:
                    feeder.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    feeder.kill()
                    feeder.wait()
            link.close()
            session.close()
        stored = c.store.db.execute("SELECT island, iteration, t FROM history WHERE campaign = 'load'").fetchall()
        lag = row_lags(stored, done["islands"])
        history_rows = c.store.count("history", "load")
        thinned = sum(c.store.thinned("load").values())
        unfollowed = c.store.unfollowed("load")
        peak = max(m for _, m in rss)
        return {
            "islands": islands, "seconds": seconds, "elapsed_s": elapsed, "stop_reason": reason, "rate_per_island": RATE, "interval": INTERVAL,
            "history_period_s": history_period(HISTORY_EVERY_S, islands),
            "rows_sent": done["rows"], "history_rows": history_rows, "rows_thinned": thinned, "rows_lost": done["rows"] - history_rows - thinned,
            "rows_per_s": history_rows / seconds, "rows_sent_per_s": done["rows"] / seconds,
            "history_messages_sent": done["history_messages"], "migrant_messages_sent": done["migrant_messages"], "migrations": c.migrations,
            "migrant_messages_superseded": c.superseded, "migrant_messages_per_s": c.migrations / seconds,
            "migrants_unfollowed_at_islands": None if unfollowed is None else unfollowed["islands"],
            "migrant_messages_sent_per_s": done["migrant_messages"] / seconds,
            "row_lag_s": {"p50": float(np.percentile(lag, 50)), "p95": float(np.percentile(lag, 95)), "max": float(np.max(lag))},
            "sending_late_p95_s": done["late_p95_s"],
            "commits": commits.ticks, "max_commit_gap_s": commits.longest, "max_stop_check_gap_s": checks.longest,
            "deepest_inbox": deepest[0], "rejected": c.rejected, "storage_holds_rows_per_s": c.policy.holds if np.isfinite(c.policy.holds) else None,
            "rss_before_mb": baseline, "rss_mb": peak, "rss_mb_per_island": peak / islands, "rss_added_mb_per_island": (peak - baseline) / islands,
            "rss_samples": rss,
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
    late = samples[(samples[:, 0] >= settle_s) & (samples[:, 0] <= seconds)]
    return {**r, "settle_s": settle_s, "rss_first_mb": float(samples[0, 1]), "rss_settled_mb": float(late[0, 1]),
            "rss_last_mb": float(late[-1, 1]), "rss_slope_mb_per_min": float(np.polyfit(late[:, 0], late[:, 1], 1)[0] * 60.0),
            "rss_every_10_s": [[round(t), round(m, 1)] for t, m in samples[::10]]}


RAMP = (32, 64, 128, 256, 512, 1024, 2048)
LAG_LIMIT_S = 1.0
"""A row stored more than this after it was sent (p95) means the coordinator lags."""
MB_PER_ISLAND = 1.0
"""The coordinator's memory target: this process's resident memory over the islands."""


def lags(r: dict[str, Any]) -> bool:
    """Whether the coordinator fell behind: p95 row lag above ``LAG_LIMIT_S``, or a row sent neither stored nor thinned."""
    return r["row_lag_s"]["p95"] > LAG_LIMIT_S or r["rows_lost"] != 0


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
            "degrades_at_islands": results[-1]["islands"] if lags(results[-1]) else None, "mb_per_island_limit": MB_PER_ISLAND}


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


HOST_ISLANDS = 64
HOST_ITERATIONS = 40
HOST_SETTINGS = ["--iterations", str(HOST_ITERATIONS), "--population", "30", "--initial", "60", "--interval", "0", "--share", "fixed", "--no-polish"]
"""Isolated islands with a budget of their own, each keeping its algorithm: its seed alone decides its search."""
SEPARATE_AT_ONCE = 16
"""Island processes started together in the comparison (a campaign each), so that the machine's memory holds them."""
MB_PER_HOSTED_ISLAND = 25.0


class Watched:
    """A process whose peak resident memory (``VmHWM``) and CPU time are read every 0.1 s until it ends."""

    def __init__(self, process: subprocess.Popen) -> None:
        self.process = process
        self.peak_mb = 0.0
        self.cpu_s = 0.0
        self._thread = threading.Thread(target=self._watch, daemon=True)
        self._thread.start()

    def _watch(self) -> None:
        tick = os.sysconf("SC_CLK_TCK")
        while self.process.poll() is None:
            try:
                with open(f"/proc/{self.process.pid}/status", encoding="utf-8") as status:
                    self.peak_mb = next(int(x.split()[1]) for x in status if x.startswith("VmHWM:")) / 1024.0
                with open(f"/proc/{self.process.pid}/stat", encoding="utf-8") as stat:
                    fields = stat.read().rsplit(")", 1)[1].split()
                    self.cpu_s = (int(fields[11]) + int(fields[12])) / tick
            except (OSError, StopIteration, IndexError):
                pass
            time.sleep(0.1)

    def wait(self, timeout_s: float) -> int:
        code = self.process.wait(timeout=timeout_s)
        self._thread.join()
        return code


def hysid_process(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "hysid", *args], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def host_campaign(workdir: Path, name: str, islands: list[tuple[str, int]], hosted: bool) -> tuple[dict[str, Any], list[Watched]]:
    """One campaign of isolated islands ``(id, seed)``: in one process (``hosted``, ids ``h-k``, seeds from the
    first) or one process each; every island's answer (iterations, evaluations, best fitness and vector) and
    stored rows (iteration -> best, evaluations), and the processes."""
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", workdir / f"{name}.sqlite"
    coordinator = hysid_process("coordinator", "--listen", endpoint, "--campaign", name, "--db", str(db), "--out", str(workdir / name), "--quiet",
                                "--min-islands", str(len(islands)), *HOST_SETTINGS, "synth")
    secret = secret_path(db, name)
    common = ["--connect", endpoint, "--campaign", name, "--secret-file", str(secret), "--wait", "120", "--quiet"]
    try:
        wait_for_secret(secret, 60)
        if hosted:
            processes = [Watched(hysid_process("island", *common, "--id", "h", "--count", str(len(islands)), "--seed", str(islands[0][1])))]
        else:
            processes = [Watched(hysid_process("island", *common, "--id", i, "--seed", str(seed))) for i, seed in islands]
        for w in processes:
            if w.wait(600) != 0:
                raise RuntimeError(f"island process exited with {w.process.returncode}: {w.process.stderr.read().strip()[-300:] if w.process.stderr else ''}")
        if coordinator.wait(timeout=120) != 0:
            raise RuntimeError(f"coordinator exited with {coordinator.returncode}: {coordinator.stderr.read().strip()[-300:] if coordinator.stderr else ''}")
    finally:
        for p in (coordinator, *(w.process for w in locals().get("processes", []))):
            if p.poll() is None:
                p.kill()
                p.wait()
    with sqlite3.connect(db) as con:
        found: dict[str, Any] = {island: {"answer": tuple(answer), "rows": {}} for island, *answer in con.execute(
            "SELECT island, iterations, evaluations, best_fitness, best_x FROM islands WHERE campaign = ?", (name,))}
        for island, iteration, *row in con.execute("SELECT island, iteration, best_fitness, evaluations FROM history WHERE campaign = ?", (name,)):
            found[island]["rows"][iteration] = tuple(row)
    return found, processes


def host(islands: int = HOST_ISLANDS) -> dict[str, Any]:
    """``islands`` isolated, seeded islands in one process, then each in a process of its own
    (:data:`SEPARATE_AT_ONCE` at a time): peak resident memory per island, CPU time, and whether each
    island's stored rows are the same either way."""
    specs = [(f"h-{k}", 100 + k) for k in range(islands)]
    with tempfile.TemporaryDirectory(prefix="hysid-bench-") as tmp:
        started = time.monotonic()
        together, [hosted] = host_campaign(Path(tmp), "hosted", specs, hosted=True)
        hosted_s = time.monotonic() - started
        alone: dict[str, Any] = {}
        separate: list[Watched] = []
        started = time.monotonic()
        for k in range(0, islands, SEPARATE_AT_ONCE):
            rows, processes = host_campaign(Path(tmp), f"alone{k}", specs[k : k + SEPARATE_AT_ONCE], hosted=False)
            alone.update(rows)
            separate += processes
        separate_s = time.monotonic() - started
    same = [i for i, _ in specs if i in together and i in alone and together[i]["answer"] == alone[i]["answer"]]
    both = [(together[i]["rows"], alone[i]["rows"]) for i, _ in specs if i in together and i in alone]
    rows_same = sum(a[it] == b[it] for a, b in both for it in a.keys() & b.keys())
    single = float(np.median([w.peak_mb for w in separate]))
    return {
        "islands": islands, "iterations": HOST_ITERATIONS, "host_peak_rss_mb": hosted.peak_mb, "host_rss_mb_per_island": hosted.peak_mb / islands,
        "island_process_peak_rss_mb": single, "memory_ratio": single / (hosted.peak_mb / islands), "mb_per_island_limit": MB_PER_HOSTED_ISLAND,
        "host_cpu_s": hosted.cpu_s, "separate_cpu_s": sum(w.cpu_s for w in separate), "host_wall_s": hosted_s, "separate_wall_s": separate_s,
        "separate_at_once": SEPARATE_AT_ONCE, "same_answers": len(same),
        "rows_compared": sum(len(a.keys() & b.keys()) for a, b in both), "same_rows": rows_same,
    }


def run(seconds: float = 10.0, sustain_s: float = 180.0, ramp_s: float = 12.0) -> dict[str, Any]:
    """A coordinator with 32 islands (gaps, memory over 3 minutes), more islands until it lags, a backlog, an island under a
    migrant flood; 64 islands in one process (memory, same answers)."""
    return {"load": load(seconds), "sustain": sustain(sustain_s), "ramp": ramp(seconds=ramp_s), "backlog": backlog(), "flood": flood(),
            "host": host()}


def to_text(r: dict[str, Any]) -> str:
    lo, su, ra, bl, fl, ho = r["load"], r["sustain"], r["ramp"], r["backlog"], r["flood"], r["host"]

    def traffic(x: dict[str, Any]) -> str:
        return (f"{x['islands']} islands for {x['elapsed_s']:.1f} s: {x['rows_per_s']:,.0f} rows/s stored of {x['rows_sent_per_s']:,.0f} sent "
                f"({x['rows_thinned']:,} thinned, {x['rows_lost']} lost), {x['migrant_messages_per_s']:,.0f} migrant messages/s handled of "
                f"{x['migrant_messages_sent_per_s']:,.0f} ({x['migrant_messages_superseded']:,} superseded"
                + (f"; not followed once {x['migrants_unfollowed_at_islands']} islands were alive" if x.get("migrants_unfollowed_at_islands") else "")
                + f"); row lag p50 "
                f"{x['row_lag_s']['p50']:.3f} s, p95 {x['row_lag_s']['p95']:.3f} s; longest gap between commits {x['max_commit_gap_s']:.3f} s, "
                f"between stop-rule checks {x['max_stop_check_gap_s']:.3f} s; deepest inbox {x['deepest_inbox']}; "
                f"RSS {x['rss_mb']:.0f} MB ({x['rss_mb_per_island']:.2f} MB per island)")

    return "\n".join([
        f"load: {traffic(lo)}",
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
        f"host: {ho['islands']} islands in one process: peak RSS {ho['host_peak_rss_mb']:.0f} MB, {ho['host_rss_mb_per_island']:.1f} MB per island "
        f"(an island process: {ho['island_process_peak_rss_mb']:.0f} MB, x {ho['memory_ratio']:.0f}); CPU {ho['host_cpu_s']:.0f} s against "
        f"{ho['separate_cpu_s']:.0f} s as separate processes; the same answer in {ho['same_answers']} of {ho['islands']} islands, "
        f"the same rows in {ho['same_rows']:,} of {ho['rows_compared']:,} stored both times",
    ])
