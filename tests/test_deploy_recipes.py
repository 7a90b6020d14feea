"""The shipped deploy recipes, used for real: every Zenoh configuration pair of deploy/zenoh as real sessions on
127.0.0.1 (free ports only), the short lease, deploy/members.py, the systemd units, the shell scripts and the
local recipe (deploy/local/run-campaign.sh). Helpers: tests/deploy_support.py.
"""

from __future__ import annotations

import json
import os
import queue
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import zenoh

from coordinator.launch import free_port
from deploy_support import (
    CAMPAIGN,
    DEPLOY,
    WAIT,
    ZENOH_DIR,
    collector,
    localized,
    pair,
    put_until_received,
    replies,
    session,
    setting,
    uses_tls,
)

pytestmark = pytest.mark.timeout(60)

FLAVOURS = ("", "-tls", "-usrpwd", "-secure")
MEMBERS = DEPLOY / "members.py"


def test_every_config_file_is_one_of_the_tested_pairs() -> None:
    shipped = {path.name for path in ZENOH_DIR.glob("*.json5")}
    tested = {path.name for flavour in FLAVOURS for path in pair(flavour)}
    assert shipped == tested


@pytest.mark.parametrize("flavour", FLAVOURS)
def test_config_pair_opens_real_sessions_and_exchanges(flavour: str, request: pytest.FixtureRequest) -> None:
    coordinator_file, island_file = pair(flavour)
    for path, mode in ((coordinator_file, "router"), (island_file, "client")):
        config = zenoh.Config.from_file(path)
        assert setting(config, "mode") == mode
        assert setting(config, "scouting/multicast/enabled") is False
        assert setting(config, "transport/link/tx/lease") == 2000
    tls_certs = request.getfixturevalue("certs") if uses_tls(coordinator_file) else None
    port = free_port()
    with session(localized(coordinator_file, port, tls_certs)) as coordinator:
        received: list = []
        subscriber = coordinator.declare_subscriber(f"{CAMPAIGN}/migrants/*", collector(received))
        queryable = coordinator.declare_queryable(f"{CAMPAIGN}/config", lambda query: query.reply(query.key_expr, b"loop set"))
        with session(localized(island_file, port, tls_certs)) as island:
            assert island.info.routers_zid() == [coordinator.zid()]
            assert put_until_received(island, f"{CAMPAIGN}/migrants/island-1", b"migrant", received)
            assert replies(island, f"{CAMPAIGN}/config") == [b"loop set"]
        subscriber.undeclare()
        queryable.undeclare()


FROZEN_ISLAND = """
import json, sys, time, zenoh
config = zenoh.Config.from_file(sys.argv[1])
config.insert_json5("connect/endpoints", json.dumps([sys.argv[2]]))
island = zenoh.open(config)
token = island.liveliness().declare_token(sys.argv[3])
print("member", flush=True)
time.sleep(120)
"""


def test_short_lease_notices_a_frozen_island_before_zenoh_default_lease() -> None:
    """lease 2000 ms: a stopped (SIGSTOP) island's membership ends well before the 10 s default."""
    coordinator_file, island_file = pair("")
    port = free_port()
    member = f"{CAMPAIGN}/members/island-7"
    with session(localized(coordinator_file, port)) as coordinator:
        events: queue.Queue = queue.Queue()
        subscriber = coordinator.liveliness().declare_subscriber(member, lambda sample: events.put(sample.kind))
        child = subprocess.Popen(
            [sys.executable, "-c", FROZEN_ISLAND, str(island_file), f"tcp/127.0.0.1:{port}", member],
            stdout=subprocess.PIPE,
            text=True,
        )
        try:
            assert events.get(timeout=WAIT + 5) == zenoh.SampleKind.PUT
            child.send_signal(signal.SIGSTOP)
            assert events.get(timeout=8.0) == zenoh.SampleKind.DELETE
        finally:
            child.kill()
            child.wait(timeout=10)
            child.stdout.close()
        subscriber.undeclare()


def members_cli(port: int) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(MEMBERS), "--connect", f"tcp/127.0.0.1:{port}", "--config", str(pair("")[1]), "--campaign", "demo", "--timeout", "2"],
        capture_output=True,
        text=True,
        timeout=30,
    )


