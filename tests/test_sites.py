"""Multi-site campaigns: ``hysid router`` between a site's islands and the coordinator, WAN-like links.

The router test runs on loopback anywhere; the multi-site test needs network
namespaces (root, iproute2: skipped otherwise, with the reason) and applies each
impairment with the tool this machine has (:mod:`hysid.bench.netns`).
"""

from __future__ import annotations

import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from coordinator.launch import free_port
from hysid.bench.netns import NamespacesUnavailable
from hysid.bench.sites import Site, campaign
from hysid.cli import main
from support import coordinator_args, hysid, query, stderr_read, time_boxed

pytestmark = pytest.mark.timeout(120)
DEPLOY = Path(__file__).resolve().parents[1] / "deploy"
ROUTER_CONFIG = DEPLOY / "sites" / "router.json5"


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--listen", "localhost"], "--listen 'localhost': a Zenoh endpoint looks like tcp/127.0.0.1:7447"),
        (["--config", str(DEPLOY / "zenoh" / "island.json5")], 'island.json5: is not a router configuration (its mode must be "router")'),
        (["--config", "nowhere.json5"], "--config nowhere.json5: no such file"),
    ],
)
def test_bad_router_arguments_are_one_line_errors(argv: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["router", *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("hysid: error: ") and message in err and err.count("\n") == 1


@pytest.mark.slow
def test_the_delay_relay_holds_every_byte_for_its_delay_each_way() -> None:
    echo = socket.create_server(("127.0.0.1", 0))

    def serve() -> None:
        connection, _ = echo.accept()
        with connection:
            while data := connection.recv(65536):
                connection.sendall(data)

    threading.Thread(target=serve, daemon=True).start()
    port = free_port()
    relay = subprocess.Popen(
        [sys.executable, "-m", "hysid.bench.relay", "127.0.0.1", str(port), "127.0.0.1", str(echo.getsockname()[1]), "50"], stdout=subprocess.PIPE, text=True
    )
    try:
        assert relay.stdout.readline().strip() == "ready"
        message = bytes(range(256)) * 400
        with socket.create_connection(("127.0.0.1", port)) as client:
            sent = time.monotonic()
            client.sendall(message)
            got = b""
            while len(got) < len(message):
                got += client.recv(65536)
            elapsed = time.monotonic() - sent
    finally:
        relay.kill()
        relay.wait(timeout=10)
        echo.close()
    assert got == message
    assert elapsed >= 0.1  # 50 ms there and 50 ms back: a relay cannot deliver early, whatever the load


@pytest.mark.slow
def test_islands_behind_a_router_take_part_in_a_campaign(tmp_path: Path) -> None:
    """Coordinator <- hysid router (deploy/sites/router.json5) <- two islands on loopback: the router
    comes up before the coordinator and dials it."""
    upstream, site = f"tcp/127.0.0.1:{free_port()}", f"tcp/127.0.0.1:{free_port()}"
    router = subprocess.Popen(hysid("router", "--config", str(ROUTER_CONFIG), "--listen", site, "--connect", upstream), stderr=subprocess.PIPE, text=True)
    processes = [router]
    try:
        ready = router.stderr.readline()
        assert " ready (listening on " + site in ready, ready
        db = tmp_path / "c.sqlite"
        coordinator = stderr_read(
            hysid(
                *coordinator_args(upstream, "behind", db, tmp_path / "out"),
                "--quiet",
                "--no-figures",
                *time_boxed(2, 6),
                "synth",
            ),
        )
        processes.append(coordinator)
        islands = [
            subprocess.Popen(
                hysid("island", "--connect", site, "--campaign", "behind", "--id", name, "--wait", "30", "--quiet", "--secret-file", f"{db}-behind.secret"),
                stderr=subprocess.PIPE,
                text=True,
            )
            for name in ("a", "b")
        ]
        processes += islands
        linked = router.stderr.readline()
        assert " router " in linked and " up | routers 1" in linked, linked
        for island in islands:
            assert island.wait(timeout=60) == 0, island.stderr.read()
        assert coordinator.wait(timeout=120) == 0, coordinator.stderr.read()  # its report takes seconds, more on a loaded machine
    finally:
        for p in processes:
            p.kill()
            p.wait(timeout=10)
    rows = query(db, "SELECT island, COUNT(*), MAX(iteration) FROM history WHERE campaign = 'behind' GROUP BY island")
    finals = dict(query(db, "SELECT island, iterations FROM islands WHERE campaign = 'behind' AND final = 1"))
    assert sorted(finals) == ["a", "b"] and all(finals.values())
    assert sorted(rows) == [(name, finals[name] + 1, finals[name]) for name in ("a", "b")]


@pytest.mark.slow
def test_a_two_site_campaign_over_delayed_lossy_links_survives_a_cut_without_losing_history(tmp_path: Path) -> None:
    sites = [Site(2, delay_ms=50.0), Site(2, delay_ms=50.0, loss_pct=1.0, cut_at_s=3.0, cut_for_s=5.0, per_process=2)]  # the cut site: one process of 2 islands
    try:
        r = campaign(sites, time_limit_s=30.0, workdir=tmp_path)  # the cut ends 8 s after the last join: room for a slow start
    except NamespacesUnavailable as exc:
        pytest.skip(str(exc))
    assert r["stop_reason"] == "time limit of 30 s"
    assert r["best_fitness"] < 1e-20 and r["max_relative_error"] < 1e-6
    assert r["islands_final"] == 4 and r["history_rows_missing"] == 0 and r["history_rows"] > 0
    assert r["impairments"][1]["cut"] and r["impairments"][0]["delay"] and r["impairments"][1]["delay"]
    [link] = r["links"]
    assert link["site"] == 2 and link["detect_s"] > 0 and link["back_s"] > 0 and link["caught_up_s"] > 0
    cut_site = [(island, event) for island, event in r["members"] if island.startswith("s2-")]
    assert r["island_processes"] == 3
    for island in ("s2-h1-0", "s2-h1-1"):
        assert [e for i, e in cut_site if i == island] == ["join", "lost", "back", "left"]
    assert [e for i, e in r["members"] if i.startswith("s1-")] == ["join", "join", "left", "left"]
