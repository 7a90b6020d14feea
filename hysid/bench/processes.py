"""``hysid bench coordinator``'s parts with processes of their own: commit gaps, an island under a flood, islands many to a process.

* **commits**: a coordinator in this process (a real SQLite file, listening on loopback), one island process
  searching and, in a second run, a joined island in a third process flooding :data:`FLOOD_PER_S` valid migrant
  messages of 256 new migrants each a second (each one the coordinator re-evaluates): the gaps between two commits
  over :data:`COMMITS_S` (target: at most :data:`coordinator.loop.COMMIT_EVERY_S`, with and without the flood),
  measured on the cores this process may run on (the figure depends on them: two in the committed results);
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
import zenoh

from coordinator.launch import free_port
from coordinator.links import ZenohLink
from coordinator.loop import COMMIT_EVERY_S, serve
from coordinator.state import Coordinator
from coordinator.store import Store
from hysid.bench.relay import when_ready
from hysid_model.synth import synth_loops
from island.config import CampaignConfig, decode_config
from island.island_messages import Migrants, encode_migrants
from island.joining import fetch_config, join
from island.migration import Migration
from island.node import IslandNode
from island.secret import CampaignSecret, secret_path
from island.session import open_session, session_config
from island.termination import Termination
from island.transports import ZenohTransport

SIZES = {a: {"population": 20, "initial_population": 40, "iterations": 10**9} for a in ("ga", "pso")}
"""Islands of the benches: the default sizes of a PSO island on the Synth set, an endless budget."""


def coordinator(workdir: Path, name: str, termination: Termination | None = None) -> Coordinator:
    """A coordinator of campaign ``name`` on the Synth set (islands of :data:`SIZES`, migrating every 5 iterations) in
    this process, its database in ``workdir``."""
    loops = synth_loops(n_points=30)
    config = CampaignConfig.create(loops, name=name, options=SIZES, migration=Migration(interval=5, k=2))
    return Coordinator(Store(workdir / f"{name}.sqlite"), config, loops, termination)


def listening(workdir: Path, name: str) -> tuple[Coordinator, str, zenoh.Session, ZenohLink, Path]:
    """A coordinator of campaign ``name`` (:func:`coordinator`) listening on a free loopback port: it, the endpoint, its
    session and link, and the file of its secret (in ``workdir``)."""
    c = coordinator(workdir, name)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = open_session(session_config("router", listen=[endpoint]), endpoint)
    return c, endpoint, session, ZenohLink(session, c), c.secret.write(workdir / f"{name}.secret")


FLOOD_PER_S = 250.0
"""Migrant messages a second of the commits part's flood (256 new migrants each: 64,000 candidates a second to check)."""
COMMITS_S = 20.0
"""How long the commits part watches, with and without the flood."""