def test_members_script_lists_the_campaign_members_only() -> None:
    coordinator_file, island_file = pair("")
    port = free_port()
    with session(localized(coordinator_file, port)) as coordinator:
        nobody = members_cli(port)
        assert nobody.returncode == 1 and "no island is a member of campaign 'demo'" in nobody.stderr
        with session(localized(island_file, port)) as island:
            tokens = [
                island.liveliness().declare_token(f"{CAMPAIGN}/members/island-3"),
                coordinator.liveliness().declare_token(f"{CAMPAIGN}/members/island-1"),
                island.liveliness().declare_token("hysid/other/members/island-4"),
            ]
            listed = members_cli(port)
            assert (listed.returncode, listed.stdout) == (0, "island-1\nisland-3\n"), listed.stderr
            for token in tokens:
                token.undeclare()


def test_members_script_reports_an_unreachable_coordinator_in_one_line() -> None:
    done = members_cli(free_port())
    assert done.returncode == 2
    assert done.stderr.startswith("members.py: error: cannot open Zenoh session") and done.stderr.count("\n") == 1


@pytest.mark.parametrize("unit", ["hysid-coordinator.service", "hysid-island@.service"])
def test_systemd_units_verify_cleanly(unit: str, tmp_path: Path) -> None:
    if shutil.which("systemd-analyze") is None:
        pytest.skip("systemd-analyze is not installed")
    hysid = Path(sys.executable).with_name("hysid")
    if not hysid.exists():
        pytest.skip(f"no hysid console script next to {sys.executable}")
    text = (DEPLOY / "systemd" / unit).read_text()
    assert "/opt/hysid/venv/bin/hysid" in text
    (tmp_path / unit).write_text(text.replace("/opt/hysid/venv/bin/hysid", str(hysid)))
    done = subprocess.run(["systemd-analyze", "verify", str(tmp_path / unit)], capture_output=True, text=True, timeout=60)
    assert (done.returncode, done.stderr) == (0, "")
    assert "Restart=on-failure" in text and "NoNewPrivileges=yes" in text and "EnvironmentFile=/etc/hysid/" in text


@pytest.mark.parametrize("script", ["slurm/hysid-campaign.sbatch", "local/run-campaign.sh", "tls/make-certs.sh"])
def test_shell_scripts_parse(script: str) -> None:
    done = subprocess.run(["bash", "-n", str(DEPLOY / script)], capture_output=True, text=True, timeout=30)
    assert (done.returncode, done.stderr) == (0, "")


@pytest.mark.slow
def test_local_recipe_runs_a_campaign_of_separate_processes(tmp_path: Path) -> None:
    hysid = Path(sys.executable).with_name("hysid")
    if not hysid.exists():
        pytest.skip(f"no hysid console script next to {sys.executable}")
    out = tmp_path / "run"
    done = subprocess.run(
        [
            "bash",
            str(DEPLOY / "local" / "run-campaign.sh"),
            "-n",
            "2",
            "-p",
            str(free_port()),
            "-c",
            "rehearsal",
            "-o",
            str(out),
            "synth",
            "--",
            "--time-limit",
            "4",
            "--iterations",
            "100000",
            "--population",
            "30",
            "--initial",
            "60",
            "--no-polish",
            "--quiet",
        ],
        capture_output=True,
        text=True,
        timeout=55,
        env={**os.environ, "HYSID": str(hysid)},
    )
    assert done.returncode == 0, done.stderr + (out / "coordinator.log").read_text()
    result = json.loads((out / "report" / "result.json").read_text())
    assert result["settings"]["campaign"] == "rehearsal"
    assert {island["island"] for island in result["islands"]} == {"island-1", "island-2"}
    moved = {m["island"]: m["src"] for m in result["settings"]["moves"]}  # the staged share hands the GA island over to PSO
    assert {island["island"]: moved.get(island["island"], island["algo"]) for island in result["islands"]} == {"island-1": "ga", "island-2": "pso"}
    for k in (1, 2):
        assert "stopped by the coordinator" in (out / f"island-{k}.log").read_text()
