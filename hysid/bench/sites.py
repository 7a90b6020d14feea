"""``hysid bench sites``: a multi-site campaign over WAN-like links through Zenoh routers.

Each site is a network namespace (:mod:`hysid.bench.netns`) with its own ``hysid
router`` and island processes connected to it (one island each, or with ``--large``
256 islands in all, 42-43 a process: ``hysid island --count``); the coordinator runs in the hub
namespace, and each site's router dials it over the site's link, impaired as the
:class:`Site` says (delay each way, random loss, one cut and restore). Measured:

* ``detect_s``: from the cut until the coordinator has recorded every island of the
  cut site ``lost`` (their liveliness tokens vanish when the router's lease expires);
* ``back_s``: from the restore until every one of them is ``back`` (the router redials,
  the tokens return);
* ``caught_up_s``: from the restore until the coordinator's history of each of them is
  gapless again and past where it stood at the cut (the rows sent while the link was
  down come back through the coordinator's catch-up queries);
* the answer (best fitness and parameters against the Synth truth), the history rows
  stored against the islands' iterations (no row lost), and the resident memory of
  every island process, router and the coordinator (``VmRSS`` at the cut, the most
  crowded moment).
"""

from __future__ import annotations

import json
import sqlite3
import subprocess
import sys
import tempfile
import time
import zlib
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, TextIO, cast

import numpy as np

from hysid.bench.netns import Lab, NamespacesUnavailable, unavailable
from hysid_model.synth import TRUE_PARAMS
from island.secret import secret_path

ROUTER_CONFIG = Path(__file__).resolve().parents[2] / "deploy" / "sites" / "router.json5"
"""The site router's configuration of the recipe (deploy/GUIDE.md, section 6), in a source checkout."""
PORT = 7447
RELAY_PORT = 7450
CAMPAIGN = "sites"
ISLAND_SETTINGS = ["--iterations", "1000000", "--population", "30", "--initial", "60", "--interval", "5", "--no-polish"]
"""Islands that evolve until the coordinator's time limit (so the cut hits running islands)."""


@dataclass(frozen=True)
class Site:
    """One site: its islands and what its link to the coordinator suffers."""

    islands: int
    delay_ms: float = 0.0
    """Added each way."""
    loss_pct: float = 0.0
    """Packets dropped at random, each way."""
    cut_at_s: float | None = None
    """Seconds after every island joined at which the link goes down (None: never)."""
    cut_for_s: float = 0.0
    per_process: int = 1
    """Islands in each island process of the site (``hysid island --count``)."""


def island_processes(k: int, site: Site) -> list[tuple[str, list[str]]]:
    """Site ``k``'s island processes: each one's ``--id`` and the ids of its islands (``s<k>-i<j>`` for one
    island a process; ``s<k>-h<p>-<j>`` for a process of several, as :func:`island.host.host_specs` names them)."""
    if site.per_process == 1:
        return [(f"s{k}-i{j}", [f"s{k}-i{j}"]) for j in range(1, site.islands + 1)]
    sizes = [min(site.per_process, site.islands - start) for start in range(0, site.islands, site.per_process)]
    return [(f"s{k}-h{p}", [f"s{k}-h{p}-{j}" for j in range(n)]) for p, n in enumerate(sizes, start=1)]


def hysid(lab: Lab, namespace: str, *args: str) -> list[str]:
    return lab.command(namespace, sys.executable, "-m", "hysid", *args)


def rss_mb(pid: int) -> float | None:
    try:
        with open(f"/proc/{pid}/status", encoding="utf-8") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return None


def query(db: Path, sql: str, *params: Any) -> list[tuple]:
    """Read a campaign database, also while a coordinator writes it ([] until its tables exist)."""
    if not db.exists():
        return []
    with sqlite3.connect(db, timeout=10) as con:
        try:
            return con.execute(sql, params).fetchall()
        except sqlite3.OperationalError as exc:
            if "no such table" in str(exc):
                return []
            raise


