"""A multi-host campaign on one machine: hosts are Linux network namespaces
(:mod:`hysid.bench.netns`: the coordinator's namespace is the hub). Needs root and
iproute2 (``ip``); skipped otherwise."""

from __future__ import annotations

import json
import shutil
import sqlite3
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from hysid.bench.netns import SUBNET, Lab, NamespacesUnavailable, ip, unavailable
from support import stderr_read, time_boxed

pytestmark = pytest.mark.timeout(60)

PORT = 7447
DEPLOY = Path(__file__).resolve().parents[1] / "deploy"
HYSID = [sys.executable, "-m", "hysid"]
ISLANDS = ("h1", "h2")
TIME_LIMIT_S = 8
TIME_BOXED_CAMPAIGN = time_boxed(len(ISLANDS), TIME_LIMIT_S)


def lab_or_skip(hosts: int) -> Iterator[Lab]:
    if reason := unavailable():
        pytest.skip(reason)
    lab = Lab(hosts)
    try:
        try:
            lab.build()
        except NamespacesUnavailable as exc:
            pytest.skip(str(exc))
        yield lab
    finally:
        lab.destroy()


@pytest.fixture
def lab() -> Iterator[Lab]:
    yield from lab_or_skip(hosts=2)


def test_lab_namespaces_have_no_route_beyond_their_subnet(lab: Lab) -> None:
    for namespace in lab.namespaces():
        assert ip("-n", namespace, "route", "show", "default").stdout.strip() == ""
    for k in (1, 2):
        routes = ip("-n", lab.host(k), "-4", "route", "show").stdout
        assert routes.split()[0] == f"{SUBNET}.0/24", routes


ROUTER = """
import json, sys, time, zenoh
endpoint, expected = sys.argv[1], set(sys.argv[2:])
config = zenoh.Config()
config.insert_json5("mode", '"router"')
config.insert_json5("scouting/multicast/enabled", "false")
config.insert_json5("listen/endpoints", json.dumps([endpoint]))
router = zenoh.open(config)
got, remotes = {}, set()
def heard(sample):
    sender = str(sample.key_expr).rsplit("/", 1)[1]
    got[sender] = sample.payload.to_bytes().decode()
    remotes.update(link.dst for link in router.info.links())
    router.put(f"hysid/netns/ack/{sender}", b"ack")
subscriber = router.declare_subscriber("hysid/netns/hello/*", heard)
print("ready", flush=True)
deadline = time.monotonic() + 30
while set(got) != expected and time.monotonic() < deadline:
    time.sleep(0.05)
print(json.dumps({"got": got, "remotes": sorted(remotes)}), flush=True)
time.sleep(0.5)
router.close()
"""

PEER = """
import json, sys, time, threading, zenoh
endpoint, name = sys.argv[1], sys.argv[2]
config = zenoh.Config()
config.insert_json5("mode", '"peer"')
config.insert_json5("scouting/multicast/enabled", "false")
config.insert_json5("connect/endpoints", json.dumps([endpoint]))
config.insert_json5("connect/timeout_ms", "20000")
peer = zenoh.open(config)
acked = threading.Event()
subscriber = peer.declare_subscriber(f"hysid/netns/ack/{name}", lambda sample: acked.set())
deadline = time.monotonic() + 30
while not acked.is_set() and time.monotonic() < deadline:
    peer.put(f"hysid/netns/hello/{name}", f"hello from {name}")
    acked.wait(0.2)
peer.close()
sys.exit(0 if acked.is_set() else 1)
"""


