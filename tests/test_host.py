"""Many islands in one process (island/host.py, ``hysid island --count``): each its own id, run, key, seed and
algorithm; one island's failure leaves the others running; Ctrl-C ends them all cleanly; a seed gives the same
search whether its island shares a process or not.

The coordinator is the real one (in this process on a real SQLite file, or a ``hysid coordinator``
process), the islands speak to it over Zenoh on loopback."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

import coordinator.intake
from coordinator.launch import free_port
from coordinator.links import ZenohLink
from coordinator.loop import serve
from coordinator.state import Coordinator
from coordinator.store import Store
from hysid.campaigns import CampaignResult
from hysid.cli import main
from hysid.report.campaign_text import campaign_progress_line, watch_text
from hysid.watch import snapshot
from hysid_model.errors import HysidInputError
from hysid_model.synth import synth_loops
from island.config import CampaignConfig
from island.host import Hosted, IslandSpec, host_specs, run_islands
from island.migration import Migration
from island.session import open_session, session_config
from island.termination import Termination
from island.turns import Turns
from support import coordinator_args, query, ready, rows_of, secret_file, sizes, wait_for

LOOPS = synth_loops(n_points=30)
SIZES = {a: {"population": 10, "initial_population": 20, "iterations": 12} for a in ("ga", "pso")}
TRIO_ITERATIONS = 200


def config(name: str = "h1", interval: int = 2, min_islands: int = 1, iterations: int = 12) -> CampaignConfig:
    options = {a: {**o, "iterations": iterations} for a, o in SIZES.items()}
    return CampaignConfig.create(LOOPS, name=name, options=options, migration=Migration(interval=interval, k=2), min_islands=min_islands, seed=7)


def test_a_hosts_islands_are_named_seeded_and_mixed_like_separate_islands() -> None:
    cfg = config()
    assert host_specs("node7", 1, cfg, seed=3) == [IslandSpec("node7", "pso", 3)]  # one island: the id as given
    specs = host_specs("node7", 4, cfg, seed=10)
    assert [s.id for s in specs] == ["node7-0", "node7-1", "node7-2", "node7-3"]
    assert [s.seed for s in specs] == [10, 11, 12, 13]
    assert [s.algo for s in specs] == ["ga", "pso", "ga", "pso"]  # the campaign's mix, by seed, as for an island process
    drawn = host_specs("node7", 3, cfg)
    assert len({s.seed for s in drawn}) == 3 and [s.algo for s in drawn] == [cfg.algo_for(s.seed) for s in drawn]
    assert {s.algo for s in host_specs("node7", 3, cfg, algo="ga")} == {"ga"}
    with pytest.raises(HysidInputError, match="count=0"):
        host_specs("node7", 0, cfg)


@pytest.mark.parametrize(
    "count, message", [("0", "--count '0': must be from 1 to 4096 islands (or 'cores')"), ("many", "--count 'many': must be a number of islands or 'cores'")]
)
def test_a_bad_count_is_a_one_line_error(count: str, message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["island", "--count", count, "--campaign", "h1"]) == 2
    err = capsys.readouterr().err
    assert err == f"hysid: error: {message}\n"


def test_islands_take_turns_to_compute_in_the_order_they_asked() -> None:
    """One turn, three islands queued behind it: they compute one after the other, always in the same
    order (none twice while another waits), until each has had its 20 turns."""
    turns = Turns(1)
    order: list[str] = []

    def island(name: str) -> None:
        turns.acquire()
        for _ in range(20):
            order.append(name)  # only the island holding the turn gets here
            turns.next()
        turns.release()

    turns.acquire()
    threads = [threading.Thread(target=island, args=(n,)) for n in "abc"]
    for t in threads:
        t.start()
    wait_for(lambda: len(turns._waiting) == 3, 10, "all three islands to queue")
    turns.release()
    for t in threads:
        t.join(10)
    assert sorted(order[:3]) == ["a", "b", "c"] and order == order[:3] * 20


class Campaign:
    """A coordinator in this process (real SQLite, Zenoh router on loopback) serving until :meth:`end`."""

    def __init__(self, tmp_path: Path, cfg: CampaignConfig, termination: Termination | None = None) -> None:
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.router = open_session(session_config("router", listen=[self.endpoint]), self.endpoint)
        self.c = Coordinator(Store(tmp_path / f"{cfg.name}.sqlite"), cfg, LOOPS, termination)
        self.link = ZenohLink(self.router, self.c)
        self._done = threading.Event()
        self.thread = threading.Thread(target=lambda: serve(self.c, self.link, extra_stop=lambda: "ended" if self._done.is_set() else None))
        self.thread.start()
        self.client = open_session(session_config("client", connect=[self.endpoint]), self.endpoint)

    def islands(self, specs: list[IslandSpec], **kwargs) -> list[Hosted]:
        return run_islands(self.client, self.c.secret, self.c.config, LOOPS, specs, wait_s=20.0, history_every_s=0.05, **kwargs)

    def end(self) -> None:
        self._done.set()
        self.thread.join(30)
        self.client.close()
        self.link.close()
        self.router.close()
        self.c.store.close()


@pytest.fixture
def campaign(tmp_path: Path) -> Iterator[Campaign]:
    running = Campaign(tmp_path, config())
    yield running
    running.end()


@pytest.fixture
def trio(tmp_path: Path) -> Iterator[Campaign]:
    """A campaign whose islands start once three have joined (so that they search, and migrate, together:
    long enough for migrants to cross the network between them however loaded the machine)."""
    running = Campaign(tmp_path, config(min_islands=3, iterations=TRIO_ITERATIONS))
    yield running
    running.end()


@pytest.mark.slow  # over 3 s (fast lane, 2 cores, 2026-11-29)
def test_each_island_of_a_process_joins_as_its_own_run_with_its_own_key_and_reports_everything(trio: Campaign) -> None:
    campaign = trio
    specs = host_specs("h", 3, campaign.c.config, seed=20)
    hosted = campaign.islands(specs, turns=2)
    assert all(h.error is None and h.node is not None and h.node.confirmed for h in hosted)
    runs = query(Path(campaign.c.store.path), "SELECT island, run, key, algo, seed FROM runs ORDER BY island")
    assert [(i, a, s) for i, _, _, a, s in runs] == [("h-0", "ga", 20), ("h-1", "pso", 21), ("h-2", "ga", 22)]
    assert len({r for _, r, _, _, _ in runs}) == 3 and len({k for _, _, k, _, _ in runs}) == 3  # a run and a signing key each
    assert {h.node.credentials.public for h in hosted} == {bytes(k) for _, _, k, _, _ in runs}
    for h in hosted:
        assert [r[0] for r in h.node.rows] == list(range(TRIO_ITERATIONS + 1))
        assert rows_of(Path(campaign.c.store.path), h.spec.id) == TRIO_ITERATIONS + 1  # every row of every island stored
        assert h.node.stats["received"] > 0 and h.node.stats["rejected"] == 0  # they migrate to one another
    assert {e for i, e in query(Path(campaign.c.store.path), "SELECT island, event FROM members")} == {"join", "left"}


@pytest.mark.slow  # over 3 s (fast lane, 2 cores, 2026-11-29)
def test_a_coordinator_of_more_islands_than_it_follows_leaves_migration_to_them_and_says_so(trio: Campaign, monkeypatch: pytest.MonkeyPatch) -> None:
    """Past :data:`coordinator.intake.FOLLOWS_MIGRANTS_UP_TO` islands alive (2 here) the coordinator stops
    subscribing to migrant messages before the islands start; they still migrate to one another, report
    their counts, and the result says who counted what."""
    campaign = trio
    monkeypatch.setattr(coordinator.intake, "FOLLOWS_MIGRANTS_UP_TO", 2)
    hosted = campaign.islands(host_specs("h", 3, campaign.c.config, seed=20), turns=2)
    assert all(h.error is None and h.node is not None and h.node.confirmed for h in hosted)
    assert not campaign.link.follows_migrants and not campaign.c.follows_migrants
    assert campaign.c.store.count("migrations", "h1") == 0  # it stopped once the third joined, before they searched
    unfollowed = campaign.c.store.unfollowed("h1")
    assert unfollowed is not None and (unfollowed["islands"], unfollowed["up_to"]) == (3, 2)
    assert all(h.node.stats["sent"] > 0 and h.node.stats["received"] > 0 for h in hosted)  # island to island
    assert "| migrations 0 (then island to island) |" in campaign_progress_line(campaign.c.progress())
    assert "migrant messages 0 (then island to island)" in watch_text(snapshot(campaign.c.store, "h1"))  # hysid watch, from the database
    campaign.thread.join(30)  # every island finished: the coordinator's loop ends
    assert campaign.c.stop_reason == "every island finished"
    result = CampaignResult.from_outcome(campaign.c.outcome(polish_best=False))
    m = result.migrations
    assert m["messages"] == 0 and m["sent"] == sum(h.node.stats["sent"] for h in hosted) and m["unfollowed"]["islands"] == 3
    assert "0 messages handled by the coordinator (ring, every 2 iterations) until 3 islands were alive" in result.summary()
    assert f"by the islands' own counts {m['sent']:,} messages sent" in result.summary()


def test_one_islands_failure_does_not_end_the_others(campaign: Campaign) -> None:
    """Island h-1 is refused (its id is taken by a running island): it ends, h-0 and h-2 run to their end."""
    campaign.c.join("h-1", "pso", 0)  # a run of h-1, alive, before the host starts
    campaign.c.membership.stale_s = 2.0  # which never speaks: lost soon, so that the campaign need not wait for it at its end
    said: list[str] = []
    hosted = campaign.islands(host_specs("h", 3, campaign.c.config, seed=20), notify=said.append)
    failed = [h for h in hosted if h.error is not None]
    assert [h.spec.id for h in failed] == ["h-1"] and isinstance(failed[0].error, HysidInputError)
    assert "is taken by a running island" in str(failed[0].error)
    assert any(line.startswith("island h-1 failed: ") and "the other islands of this process carry on" in line for line in said)
    for h in (hosted[0], hosted[2]):
        assert h.node is not None and [r[0] for r in h.node.rows] == list(range(13)) and h.node.confirmed


@pytest.mark.slow
def test_a_seed_searches_alike_in_a_shared_process_and_alone(tmp_path: Path) -> None:
    """Isolated islands (interval 0) take nothing from others: each seed gives the same rows (iteration,
    best, evaluations) whether its island shares a process with others or runs alone."""
    cfg = config("same", interval=0)
    specs = host_specs("s", 3, cfg, seed=40)
    (tmp_path / "shared").mkdir()
    shared = Campaign(tmp_path / "shared", cfg)
    try:
        together = shared.islands(specs, turns=2)
    finally:
        shared.end()
    alone = []
    for spec in specs:
        where = tmp_path / spec.id
        where.mkdir()
        single = Campaign(where, cfg)
        try:
            alone += single.islands([spec])
        finally:
            single.end()
    for a, b in zip(together, alone):
        assert a.node is not None and b.node is not None and a.error is None and b.error is None
        assert [r[:3] for r in a.node.rows] == [r[:3] for r in b.node.rows]
        assert a.node.optimizer.best(1)[1][0] == b.node.optimizer.best(1)[1][0]


@pytest.mark.slow
def test_ctrl_c_ends_every_island_of_a_process_cleanly(spawn, tmp_path: Path) -> None:
    """SIGINT to ``hysid island --count 3``: every island stops, sends its last history (each run ends
    ``final`` and ``left``), the coordinator confirms, and the process exits with 130 in seconds."""
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "c.sqlite"
    coordinator = spawn(
        *coordinator_args(endpoint, "ctrlc", db, tmp_path / "out"),
        "--quiet",
        *sizes(10, 20, 1000000),
        "--interval",
        "2",
        "--no-polish",
        "synth",
    )
    ready(endpoint, "ctrlc")
    host = spawn("island", "--connect", endpoint, "--campaign", "ctrlc", "--id", "h", "--count", "3", "--secret-file", secret_file(db, "ctrlc"))
    wait_for(lambda: all(rows_of(db, f"h-{k}") > 5 for k in range(3)), 60, "three islands reporting")
    host.send_signal(signal.SIGINT)
    _, err = host.communicate(timeout=30)
    assert host.returncode == 130, err
    assert "3 island(s) of this process interrupted" in err and err.rstrip().endswith("hysid: error: interrupted")
    finals = query(db, "SELECT island, final, iterations FROM islands ORDER BY island")
    assert [(i, f) for i, f, _ in finals] == [("h-0", 1), ("h-1", 1), ("h-2", 1)]
    assert all(rows_of(db, i) == n + 1 for i, _, n in finals)  # every row, up to the last
    assert [e for _, e in query(db, "SELECT island, event FROM members WHERE island = 'h-1' ORDER BY id")] == ["join", "left"]
    assert coordinator.poll() is None  # the campaign goes on without them