class Database:
    """The coordinator's SQLite file, read while it writes."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def rows(self, sql: str, *params: Any) -> list[tuple]:
        return query(self.path, sql, *params)

    def events(self, event: str, islands: list[str], after: float = 0.0) -> dict[str, float]:
        """The first ``event`` of each island at or after ``after`` (unix time)."""
        got: dict[str, float] = {}
        for island, t in self.rows("SELECT island, t FROM members WHERE campaign = ? AND event = ? AND t >= ? ORDER BY t", CAMPAIGN, event, after):
            if island in islands:
                got.setdefault(island, t)
        return got

    def history(self, islands: list[str]) -> dict[str, tuple[int, int]]:
        """Rows stored and highest iteration, per island."""
        return {
            i: (n, top)
            for i, n, top in self.rows("SELECT island, COUNT(*), MAX(iteration) FROM history WHERE campaign = ? GROUP BY island", CAMPAIGN)
            if i in islands
        }


def wait_for(what: str, condition: Any, timeout_s: float, processes: list[subprocess.Popen]) -> Any:
    """Poll ``condition()`` every 0.1 s until it returns something true; fail if a process died or time ran out."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if value := condition():
            return value
        if dead := [p for p in processes if p.poll() is not None]:
            raise RuntimeError(f"waiting for {what}: {cast(list[str], dead[0].args)[-8:]} exited with {dead[0].returncode}")
        time.sleep(0.1)
    raise RuntimeError(f"waiting for {what}: nothing after {timeout_s:g} s")


def campaign(sites: list[Site], time_limit_s: float, workdir: Path) -> dict[str, Any]:
    """Run one multi-site campaign in fresh namespaces; the measurements of the module docstring.
    :class:`NamespacesUnavailable` where this machine cannot make them."""
    if reason := unavailable():
        raise NamespacesUnavailable(reason)
    lab = Lab(len(sites))
    processes: list[subprocess.Popen] = []
    try:
        lab.build()
        with (workdir / "coordinator.log").open("w") as log:
            return _campaign(lab, sites, time_limit_s, workdir, processes, log)
    finally:
        for p in reversed(processes):
            if p.poll() is None:
                p.kill()
            p.wait(timeout=10)
        lab.destroy()