def commit_gaps(flood: bool, seconds: float = COMMITS_S) -> dict[str, Any]:
    """The gaps between commits of a coordinator in this process serving one island process, for ``seconds`` once the
    island reports; with ``flood``, while a joined island floods (:func:`flooder`, varied migrants)."""
    with tempfile.TemporaryDirectory(prefix="hysid-bench-") as tmp:
        c, endpoint, session, link, secret = listening(Path(tmp), "gaps")
        island = subprocess.Popen(
            [sys.executable, "-m", "hysid", "island", "--connect", endpoint, "--campaign", "gaps", "--id", "a", "--secret-file", str(secret), "--quiet"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        stamps: list[float] = []
        commit = c.store.commit

        def stamped(campaign: str | None = None, elapsed_s: float = 0.0) -> None:
            commit(campaign, elapsed_s)
            if campaign is not None:  # the run loop's commits, with the heartbeat (a join commits too)
                stamps.append(time.monotonic())

        c.store.commit = stamped  # type: ignore[method-assign]
        window: list[float] = []
        started: list[threading.Thread] = []
        floods: list[subprocess.Popen] = []

        handled: list[int] = []

        def begin() -> None:  # in a thread of its own: the coordinator admits the flooder meanwhile
            if flood:
                floods.append(start_flooder(endpoint, secret, FLOOD_PER_S, varied=True))
            window.append(time.monotonic())

        def stop() -> str | None:
            if not started and c.store.count("history", "gaps") > 10:  # the island searches: the watch begins
                started.append(threading.Thread(target=begin, daemon=True))
                started[0].start()
            if window and len(handled) == 0:
                handled.append(c.migrations)
            if window and time.monotonic() - window[0] >= seconds:
                handled.append(c.migrations)
                return "watched"
            return None

        try:
            serve(c, link, extra_stop=stop)
        finally:
            for p in (*floods, island):
                if p.poll() is None:
                    p.kill()
                    p.wait()
            link.close()
            session.close()
            c.store.close()
    watched = np.array([t for t in stamps if window and window[0] <= t <= window[0] + seconds])
    gaps = np.diff(watched)
    return {
        "flood": flood,
        "flood_messages_per_s": FLOOD_PER_S if flood else 0,
        "seconds": seconds,
        "commits": int(watched.size),
        "max_gap_s": float(gaps.max()),
        "p99_gap_s": float(np.percentile(gaps, 99)),
        "median_gap_s": float(np.median(gaps)),
        "migrant_messages_per_s": (handled[-1] - handled[0]) / seconds,
        "superseded": c.superseded,
    }


def commits(seconds: float = COMMITS_S) -> dict[str, Any]:
    """The commit gaps without and with a flood (:func:`commit_gaps`), on this process' cores."""
    quiet, flooded = commit_gaps(False, seconds), commit_gaps(True, seconds)
    return {
        "quiet": quiet,
        "flooded": flooded,
        "cores": len(os.sched_getaffinity(0)),
        "target_s": COMMIT_EVERY_S,
        "ok": max(quiet["max_gap_s"], flooded["max_gap_s"]) <= COMMIT_EVERY_S,
    }


def flooder(endpoint: str, secret_file: str, per_s: float = 1000.0, varied: bool = False) -> None:
    """A joined island that floods ``migrants/flooder`` with valid messages of 256 migrants each until killed (run in
    its own process); ``varied``: new random migrants in every message (each one the coordinator re-evaluates), else
    the same ones again."""
    secret = CampaignSecret.read(secret_file)
    campaign = secret.campaign
    session = open_session(session_config("client", connect=[endpoint]), endpoint)
    config, loops = decode_config(fetch_config(session, secret, 30), campaign)
    bounds = config.objective(loops).bounds
    cred = join(session, campaign, "flooder", "pso", 9, secret, 30)
    token = session.liveliness().declare_token(f"hysid/{campaign}/members/flooder")
    publisher = session.declare_publisher(f"hysid/{campaign}/migrants/flooder")
    rng = np.random.default_rng(9)
    x = np.tile(bounds.mean(axis=1), (256, 1))
    print("ready", flush=True)
    seq, started = 0, time.monotonic()
    while token is not None:
        if varied:
            x = bounds[:, 0] + rng.random((256, bounds.shape[0])) * (bounds[:, 1] - bounds[:, 0])
        publisher.put(encode_migrants(Migrants(campaign, "flooder", cred.run, 1, x, np.zeros(256), time.time(), seq), cred))
        seq += 1
        time.sleep(max(0.0, started + seq / per_s - time.monotonic()))


def start_flooder(endpoint: str, secret: Path, per_s: float, varied: bool) -> subprocess.Popen:
    """A process of :func:`flooder`, returned once it joined and floods."""
    flooding = subprocess.Popen(
        [sys.executable, "-c", f"from hysid.bench.processes import flooder; flooder({endpoint!r}, {str(secret)!r}, {per_s!r}, {varied!r})"],
        stdout=subprocess.PIPE,
        text=True,
    )
    return when_ready(flooding, lambda p: f"the flooder did not start ({p.wait()})")


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
            [
                sys.executable,
                "-m",
                "hysid",
                "coordinator",
                "--listen",
                endpoint,
                "--campaign",
                "flood",
                "--db",
                f"{tmp}/f.sqlite",
                "--out",
                f"{tmp}/out",
                "--quiet",
                "--algos",
                "pso",
                "--population",
                "20",
                "--initial",
                "40",
                "--iterations",
                str(iterations),
                "--interval",
                "1",
                "--topology",
                "full",
                "--no-polish",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        flooding = None
        client = open_session(session_config("client", connect=[endpoint], connect_timeout_s=30), endpoint)
        try:
            secret = wait_for_secret(secret_path(f"{tmp}/f.sqlite", "flood"), 30)
            config, loops = decode_config(fetch_config(client, secret, 30), "flood")
            if flood:
                flooding = start_flooder(endpoint, secret_path(f"{tmp}/f.sqlite", "flood"), 1000.0, varied=False)
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
        return {
            "run_s": elapsed,
            "evolution_cpu_s": own,
            "process_cpu_s": process_cpu,
            "iterations": iterations,
            "migrants_evaluated": node.migrant_evaluations,
            "rejected": node.stats["rejected"],
            "received": node.stats["received"],
        }


def flood(iterations: int = 1000) -> dict[str, Any]:
    quiet, flooded = flood_run(iterations, False), flood_run(iterations, True)
    return {
        "quiet": quiet,
        "flooded": flooded,
        "run_time_ratio": flooded["run_s"] / quiet["run_s"],
        "flood_messages_per_s": 1000,
        "most_migrants_allowed": 2 * iterations + 1,
    }  # k = 2 from its one in-neighbour per migration, plus the global best


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
    coordinator = hysid_process(
        "coordinator",
        "--listen",
        endpoint,
        "--campaign",
        name,
        "--db",
        str(db),
        "--out",
        str(workdir / name),
        "--quiet",
        "--min-islands",
        str(len(islands)),
        *HOST_SETTINGS,
        "synth",
    )
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
        found: dict[str, Any] = {
            island: {"answer": tuple(answer), "rows": {}}
            for island, *answer in con.execute("SELECT island, iterations, evaluations, best_fitness, best_x FROM islands WHERE campaign = ?", (name,))
        }
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
        "islands": islands,
        "iterations": HOST_ITERATIONS,
        "host_peak_rss_mb": hosted.peak_mb,
        "host_rss_mb_per_island": hosted.peak_mb / islands,
        "island_process_peak_rss_mb": single,
        "memory_ratio": single / (hosted.peak_mb / islands),
        "mb_per_island_limit": MB_PER_HOSTED_ISLAND,
        "host_cpu_s": hosted.cpu_s,
        "separate_cpu_s": sum(w.cpu_s for w in separate),
        "host_wall_s": hosted_s,
        "separate_wall_s": separate_s,
        "separate_at_once": SEPARATE_AT_ONCE,
        "same_answers": len(same),
        "rows_compared": sum(len(a.keys() & b.keys()) for a, b in both),
        "same_rows": rows_same,
    }