def test_zenoh_router_and_peers_in_separate_namespaces_exchange(lab: Lab) -> None:
    endpoint = f"tcp/{lab.hub_address}:{PORT}"
    names = ["h1", "h2"]
    router = subprocess.Popen(
        lab.command(lab.hub, sys.executable, "-c", ROUTER, endpoint, *names),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    peers = []
    try:
        assert router.stdout.readline().strip() == "ready", router.stderr.read()
        peers = [
            subprocess.Popen(lab.command(lab.host(k), sys.executable, "-c", PEER, endpoint, name), stderr=subprocess.PIPE, text=True)
            for k, name in enumerate(names, start=1)
        ]
        for peer in peers:
            assert peer.wait(timeout=40) == 0, peer.stderr.read()
        report = json.loads(router.stdout.readline())
        assert router.wait(timeout=10) == 0, router.stderr.read()
    finally:
        for process in (router, *peers):
            process.kill()
            process.wait(timeout=10)
    assert report["got"] == {name: f"hello from {name}" for name in names}
    assert {remote.split(":")[0] for remote in report["remotes"]} == {f"tcp/{lab.host_address(k)}" for k in (1, 2)}


def zenoh_file(tmp_path: Path, name: str, settings: dict[str, object]) -> Path:
    """deploy/zenoh/NAME with SETTINGS (key path -> value) changed, as an operator edits it, saved in tmp_path."""
    config = zenoh.Config.from_file(DEPLOY / "zenoh" / name)
    for key, value in settings.items():
        config.insert_json5(key, json.dumps(value))
    edited = tmp_path / name
    edited.write_text(str(config))
    return edited


def run_campaign(lab: Lab, tmp_path: Path, campaign: str, coordinator_config: Path, island_configs: dict[str, Path], protocol: str) -> Path:
    """The coordinator in the hub namespace, island h<k> in namespace h<k>; returns the report directory."""
    out = tmp_path / "out"
    coordinator = stderr_read(
        lab.command(
            lab.hub,
            *HYSID,
            "coordinator",
            "--config",
            str(coordinator_config),
            "--listen",
            f"{protocol}/{lab.hub_address}:{PORT}",
            "--campaign",
            campaign,
            "--out",
            str(out),
            "--quiet",
            "--no-figures",
            *TIME_BOXED_CAMPAIGN,
            "synth",
        ),
        cwd=tmp_path,
    )
    islands = []
    try:
        islands = [
            stderr_read(
                lab.command(
                    lab.host(k),
                    *HYSID,
                    "island",
                    "--config",
                    str(island_configs[name]),
                    "--connect",
                    f"{protocol}/{lab.hub_address}:{PORT}",
                    "--campaign",
                    campaign,
                    "--id",
                    name,
                    "--wait",
                    "20",
                    "--quiet",
                    "--secret-file",
                    str(out / f"campaign.sqlite-{campaign}.secret"),
                ),
                cwd=tmp_path,
            )
            for k, name in enumerate(ISLANDS, start=1)
        ]
        for island in islands:
            assert island.wait(timeout=120) == 0, island.stderr.read()
        assert coordinator.wait(timeout=120) == 0, coordinator.stderr.read()  # its report takes seconds, more on a loaded machine
    finally:
        for process in (coordinator, *islands):
            process.kill()
            process.wait(timeout=10)
            process.stderr.close()
    return out


def check_every_island_took_part(out: Path, campaign: str) -> None:
    result = json.loads((out / "result.json").read_text())
    assert result["settings"]["stop_reason"] == f"time limit of {TIME_LIMIT_S} s"
    islands = {island["island"]: island for island in result["islands"]}
    assert set(islands) == set(ISLANDS)
    assert all(island["final"] and island["iterations"] > 0 for island in islands.values())
    assert {event["island"] for event in result["members"] if event["event"] == "join"} == set(ISLANDS)
    with sqlite3.connect(out / "campaign.sqlite") as db:
        rows = db.execute("SELECT island, COUNT(*), MAX(iteration) FROM history WHERE campaign = ? GROUP BY island", (campaign,)).fetchall()
    assert sorted(rows) == [(name, islands[name]["iterations"] + 1, islands[name]["iterations"]) for name in ISLANDS]


@pytest.mark.slow
def test_campaign_across_namespaces_over_tcp(lab: Lab, tmp_path: Path) -> None:
    coordinator_config = DEPLOY / "zenoh" / "coordinator.json5"
    island_config = DEPLOY / "zenoh" / "island.json5"
    out = run_campaign(lab, tmp_path, "netns", coordinator_config, dict.fromkeys(ISLANDS, island_config), "tcp")
    check_every_island_took_part(out, "netns")


@pytest.mark.slow
def test_campaign_across_namespaces_with_tls_credentials_and_acl(lab: Lab, tmp_path: Path) -> None:
    """The multi-machine recipe of deploy/GUIDE.md: make-certs.sh, then secure-campaign.py, one identity per island."""
    if shutil.which("openssl") is None:
        pytest.skip("openssl is not installed: make-certs.sh cannot create the TLS certificates")
    certs = tmp_path / "certs"
    subprocess.run(
        ["bash", str(DEPLOY / "tls" / "make-certs.sh"), "-o", str(certs), "-s", lab.hub_address, *ISLANDS],
        check=True,
        capture_output=True,
        timeout=60,
    )
    endpoint = f"tls/{lab.hub_address}:{PORT}"
    subprocess.run(
        [
            sys.executable,
            str(DEPLOY / "secure-campaign.py"),
            "--campaign",
            "demo",
            "--listen",
            endpoint,
            "--connect",
            endpoint,
            "--certs",
            str(certs),
            "-o",
            str(tmp_path / "zenoh"),
            *ISLANDS,
        ],
        check=True,
        capture_output=True,
        timeout=60,
    )
    island_configs = {name: tmp_path / "zenoh" / "islands" / f"{name}.json5" for name in ISLANDS}
    out = run_campaign(lab, tmp_path, "demo", tmp_path / "zenoh" / "coordinator.json5", island_configs, "tls")
    check_every_island_took_part(out, "demo")