def _campaign(lab: Lab, sites: list[Site], time_limit_s: float, workdir: Path, processes: list[subprocess.Popen], log: TextIO) -> dict[str, Any]:
    netem = lab.has_netem()
    impairments: list[dict[str, Any]] = []
    hosts = {k: island_processes(k, site) for k, site in enumerate(sites, start=1)}
    names = {k: [i for _, ids in hosts[k] for i in ids] for k in hosts}
    everyone = [n for group in names.values() for n in group]
    db = Database(workdir / "sites.sqlite")
    coordinator = subprocess.Popen(
        hysid(
            lab,
            lab.hub,
            "coordinator",
            "--listen",
            f"tcp/{lab.hub_address}:{PORT}",
            "--campaign",
            CAMPAIGN,
            "--db",
            str(db.path),
            "--out",
            str(workdir / "out"),
            "--min-islands",
            str(len(everyone)),
            "--time-limit",
            f"{time_limit_s:g}",
            *ISLAND_SETTINGS,
            "--no-figures",  # the bench reads the database, not the report's figures
            "synth",
        ),
        stdout=subprocess.DEVNULL,
        stderr=log,
        cwd=workdir,
    )
    processes.append(coordinator)
    routers, islands = [], []
    for k, site in enumerate(sites, start=1):
        applied: dict[str, Any] = {"site": k, "delay": None, "loss": None, "cut": "ip link set eth0 down/up" if site.cut_at_s is not None else None}
        upstream = f"tcp/{lab.hub_address}:{PORT}"
        if netem and (site.delay_ms or site.loss_pct):
            lab.netem(k, site.delay_ms, site.loss_pct)
            applied["delay"] = applied["loss"] = "tc netem"
        else:
            if site.delay_ms:
                processes.append(lab.delay_relay(k, RELAY_PORT, PORT, site.delay_ms))
                upstream, applied["delay"] = f"tcp/127.0.0.1:{RELAY_PORT}", "userspace TCP relay (hysid.bench.relay)"
            if site.loss_pct:
                why = lab.drop(k, site.loss_pct)
                applied["loss"] = "iptables -m statistic --mode random" if why is None else f"not applied: {why}"
        impairments.append(applied)
        config = ["--config", str(ROUTER_CONFIG)] if ROUTER_CONFIG.is_file() else []
        router = subprocess.Popen(
            hysid(lab, lab.host(k), "router", *config, "--listen", f"tcp/{lab.host_address(k)}:{PORT}", "--connect", upstream),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        processes.append(router)
        assert router.stderr is not None
        ready = router.stderr.readline()
        if " ready " not in ready:
            router.kill()
            raise RuntimeError(f"router of site {k} did not start: {ready.strip()} {router.communicate(timeout=10)[1].strip()[-500:]}")
        routers.append(router)
        for name, ids in hosts[k]:
            count = ["--count", str(len(ids)), "--seed", str(zlib.crc32(name.encode()) % 10**6)] if len(ids) > 1 else []
            island = subprocess.Popen(
                hysid(
                    lab,
                    lab.host(k),
                    "island",
                    "--connect",
                    f"tcp/{lab.host_address(k)}:{PORT}",
                    "--campaign",
                    CAMPAIGN,
                    "--id",
                    name,
                    *count,
                    "--wait",
                    "120",
                    "--quiet",
                    "--secret-file",
                    str(secret_path(db.path, CAMPAIGN)),
                ),
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
                text=True,
            )
            processes.append(island)
            islands.append(island)
    launched = time.monotonic()
    wait_for("every island to join", lambda: len(db.events("join", everyone)) == len(everyone), time_limit_s, [coordinator, *islands])
    t0 = time.time()
    startup_s = time.monotonic() - launched
    links: list[dict[str, Any]] = []
    memory: dict[str, Any] = {}
    for k, site in enumerate(sites, start=1):
        if site.cut_at_s is None:
            continue
        time.sleep(max(0.0, t0 + site.cut_at_s - time.time()))
        memory = {
            "island_rss_mb": [rss_mb(p.pid) for p in islands],
            "router_rss_mb": [rss_mb(p.pid) for p in routers],
            "coordinator_rss_mb": rss_mb(coordinator.pid),
        }
        stood = db.history(names[k])
        lab.link(k, False)
        cut = time.time()
        lost = wait_for(f"site {k} lost", lambda: (e := db.events("lost", names[k], cut)) and len(e) == len(names[k]) and e, 60, [coordinator])  # noqa: B023 (called within this iteration)
        time.sleep(max(0.0, cut + site.cut_for_s - time.time()))
        lab.link(k, True)
        up = time.time()
        back = wait_for(f"site {k} back", lambda: (e := db.events("back", names[k], up)) and len(e) == len(names[k]) and e, 60, [coordinator])  # noqa: B023 (called within this iteration)

        def caught_up() -> float | None:
            now = db.history(names[k])  # noqa: B023 (called within this iteration)
            ok = all(n in now and now[n][0] == now[n][1] + 1 and now[n][1] > stood.get(n, (0, -1))[1] for n in names[k])  # noqa: B023 (called within this iteration)
            return time.time() if ok else None

        links.append(
            {
                "site": k,
                "cut_at_s": cut - t0,
                "cut_for_s": up - cut,
                "detect_s": max(lost.values()) - cut,
                "first_lost_s": min(lost.values()) - cut,
                "back_s": max(back.values()) - up,
                "caught_up_s": wait_for(f"site {k} history caught up", caught_up, 60, [coordinator]) - up,
            }
        )
    for island in islands:
        if island.wait(timeout=time_limit_s + 120) != 0:
            args = cast(list[str], island.args)
            assert island.stderr is not None  # started with stderr=PIPE
            raise RuntimeError(f"island process {args[args.index('--id') + 1]} exited with {island.returncode}: {island.stderr.read().strip()[-300:]}")
    if coordinator.wait(timeout=60) != 0:
        log.flush()
        raise RuntimeError(f"coordinator exited with {coordinator.returncode}: {Path(log.name).read_text().strip()[-500:]}")
    for router in routers:
        router.terminate()
        router.wait(timeout=10)
    result = json.loads((workdir / "out" / "result.json").read_text())
    stored = db.history(everyone)
    by_island = {i["island"]: i for i in result["islands"]}
    best = np.array([result["params"][n] for n in TRUE_PARAMS])
    truth = np.array(list(TRUE_PARAMS.values()))
    return {
        "sites": [asdict(s) for s in sites],
        "islands": len(everyone),
        "island_processes": len(islands),
        "processes": "one island per process" if len(islands) == len(everyone) else f"{len(everyone)} islands in {len(islands)} processes",
        "impairments": impairments,
        "netem": netem,
        "router_config": str(ROUTER_CONFIG.name) if ROUTER_CONFIG.is_file() else "defaults",
        "startup_s": startup_s,
        "time_limit_s": time_limit_s,
        "stop_reason": result["settings"]["stop_reason"],
        "best_fitness": result["fitness"],
        "max_relative_error": float(np.max(np.abs(best - truth) / np.abs(truth))),
        "islands_final": sum(1 for i in by_island.values() if i["final"]),
        "history_rows": sum(n for n, _ in stored.values()),
        "history_rows_missing": sum(by_island[i]["iterations"] + 1 - stored.get(i, (0, 0))[0] for i in everyone),
        "links": links,
        **memory,
        "members": [(i, e) for i, e, _ in db.rows("SELECT island, event, t FROM members WHERE campaign = ? ORDER BY t", CAMPAIGN)],
    }


BENCH_SITES = [Site(11, delay_ms=50.0), Site(11, delay_ms=50.0, loss_pct=1.0, cut_at_s=15.0, cut_for_s=10.0), Site(10)]
"""32 islands on three sites: two behind 50 ms each way, one of them losing 1 % and cut for 10 s."""
LARGE_SITES = [
    Site(86, delay_ms=50.0, per_process=43),
    Site(86, delay_ms=50.0, loss_pct=1.0, cut_at_s=15.0, cut_for_s=10.0, per_process=43),
    Site(84, per_process=42),
]
"""The same three sites with 256 islands, in processes of 42-43 islands each (``hysid island --count``)."""


def run(time_limit_s: float = 120.0, large: bool = False) -> dict[str, Any]:
    """Three sites, 32 islands (``large``: 256, many a process) behind Zenoh routers, 50 ms links, 1 % loss, one link cut and restored."""
    with tempfile.TemporaryDirectory(prefix="hysid-bench-") as tmp:
        return campaign(LARGE_SITES if large else BENCH_SITES, time_limit_s, Path(tmp))


def to_text(r: dict[str, Any]) -> str:
    lines = [
        f"{r['islands']} islands ({r['processes']}) on {len(r['sites'])} sites, started in {r['startup_s']:.1f} s; "
        f"{r['stop_reason']}; best {r['best_fitness']:.3g} (largest relative parameter error {r['max_relative_error']:.2g}); "
        f"{r['islands_final']} islands final; {r['history_rows']:,} history rows, {r['history_rows_missing']} missing",
    ]
    for imp in r["impairments"]:
        lines.append(f"site {imp['site']}: delay {imp['delay'] or '-'}; loss {imp['loss'] or '-'}; cut {imp['cut'] or '-'}")
    for link in r["links"]:
        lines.append(
            f"site {link['site']} cut at {link['cut_at_s']:.1f} s for {link['cut_for_s']:.1f} s: lost after {link['detect_s']:.2f} s "
            f"(first {link['first_lost_s']:.2f} s), back {link['back_s']:.2f} s after the restore, history caught up after {link['caught_up_s']:.2f} s"
        )
    if r.get("island_rss_mb"):
        rss = [m for m in r["island_rss_mb"] if m is not None]
        lines.append(
            f"RSS per island process {np.median(rss):.0f} MB (median; {min(rss):.0f}-{max(rss):.0f}; {r['islands'] / len(rss):.0f} islands each), routers "
            f"{max(m or 0 for m in r['router_rss_mb']):.0f} MB at most, coordinator {r['coordinator_rss_mb']:.0f} MB"
        )
    return "\n".join(lines)
