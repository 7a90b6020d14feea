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
  :data:`coordinator.intake.FOLLOWS_MIGRANTS_UP_TO` islands: then it no longer follows them), and the coordinator's memory
  (this process's resident memory over the islands: target 1 MB per island at most);
* **backlog**: 32 islands with a backlog of 6400 messages queued at once and a budget spent after about a
  quarter of them: seconds from the start to the stop decision and how much was still queued (it must not
  drain the queue first);
* **commits**, **flood**, **host**: with processes of their own (:mod:`hysid.bench.processes`): the longest
  gap between two commits with and without a migrant flood, an island under a flood, islands many to a process.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from coordinator.links import MemoryLink
from coordinator.loop import pump, serve
from hysid.bench.processes import commits, coordinator, flood, host, listening
from island.island_messages import History, encode_history
from island.node import HISTORY_EVERY_S, history_period
from island.termination import Termination

ISLANDS = 32
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
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
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
        c, endpoint, session, link, secret = listening(Path(tmp), "load")
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
            "islands": islands,
            "seconds": seconds,
            "elapsed_s": elapsed,
            "stop_reason": reason,
            "rate_per_island": RATE,
            "interval": INTERVAL,
            "history_period_s": history_period(HISTORY_EVERY_S, islands),
            "rows_sent": done["rows"],
            "history_rows": history_rows,
            "rows_thinned": thinned,
            "rows_lost": done["rows"] - history_rows - thinned,
            "rows_per_s": history_rows / seconds,
            "rows_sent_per_s": done["rows"] / seconds,
            "history_messages_sent": done["history_messages"],
            "migrant_messages_sent": done["migrant_messages"],
            "migrations": c.migrations,
            "migrant_messages_superseded": c.superseded,
            "migrant_messages_per_s": c.migrations / seconds,
            "migrants_unfollowed_at_islands": None if unfollowed is None else unfollowed["islands"],
            "migrant_messages_sent_per_s": done["migrant_messages"] / seconds,
            "row_lag_s": {"p50": float(np.percentile(lag, 50)), "p95": float(np.percentile(lag, 95)), "max": float(np.max(lag))},
            "sending_late_p95_s": done["late_p95_s"],
            "commits": commits.ticks,
            "max_commit_gap_s": commits.longest,
            "max_stop_check_gap_s": checks.longest,
            "deepest_inbox": deepest[0],
            "rejected": c.rejected,
            "storage_holds_rows_per_s": c.policy.holds if np.isfinite(c.policy.holds) else None,
            "rss_before_mb": baseline,
            "rss_mb": peak,
            "rss_mb_per_island": peak / islands,
            "rss_added_mb_per_island": (peak - baseline) / islands,
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
    return {
        **r,
        "settle_s": settle_s,
        "rss_first_mb": float(samples[0, 1]),
        "rss_settled_mb": float(late[0, 1]),
        "rss_last_mb": float(late[-1, 1]),
        "rss_slope_mb_per_min": float(np.polyfit(late[:, 0], late[:, 1], 1)[0] * 60.0),
        "rss_every_10_s": [[round(t), round(m, 1)] for t, m in samples[::10]],
    }


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
    return {
        "steps": results,
        "lag_limit_s": LAG_LIMIT_S,
        "held_at_islands": max(held, default=None),
        "degrades_at_islands": results[-1]["islands"] if lags(results[-1]) else None,
        "mb_per_island_limit": MB_PER_ISLAND,
    }


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
        return {
            "queued": queued,
            "budget": budget,
            "stop_reason": reason,
            "stop_decided_s": decided_s,
            "still_queued_at_stop": left,
            "stop_checks_before": sum(1 for s in seen if s[1] < budget),
        }


PARTS = ("load", "sustain", "ramp", "backlog", "commits", "flood", "host")


def run(seconds: float = 10.0, sustain_s: float = 180.0, ramp_s: float = 12.0, parts: tuple[str, ...] = PARTS) -> dict[str, Any]:
    """A coordinator with 32 islands (gaps, memory over 3 minutes), more islands until it lags, a backlog, commit gaps with and
    without a flood, an island under a migrant flood; 64 islands in one process (memory, same answers)."""
    benches = {
        "load": lambda: load(seconds),
        "sustain": lambda: sustain(sustain_s),
        "ramp": lambda: ramp(seconds=ramp_s),
        "backlog": backlog,
        "commits": commits,
        "flood": flood,
        "host": host,
    }
    return {part: benches[part]() for part in parts}


def _traffic(x: dict[str, Any]) -> str:
    """A load's (or a ramp step's) rows, migrants, lags, gaps and memory."""
    return (
        f"{x['islands']} islands for {x['elapsed_s']:.1f} s: {x['rows_per_s']:,.0f} rows/s stored of {x['rows_sent_per_s']:,.0f} sent "
        f"({x['rows_thinned']:,} thinned, {x['rows_lost']} lost), {x['migrant_messages_per_s']:,.0f} migrant messages/s handled of "
        f"{x['migrant_messages_sent_per_s']:,.0f} ({x['migrant_messages_superseded']:,} superseded"
        + (f"; not followed once {x['migrants_unfollowed_at_islands']} islands were alive" if x.get("migrants_unfollowed_at_islands") else "")
        + f"); row lag p50 "
        f"{x['row_lag_s']['p50']:.3f} s, p95 {x['row_lag_s']['p95']:.3f} s; longest gap between commits {x['max_commit_gap_s']:.3f} s, "
        f"between stop-rule checks {x['max_stop_check_gap_s']:.3f} s; deepest inbox {x['deepest_inbox']}; "
        f"RSS {x['rss_mb']:.0f} MB ({x['rss_mb_per_island']:.2f} MB per island)"
    )


def _ramp_text(ra: dict[str, Any]) -> list[str]:
    steps = [f"ramp: {_traffic(x)}{' <- lags' if lags(x) else ''}" for x in ra["steps"]]
    return [*steps, f"ramp: held {ra['held_at_islands']} islands; degrades at {ra['degrades_at_islands'] or 'none of the steps'}"]


def _commits_text(co: dict[str, Any]) -> list[str]:
    return [
        f"commits: {'under ' + format(x['flood_messages_per_s'], ',.0f') + ' migrant messages/s of 256 new migrants' if x['flood'] else 'no flood'}, "
        f"{x['seconds']:g} s on {co['cores']} cores: {x['commits']} commits, longest gap {x['max_gap_s']:.3f} s (p99 {x['p99_gap_s']:.3f} s, "
        f"median {x['median_gap_s']:.3f} s; target {co['target_s']:g} s); {x['migrant_messages_per_s']:,.0f} migrant messages/s handled, "
        f"{x['superseded']:,} superseded"
        for x in (co["quiet"], co["flooded"])
    ]


TEXT = {
    "load": lambda x: [f"load: {_traffic(x)}"],
    "sustain": lambda su: [
        f"sustain: {_traffic(su)}; RSS {su['rss_first_mb']:.0f} MB at the start, {su['rss_settled_mb']:.0f} MB after {su['settle_s']:g} s, "
        f"{su['rss_last_mb']:.0f} MB at the end: slope {su['rss_slope_mb_per_min']:+.2f} MB/min"
    ],
    "ramp": _ramp_text,
    "backlog": lambda bl: [
        f"backlog: {bl['queued']} messages queued; {bl['stop_reason']} decided after {bl['stop_decided_s']:.2f} s "
        f"with {bl['still_queued_at_stop']} still queued ({bl['stop_checks_before']} checks before)"
    ],
    "commits": _commits_text,
    "flood": lambda fl: [
        f"flood: an island of {fl['quiet']['iterations']} iterations ran {fl['quiet']['run_s']:.2f} s alone and "
        f"{fl['flooded']['run_s']:.2f} s under {fl['flood_messages_per_s']:,} migrant messages/s of 256 migrants each "
        f"(ratio {fl['run_time_ratio']:.2f}); CPU of its evolution thread {fl['quiet']['evolution_cpu_s']:.2f} -> "
        f"{fl['flooded']['evolution_cpu_s']:.2f} s, of the whole island process {fl['quiet']['process_cpu_s']:.2f} -> "
        f"{fl['flooded']['process_cpu_s']:.2f} s; it re-evaluated {fl['flooded']['migrants_evaluated']} migrants "
        f"(at most {fl['most_migrants_allowed']} allowed)"
    ],
    "host": lambda ho: [
        f"host: {ho['islands']} islands in one process: peak RSS {ho['host_peak_rss_mb']:.0f} MB, {ho['host_rss_mb_per_island']:.1f} MB per island "
        f"(an island process: {ho['island_process_peak_rss_mb']:.0f} MB, x {ho['memory_ratio']:.0f}); CPU {ho['host_cpu_s']:.0f} s against "
        f"{ho['separate_cpu_s']:.0f} s as separate processes; the same answer in {ho['same_answers']} of {ho['islands']} islands, "
        f"the same rows in {ho['same_rows']:,} of {ho['rows_compared']:,} stored both times"
    ],
}
"""Each part's lines of the bench's text, from its part of the result."""


def to_text(r: dict[str, Any]) -> str:
    """One line (or a few) per part that ran, in the order of :data:`PARTS`."""
    return "\n".join(line for part in PARTS if part in r for line in TEXT[part](r[part]))
